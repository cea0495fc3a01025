"""fenicsmpm: the Material Point Method for geomechanics on dolfinx meshes.

    import fenicsmpm as fm
    grid = fm.Grid(msh)
    soil = fm.LinearElastic(E=20e6, nu=0.25, density=1500.0)
    pts = fm.Particles.fill(grid, soil, per_cell=2)
    sim = fm.Simulation(grid, pts, integrator=fm.Explicit("MUSL"), dt="auto", gravity=(0, -9.81))
"""
from .grid import Grid
from .particles import Particles
from .materials import LinearElastic, NeoHookean
from .integrators import Explicit, Newmark, QuasiStatic
from .simulation import Simulation, Probe, Output

__version__ = "0.1.0"
__all__ = ["Grid", "Particles", "LinearElastic", "NeoHookean", "Explicit", "Newmark",
           "QuasiStatic", "Simulation", "Probe", "Output"]
