"""The exceptions fenicsmpm defines (also exported as fm.ParticlesLeftMesh and
fm.CheckpointNotFoundError). Everything else fenicsmpm raises is a built-in type: ValueError
or TypeError for bad input (the message names the parameter), NotImplementedError for a
combination that is not supported, FloatingPointError and RuntimeError from the guards (a
non-finite, inverted or collapsed particle; a Newton or KSP failure), each naming the step,
the time and the first particles concerned. Under MPI every rank raises the same error."""


class ParticlesLeftMesh(RuntimeError):
    """Particles left the mesh (Simulation(on_leave="error"), the default). Raised before the
    step changed any state, so the last accepted state is written to the run's output and
    checkpoint; the message names the step, the time and the first particles (ids and
    positions). A RuntimeError subclass."""


class CheckpointNotFoundError(FileNotFoundError):
    """No complete checkpoint under the directory given to Simulation.restore/restart (the
    message names the path and the file that is missing). A FileNotFoundError subclass."""


__all__ = ["ParticlesLeftMesh", "CheckpointNotFoundError"]
