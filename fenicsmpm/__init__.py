"""fenicsmpm: the Material Point Method for geomechanics on dolfinx meshes.

    import fenicsmpm as fm
    grid = fm.Grid(msh)
    soil = fm.LinearElastic(E=20e6, nu=0.25, density=1500.0)
    pts = fm.Particles.fill(grid, soil, per_cell=2)
    sim = fm.Simulation(grid, pts, integrator=fm.Explicit("MUSL"), dt="auto", gravity=(0, -9.81))

Who owns which stage of a step (DESIGN.md; the integrator puts them in order):

    stage          module
    locate         grid (Grid.locate), particles, migration (ranks), guards.particles_left
    shape          shapes/ (standard, gimp, cpdi, gauss_gimp, cmpm)
    P2G            kernels/transfer (+ kernels/axisymmetric hoop terms), boundaries/ (loads)
    grid solve     integrators/ (explicit, implicit, generalized_alpha, dmgc), contact/
    G2P            kernels/transfer, kernels/smoothing
    constitutive   materials/ (Simulation.stress_update: trial_stress / commit, or for one
                   linear-elastic body the fused pass of kernels/fused)
    relocate       particles, migration, splitting; guards (checks after the step)
    time loop      simulation (Simulation.step/run); set-up API in setup, energy monitor in
                   energy, checkpoint/restart in checkpoint; Probe, Output and writers in io/

Known-answer problems (tests, demos, benchmarks) are in problems/, the benchmark suite in
bench/ (python -m fenicsmpm.bench), MPI mesh partitioners in partition.
"""
from .grid import Grid
from .particles import Particles
from .materials import Hencky, LinearElastic, NeoHookean, MohrCoulomb, VonMises
from .materials import BiotElastic, Hypoplastic
from .integrators import Explicit, Newmark, QuasiStatic
from .integrators import ExplicitGeneralizedAlpha, ImplicitGeneralizedAlpha
from .contact import ExplicitContact, RigidLoad, set_body
from .integrators import DoubleMappingNewmark, DoubleMappingQuasiStatic
from .boundaries import ParticleLayer, Robin, Viscous, Viscoelastic
from .boundaries import CompliantBase, InputMotion, compliant_base, rigid_base
from .simulation import Simulation
from .io import Probe, Output
from .errors import CheckpointNotFoundError, ParticlesLeftMesh
from .io.compiler_log import silence_compiler_output
from . import partition

silence_compiler_output()

__version__ = "0.1.0"


def _abort_all_ranks_on_uncaught_exception():
    """Under MPI, an exception left uncaught on one rank prints its traceback and aborts every
    rank (MPI_Abort) instead of leaving the others waiting in a collective."""
    import sys
    from mpi4py import MPI
    if MPI.COMM_WORLD.size == 1:
        return
    previous = sys.excepthook

    def hook(kind, value, tb):
        previous(kind, value, tb)
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(1)

    sys.excepthook = hook


_abort_all_ranks_on_uncaught_exception()
__all__ = ["Grid", "Particles", "Hencky", "LinearElastic", "NeoHookean", "MohrCoulomb", "VonMises", "Explicit", "Newmark",
           "QuasiStatic", "Simulation", "Probe", "Output", "Robin", "Viscous", "Viscoelastic", "ParticleLayer"]
__all__ += ["ExplicitGeneralizedAlpha", "ImplicitGeneralizedAlpha"]
__all__ += ["CompliantBase", "InputMotion", "compliant_base", "rigid_base"]
__all__ += ["ExplicitContact", "RigidLoad", "set_body"]
__all__ += ["BiotElastic", "Hypoplastic"]
__all__ += ["DoubleMappingNewmark", "DoubleMappingQuasiStatic"]
__all__ += ["ParticlesLeftMesh", "CheckpointNotFoundError"]
