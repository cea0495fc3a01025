"""Verification problems with exact solutions (BENCHMARKS.md section V), shared by the tests,
the demos and the benchmark suite.

Each builder returns a ready `Simulation` and a dict of exact answers."""
import time

import numpy as np
from mpi4py import MPI
from dolfinx import mesh as dmesh

from ..collective import gmax, gmax_of
from ..grid import Grid, vertex_ghost_partitioner
from ..integrators import DoubleMappingQuasiStatic, QuasiStatic
from ..materials import LinearElastic
from ..particles import Particles
from ..simulation import Simulation


def _partitioner(partitioner):
    """create_rectangle keyword for an optional cell partitioner (e.g. fm.partition.strips)."""
    return {} if partitioner is None else {"partitioner": partitioner}


def vibrating_bar(integrator, n_cells=20, per_cell=2, dt=None, cfl=0.2, length=1.0, E=100.0,
                  density=1.0, v0=0.1, cell_type=dmesh.CellType.quadrilateral,
                  comm=MPI.COMM_WORLD, partitioner=None, shape="auto"):
    """V1: axially vibrating bar, fixed at x = 0, free at x = L, v(x, 0) = v0 sin(pi x / 2L).

    Plane strain with nu = 0 and the transverse motion fixed, so the bar is 1D. The mesh
    extends two cells beyond the free end so the end stays inside the grid.
    Exact: v(x, t) = v0 cos(w t) sin(pi x / 2L), w = (pi / 2L) sqrt(E / rho).
    dt defaults to cfl * h / c (explicit) or to 5 h / c (implicit); `shape`: the
    Simulation's shape family."""
    h = length / n_cells
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [length + 2 * h, h]], [n_cells + 2, 1], cell_type,
                                 **_partitioner(partitioner))
    grid = Grid(msh)
    mat = LinearElastic(E=E, nu=0.0, density=density)
    k = np.pi / (2 * length)
    pts = Particles.fill(grid, mat, per_cell=per_cell, region=lambda x: x[:, 0] < length,
                         velocity=lambda x: np.c_[v0 * np.sin(k * x[:, 0]), np.zeros(len(x))])
    c = np.sqrt(E / density)
    if dt is None:
        dt = cfl * h / c if integrator.explicit else 5.0 * h / c
    sim = Simulation(grid, pts, integrator, dt=dt, shape=shape)
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0), [0])
    sim.fix(lambda x: np.full(len(x), True), [1])
    omega = k * c
    exact = dict(omega=omega, period=2 * np.pi / omega, wave_speed=c, h=h,
                 velocity=lambda x, t: v0 * np.cos(omega * t) * np.sin(k * x),
                 energy=0.25 * density * v0 ** 2 * length * h)
    return sim, exact


def self_weight_column(integrator, n_cells=10, per_cell=2, height=10.0, E=1e8, nu=0.0,
                       density=2000.0, g=10.0, dt=1.0, cell_type=dmesh.CellType.quadrilateral,
                       comm=MPI.COMM_WORLD, shape="auto"):
    """V2 (small strain): elastic column under self-weight, one cell wide, rollers on the sides
    and base. The mesh has one empty cell row above the column (inactive nodes).

    Exact (linear): sigma_yy(y) = -rho g (H - y), u_y(y) = -rho g (H y - y^2 / 2) / M,
    so the top settles rho g H^2 / (2 M). `shape`: the Simulation's shape family."""
    h = height / n_cells
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [h, height + h]], [1, n_cells + 1], cell_type)
    grid = Grid(msh)
    mat = LinearElastic(E=E, nu=nu, density=density)
    pts = Particles.fill(grid, mat, per_cell=per_cell, region=lambda x: x[:, 1] < height)
    sim = Simulation(grid, pts, integrator, dt=dt, gravity=(0.0, -g), shape=shape)
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], h), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0), [1])
    M = mat.constrained_modulus
    exact = dict(
        h=h, M=M,
        stress_yy=lambda y: -density * g * (height - y),
        displacement_y=lambda y: -density * g * (height * y - 0.5 * y ** 2) / M,
        top_settlement=density * g * height ** 2 / (2 * M))
    return sim, exact


