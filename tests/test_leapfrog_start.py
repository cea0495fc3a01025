"""fm.Explicit(start="leapfrog"): the central-difference start of Belytschko, Liu & Moran
(2014, Box 6.1), v^(1/2) = v^0 + dt/2 f^0 / m on a run's first step, against the default
start="euler" (a full first step). Runs serially and under mpirun -n 2.

Free fall under g from rest, n steps of dt (exact, to round-off):
    euler:    drop g dt^2 n (n + 1) / 2 (half a step ahead of g t^2 / 2), velocity -g n dt;
    leapfrog: drop g (n dt)^2 / 2 = g t^2 / 2,                 velocity -g (n - 1/2) dt.
The suddenly loaded PEERS.md column is in tests/test_bench_column_peers.py (rows
"-auto-leapfrog")."""
import os

import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm

comm = MPI.COMM_WORLD
G, DT = 10.0, 1e-4


def _falling_block(start, scheme="MUSL"):
    msh = mesh.create_rectangle(comm, [[0, 0], [1, 1]], [8, 8], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1e3),
                          region=lambda x: (x[:, 1] > 0.3) & (x[:, 1] < 0.7))
    sim = fm.Simulation(grid, p, fm.Explicit(scheme, start=start), dt=DT,
                        gravity=(0.0, -G))
    return sim


def _drop_and_velocity(sim, y0):
    p = sim.particles
    m = p.total(p.mass)
    return (y0 - p.total(p.mass * p.x[:, 1]) / m), p.total(p.mass * p.v[:, 1]) / m


@pytest.mark.parametrize("scheme", ["MUSL", "USF", "USL", "AVG"])
def test_free_fall_is_exact_with_the_leapfrog_start(scheme):
    """Every update order: leapfrog falls g t^2 / 2 with velocities at the half steps, euler
    falls half a step ahead (module docstring), both to 1e-9."""
    n = 40
    for start in ("euler", "leapfrog"):
        sim = _falling_block(start, scheme)
        p = sim.particles
        y0 = p.total(p.mass * p.x[:, 1]) / p.total(p.mass)
        sim.run(steps=n)
        drop, v = _drop_and_velocity(sim, y0)
        if start == "euler":
            want_drop, want_v = 0.5 * G * DT ** 2 * n * (n + 1), -G * n * DT
        else:
            want_drop, want_v = 0.5 * G * (n * DT) ** 2, -G * (n - 0.5) * DT
        assert drop == pytest.approx(want_drop, rel=1e-9), (start, drop, want_drop)
        assert v == pytest.approx(want_v, rel=1e-9), (start, v, want_v)
        assert np.allclose(p.a[:, 1], -G, rtol=1e-9)        # a = dv / dt of the last step


def test_only_the_first_step_is_a_half_step_after_a_restart(shared_tmp_path):
    """A run restored from a checkpoint at step 5 continues with full steps: 5 + 5 steps
    give the same state as 10 uninterrupted ones (to round-off)."""
    ref = _falling_block("leapfrog")
    ref.run(steps=10)
    sim = _falling_block("leapfrog")
    sim.run(steps=5)
    sim.checkpoint(os.path.join(shared_tmp_path, "ck"))
    again = _falling_block("leapfrog").restore(os.path.join(shared_tmp_path, "ck"))
    assert again.step_count == 5
    again.run(steps=5)
    assert np.allclose(again.particles.x, ref.particles.x, rtol=0, atol=1e-14)
    assert np.allclose(again.particles.v, ref.particles.v, rtol=0, atol=1e-14)


def test_unknown_start_names_the_parameter():
    with pytest.raises(ValueError, match="'start' must be one of \\('euler', 'leapfrog'\\)"):
        fm.Explicit(start="verlet")
