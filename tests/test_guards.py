"""Guards: non-finite values and inverted particles stop the run with a precise message."""
import numpy as np
import pytest
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems.elastic import colliding_discs


def test_nan_stress_stops_the_run_naming_step_field_and_particle():
    sim, _ = colliding_discs(fm.Explicit("MUSL"))
    sim.run(steps=3)
    p = sim.particles
    target = 7                                     # global id of the poisoned particle
    hit = np.flatnonzero(p.id == target)
    p.stress[hit, 0, 0] = np.nan
    # within the step the NaN reaches its neighbours through P2G, so the report lists the
    # lowest contaminated ids; it must stop at this very step
    with pytest.raises(FloatingPointError, match=r"step 4, t = .*non-finite (stress|velocity|position)"
                                                 r" in \d+ particle\(s\); first ids \[\d+"):
        sim.step()


def test_inverted_particle_is_reported():
    sim, _ = colliding_discs(fm.Explicit("USF"))
    p = sim.particles
    hit = np.flatnonzero(p.id == 3)
    p.F[hit] = np.diag([-1.0, 1.0, 1.0])           # det F < 0
    with pytest.raises(RuntimeError, match=r"step 1, .*inverted particle \(det F <= 0\).*first ids \[3\]"):
        sim.step()


def test_guards_pass_on_a_healthy_run():
    sim, _ = colliding_discs(fm.Newmark())
    sim.run(steps=3)
    assert sim.step_count == 3


def test_blow_up_is_stopped_at_its_start_with_speed_stress_and_volume():
    """Issue 21 item 4: an explicit particle whose velocity jumped by more than h / dt in one
    step (a kick of more than a cell per step) stops the run at once, naming it with its jump,
    speed, stress and det F, before it leaves the mesh or inverts others."""
    from fenicsmpm.guards import check_particles
    sim, _ = colliding_discs(fm.Explicit("MUSL"))
    sim.run(steps=2)
    check_particles(sim)                           # healthy
    p = sim.particles
    hit = np.flatnonzero(p.id == 5)
    jump = 1.5 * sim.grid.h / sim.dt
    p.a[hit] = [jump / sim.dt, 0.0]
    with pytest.raises(RuntimeError, match=r"step 2, .*blow-up: particle velocity jumped by more "
                                           r"than h / dt = .* in 1 particle\(s\); first ids \[5\]"
                                           r".*their velocity jump \[\d.*det F \[\d.*Likely causes"):
        check_particles(sim)


def test_a_blow_up_grown_over_many_steps_stops_at_two_cells_per_step():
    """Issue 21 item 4: a particle accelerated a little every step (no single jump above h /
    dt) is stopped once it moves faster than 2 h / dt, more than two cells per step, with its
    speed, stress and det F, instead of being thrown out of the mesh later."""
    sim, _ = colliding_discs(fm.Explicit("MUSL"))
    sim.run(steps=2)
    p = sim.particles
    hit = np.flatnonzero(p.id == 5)
    v_lim = 2.0 * sim.grid.h / sim.dt
    p.v[hit] = [1.01 * v_lim, 0.0]                 # reached over many steps: a = 0 this step
    p.a[hit] = 0.0
    from fenicsmpm.guards import check_particles
    with pytest.raises(RuntimeError, match=r"step 2, .*blow-up: particle speed above 2 h / dt = "
                                           r".* \(more than 2 cells per step\) in 1 particle\(s\); "
                                           r"first ids \[5\].*\|v\| \[\d.*Likely causes"):
        check_particles(sim)
    p.v[hit] = [0.99 * v_lim, 0.0]
    check_particles(sim)                           # just below: no stop