def colliding_discs(integrator, n_cells=20, per_cell=2, cfl=0.5, speed=0.1,
                    cell_type=dmesh.CellType.quadrilateral, comm=MPI.COMM_WORLD, partitioner=None,
                    shape="auto"):
    """L2: two elastic discs (radius 0.2, centres (0.2, 0.2) and (0.8, 0.8)) moving towards each
    other with velocities +-(speed, speed) in a unit square; E = 1000, nu = 0.3, rho = 1000
    (Sulsky et al. 1995). No boundary conditions, no gravity: total momentum stays zero, and
    kinetic energy turns into strain energy during the impact (which starts at t ~ 1.59 s).
    `partitioner` (a dolfinx cell partitioner) fixes where the mesh is cut across ranks.
    `shape`: the Simulation's shape family (as in the other builders)."""
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [n_cells, n_cells], cell_type,
                                 **_partitioner(partitioner))
    grid = Grid(msh)
    mat = LinearElastic(E=1000.0, nu=0.3, density=1000.0)
    centres = np.array([[0.2, 0.2], [0.8, 0.8]])

    def disc(k):
        return lambda x: np.linalg.norm(x - centres[k], axis=1) < 0.2

    v = np.array([speed, speed])
    pts = (Particles.fill(grid, mat, per_cell=per_cell, region=disc(0), velocity=v)
           + Particles.fill(grid, mat, per_cell=per_cell, region=disc(1), velocity=-v))
    dt = cfl * grid.h / mat.p_wave_speed if integrator.explicit else 2.0 * grid.h / mat.p_wave_speed
    sim = Simulation(grid, pts, integrator, dt=dt, shape=shape)
    contact = (np.linalg.norm(centres[1] - centres[0]) - 0.4) / (2 * speed * np.sqrt(2))
    return sim, dict(contact_time=contact, kinetic_energy=0.5 * 1000.0 * np.pi * 0.2 ** 2 * 2 * 2 * speed ** 2)


def self_weight_errors(method="dmgc", shape="ugimp", n_cells=10, per_cell=2, load_steps=5,
                       height=10.0, E=1e8, nu=0.0, density=2000.0, g=10.0, comm=MPI.COMM_WORLD,
                       **newton):
    """V2 small strain (BENCHMARKS.md): the elastic column under self-weight of
    self_weight_column (one cell wide, one empty cell row on top,
    rollers on the sides and base, LinearElastic, gravity ramped over `load_steps`
    quasi-static steps), on a vertex-ghost partitioned mesh with GIMP `shape`, solved with
    DoubleMappingQuasiStatic (method="dmgc") or fm.QuasiStatic ("standard"). Collective.

    Returns dict(stress, displacement, settlement, wall, newton):
      stress        sum_p |sigma_yy,p - sigma_a(Y_p)| V0_p / (rho g H sum_p V0_p),
      displacement  sqrt(sum_p V0_p (u_y,p - u_a(Y_p))^2 / sum_p V0_p u_a(Y_p)^2),
      settlement    |mean u_y of the top particles / u_a(Y_top) - 1|,
      wall          seconds of sim.run (largest over ranks),  newton: iterations per step,
    with sigma_a = -rho g (H - Y), u_a = -rho g (H Y - Y^2 / 2) / M at the initial height Y."""
    if method not in ("dmgc", "standard"):
        raise ValueError(f"self_weight_errors: 'method' must be 'dmgc' or 'standard', got {method!r}")
    h = height / n_cells
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [h, height + h]], [1, n_cells + 1],
                                 dmesh.CellType.quadrilateral, partitioner=vertex_ghost_partitioner())
    grid = Grid(msh)
    mat = LinearElastic(E=E, nu=nu, density=density)
    pts = Particles.fill(grid, mat, per_cell=per_cell, region=lambda x: x[:, 1] < height)
    integ = (DoubleMappingQuasiStatic if method == "dmgc" else QuasiStatic)(load_steps=load_steps, **newton)
    sim = Simulation(grid, pts, integ, dt=1.0, gravity=(0.0, -g), shape=shape)
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], h), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0), [1])
    comm.barrier()
    t0 = time.perf_counter()
    sim.run(steps=load_steps, progress=False)
    wall = gmax(comm, time.perf_counter() - t0)
    p = sim.particles
    Y = (p.x - p.u)[:, 1]
    M = mat.constrained_modulus
    ua = -density * g * (height * Y - 0.5 * Y ** 2) / M
    ytop = gmax_of(comm, Y)
    top = np.abs(Y - ytop) < 1e-9 * height
    loc = np.array([np.sum(np.abs(p.stress[:, 1, 1] + density * g * (height - Y)) * p.V0),
                    np.sum(p.V0), np.sum(p.V0 * (p.u[:, 1] - ua) ** 2), np.sum(p.V0 * ua ** 2),
                    np.sum(p.u[top, 1]), np.sum(ua[top]), np.count_nonzero(top)])
    tot = comm.allreduce(loc, op=MPI.SUM)
    return dict(stress=float(tot[0] / (density * g * height * tot[1])),
                displacement=float(np.sqrt(tot[2] / tot[3])),
                settlement=float(abs(tot[4] / tot[5] - 1.0)), wall=wall,
                newton=list(integ.iterations))
