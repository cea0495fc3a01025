"""The exceptions fenicsmpm defines (also exported as fm.ParticlesLeftMesh and
fm.CheckpointNotFoundError). Everything else fenicsmpm raises is a built-in type: ValueError
or TypeError for bad input (the message names the parameter), NotImplementedError for a
combination that is not supported, FloatingPointError and RuntimeError from the guards (a
non-finite, inverted or collapsed particle; a Newton or KSP failure), each naming the step,
the time and the first particles concerned. Under MPI every rank raises the same error
(raise_together for a check that only one rank can make)."""


class ParticlesLeftMesh(RuntimeError):
    """Particles left the mesh (Simulation(on_leave="error"), the default). Raised before the
    step changed any state, so the last accepted state is written to the run's output and
    checkpoint; the message names the step, the time and the first particles (ids and
    positions). A RuntimeError subclass."""


class CheckpointNotFoundError(FileNotFoundError):
    """No complete checkpoint under the directory given to Simulation.restore/restart (the
    message names the path and the file that is missing). A FileNotFoundError subclass."""


def raise_together(comm, fn, *args):
    """fn(*args), but if it raises a RuntimeError or FloatingPointError on any rank, every
    rank raises: its own error where it has one, else a RuntimeError quoting the lowest failing
    rank's. So no rank goes on into a collective that the failing rank never reaches (a
    hang). fn must not itself call collectives after the point where it may raise. One
    allreduce per call when comm.size > 1 (and a broadcast on failure)."""
    if comm.size == 1:
        return fn(*args)
    from mpi4py import MPI
    try:
        out, err = fn(*args), None
    except (RuntimeError, FloatingPointError) as e:
        out, err = None, e
    first = comm.allreduce(comm.rank if err is not None else comm.size, op=MPI.MIN)
    if first == comm.size:
        return out
    msg = comm.bcast(f"{type(err).__name__}: {err}" if comm.rank == first else None, root=first)
    if err is not None:
        raise err
    raise RuntimeError(f"on rank {first}: {msg}")


__all__ = ["ParticlesLeftMesh", "CheckpointNotFoundError", "raise_together"]
