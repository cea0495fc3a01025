"""dt="auto" follows the state (Simulation.follow_state_dt, guards.state_wave_speed; issue 21
item 4): the explicit step of the deformed particles, at most the initial one, changed when it
moves by more than 10 %. Serial and under mpirun -n 2."""
import numpy as np
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm


def _block(dt="auto", gravity=(0.0, 0.0)):
    msh = mesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [1.0, 1.0]], [8, 8],
                                mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    pts = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 1] < 0.5)
    return fm.Simulation(grid, pts, fm.Explicit(), dt=dt, gravity=gravity), mat


def test_stretched_stressed_particles_shrink_the_step():
    """A particle stretched to V = 4 V0 that carries stress is half as dense: c_p doubles and
    the step halves (exactly cfl h / (2 c_p)); without stress it does not count (a
    cohesionless material pulled apart); relaxed, the step grows back to the state's step, and
    a change within 10 % of the step in use is not taken."""
    sim, mat = _block()
    dt0 = sim.dt
    assert np.isclose(dt0, sim.cfl * sim.grid.h / mat.p_wave_speed, rtol=1e-12)
    p = sim.particles
    pick = p.id == 0                                  # one particle, on whichever rank owns it
    p.V[pick] = 4.0 * p.V0[pick]
    sim.follow_state_dt()
    assert sim.dt == dt0                              # no stress: no stiffness
    p.stress[pick, 0, 0] = 1.0
    sim.follow_state_dt()
    assert np.isclose(sim.dt, 0.5 * dt0, rtol=1e-12), (sim.dt, dt0)
    p.V[pick] = 1.05 * p.V0[pick]                     # relaxed: the step grows back
    sim.follow_state_dt()
    assert np.isclose(sim.dt, dt0 / np.sqrt(1.05), rtol=1e-12), (sim.dt, dt0)
    p.V[pick] = 1.0 * p.V0[pick]                      # within 10 % of the step in use: kept
    sim.follow_state_dt()
    assert np.isclose(sim.dt, dt0 / np.sqrt(1.05), rtol=1e-12), (sim.dt, dt0)


def test_small_strain_run_keeps_its_step_and_t_end_is_reached():
    """An elastic block settling under gravity (strains ~1e-2) keeps dt="auto" unchanged, so
    its results are those of the fixed initial step; run(t_end) ends at t_end."""
    sim, _ = _block(gravity=(0.0, -10.0))
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    dt0 = sim.dt
    sim.run(t_end=0.05)
    assert sim.dt == dt0 and sim.step_count == int(np.ceil(0.05 / dt0 - 1e-9))
    assert 0.05 <= sim.t < 0.05 + dt0


def test_run_to_t_end_with_a_changing_step():
    """When the step changes during run(t_end=...), the run still stops at the first step
    reaching t_end (not after the step count planned with the initial dt)."""
    sim, _ = _block()
    dt0 = sim.dt
    p = sim.particles
    p.V[p.id == 0] *= 4.0
    p.stress[p.id == 0, 0, 0] = 1.0
    sim.run(t_end=20 * dt0)
    assert sim.dt < 0.6 * dt0
    assert 20 * dt0 - 1e-9 * sim.dt <= sim.t < 20 * dt0 + sim.dt
    assert sim.step_count > 25
