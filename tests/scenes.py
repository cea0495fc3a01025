"""Scenes shared by several test files."""
import numpy as np
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm


def top(x):
    """The top face y = 1 of the unit block."""
    return np.isclose(x[:, 1], 1.0)


def pushed_top(eps):
    """displacement=u(x, t) of the implicit integrators: the top moved down by eps t."""
    return lambda x, t: np.column_stack([np.zeros(len(x)), np.where(top(x), -eps * t, 0.0)])


def oedometric_block(integrator, cells=4, nu=0.3, dt=1.0, **sim_options):
    """A 1 m x 1 m linear-elastic block (E = 1 MPa, rho = 1000, 2 x 2 particles per cell) on
    cells x cells quadrilaterals, rollers on its sides, its base and top held vertically (the
    integrator's displacement= moves the top): (Simulation, constrained modulus M)."""
    E = 1e6
    grid = fm.Grid(mesh.create_rectangle(MPI.COMM_WORLD, [[0, 0], [1, 1]], [cells, cells],
                                         mesh.CellType.quadrilateral))
    p = fm.Particles.fill(grid, fm.LinearElastic(E=E, nu=nu, density=1e3), per_cell=2)
    sim = fm.Simulation(grid, p, integrator, dt=dt, **sim_options)
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], 1.0), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0) | top(x), [1])
    return sim, E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
