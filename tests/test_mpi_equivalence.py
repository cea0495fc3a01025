"""1 rank vs N ranks: the same particle results, with particles crossing rank boundaries.

Under mpirun -n 2 each rank also runs the serial reference on COMM_SELF; particles are
matched by their initial position (ids are numbered per rank)."""
import math

import numpy as np
import pytest
from mpi4py import MPI
from dolfinx import mesh

import fenicsmpm as fm
from fenicsmpm.problems.elastic import colliding_discs, vibrating_bar
from fenicsmpm.partition import check_strips, strips

WORLD = MPI.COMM_WORLD


def _by_initial_position(p, comm):
    """All particles' (initial position, velocity), gathered and sorted by initial position."""
    x0 = np.concatenate(comm.allgather(p.x - p.u)) if comm.size > 1 else p.x - p.u
    v = np.concatenate(comm.allgather(p.v)) if comm.size > 1 else p.v
    order = np.lexsort(np.round(x0, 9).T[::-1])
    return x0[order], v[order]


def _moved_ranks(p, ids_before, comm):
    """Global number of particles that are now on another rank than at the start."""
    return comm.allreduce(int(np.count_nonzero(~np.isin(p.id, ids_before))))


def _compare(build, steps, rtol, cut=False):
    """Run `build(comm)` on one rank and on all; with `cut`, the parallel mesh is cut into
    vertical strips (fenicsmpm.partition), so that moving particles must change rank."""
    ref, _ = build(MPI.COMM_SELF)
    ref.run(steps=steps)
    par, _ = build(WORLD)
    if cut:
        check_strips(par.grid.mesh)
    ids0 = par.particles.id.copy()
    par.run(steps=steps)
    x_ref, v_ref = _by_initial_position(ref.particles, MPI.COMM_SELF)
    x_par, v_par = _by_initial_position(par.particles, WORLD)
    assert np.allclose(x_ref, x_par, rtol=0, atol=1e-12), "particle sets differ"
    scale = np.max(np.abs(v_ref))
    err = np.max(np.abs(v_par - v_ref)) / scale
    assert err < rtol, f"velocities differ by {err:.2e} (relative to max |v|), tolerance {rtol}"
    return _moved_ranks(par.particles, ids0, WORLD)


def test_explicit_colliding_discs_equivalence():
    """BENCHMARKS L2 (discs meet at t ~ 1.59 s; 200 steps reach 2.6 s): same velocities on
    1 and N ranks to 1e-10, with particles crossing rank boundaries."""
    moved = _compare(lambda c: colliding_discs(fm.Explicit("MUSL"), cfl=0.3, comm=c,
                                               partitioner=strips(20, 20)), 200, 1e-10,
                     cut=True)
    if WORLD.size > 1:
        assert moved > 0, "no particle crossed a rank boundary: the test would prove nothing"


def test_explicit_vibrating_bar_equivalence():
    _compare(lambda c: vibrating_bar(fm.Explicit("USF"), n_cells=20, cfl=0.5, v0=1.0, comm=c),
             200, 1e-10)


def test_implicit_newmark_equivalence_iterative_ksp():
    """Newmark with CG + Jacobi (tight tolerance): same velocities to 1e-8 on 1 and N ranks."""
    opts = {"ksp_type": "cg", "pc_type": "jacobi", "ksp_rtol": 1e-14, "ksp_atol": 1e-30,
            "ksp_max_it": 10000}
    moved = _compare(lambda c: colliding_discs(fm.Newmark(petsc_options=opts, rtol=1e-10), comm=c,
                                               partitioner=strips(20, 20)), 30, 1e-8,
                     cut=True)
    if WORLD.size > 1:
        assert moved > 0


def test_particle_crossing_back_and_forth_is_owned_at_every_step():
    """A block thrown diagonally against gravity (also diagonal) travels through the mesh and
    comes back, crossing rank boundaries both ways: at every step each particle sits on the
    rank owning its cell, and mass is exactly conserved."""
    msh = mesh.create_rectangle(WORLD, [[0, 0], [1, 1]], [12, 12], mesh.CellType.quadrilateral,
                                partitioner=strips(12, 12))
    check_strips(msh)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=100.0, nu=0.3, density=1.0)
    p = fm.Particles.fill(grid, mat, per_cell=2,
                          region=lambda x: np.all((x > 0.05) & (x < 0.3), axis=1),
                          velocity=(3.0 / np.sqrt(2), 3.0 / np.sqrt(2)))
    def total_mass():             # exactly rounded, so independent of which rank holds what
        return math.fsum(np.concatenate(WORLD.allgather(p.mass)))
    m0 = total_mass()
    n = p.n_global()
    g = 10.0 / np.sqrt(2)
    sim = fm.Simulation(grid, p, fm.Explicit("MUSL"), dt=0.005, gravity=(-g, -g))

    def owners():
        own = np.full(n, -1)
        for r, ids in enumerate(WORLD.allgather(p.id)):
            own[ids] = r
        return own

    history = [owners()]
    for k in range(120):                              # apex at t = 0.3 s, back down at 0.6 s
        sim.step()
        ok = WORLD.allreduce(int(np.all((p.cell >= 0) & (p.cell < grid.n_owned_cells))), op=MPI.MIN)
        assert ok == 1, f"step {k}: a particle is on a rank that does not own its cell"
        history.append(owners())
        assert np.all(history[-1] >= 0), f"step {k}: a particle was lost"
    assert total_mass() == m0, "mass must be exactly conserved"
    changes = np.sum(np.diff(np.array(history), axis=0) != 0, axis=0)
    if WORLD.size > 1:
        assert np.max(changes) >= 2, "no particle went to another rank and back"
    # free flight: symplectic Euler's exact discrete path u = v0 t - g t^2/2 - g dt t/2
    u = p.total(p.mass[:, None] * p.u) / m0
    t, dt, v0 = sim.t, sim.dt, 3.0 / np.sqrt(2)
    assert np.allclose(u, v0 * t - 0.5 * g * t * t - 0.5 * g * dt * t, rtol=0, atol=1e-12), u
