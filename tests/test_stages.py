"""Staged analysis (seed 000 §3.5): a static gravity stage, then a dynamic stage with gravity
removed, absorbing boundaries and sigma = sigma_ini + sigma_dyn, on one Simulation."""
import numpy as np
import pytest
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems.elastic import self_weight_column

def base(x):
    """The bottom facet, y = 0."""
    return np.isclose(x[:, 1], 0.0)


def _gravity_stage(E=1e7):
    sim, ex = self_weight_column(fm.QuasiStatic(load_steps=2), n_cells=10, E=E)
    sim.run(steps=2)
    return sim, ex


def _max_speed(sim):
    p = sim.particles
    return sim.comm.allreduce(float(np.max(np.abs(p.v), initial=0.0)), op=MPI.MAX)


@pytest.mark.parametrize("integrator", ["newmark", "explicit"])
def test_dynamic_stage_starts_in_equilibrium(integrator):
    """After the gravity stage, switching to dynamics with sigma_ini kept, gravity removed and
    the fixed base replaced by a viscous one, the column stays at rest."""
    sim, ex = _gravity_stage()
    sy = sim.comm.allreduce(float(np.min(sim.particles.stress[:, 1, 1], initial=0.0)), op=MPI.MIN)
    assert sy < -0.9 * 2000 * 10 * 10 * 0.9          # the gravity stage did load the column
    integ = fm.Newmark() if integrator == "newmark" else fm.Explicit("MUSL")
    sim.start_stage(integ, dt=5e-3 if integrator == "newmark" else "auto", gravity=(0.0, 0.0))
    sim.release(base, [1])
    sim.add_boundary(fm.Viscous(base))
    sim.run(steps=50)
    v = _max_speed(sim)
    # scale: the speed a 1 % imbalance of the self-weight would cause in the same time
    scale = 0.01 * 10.0 * sim.t
    assert v < 1e-6 * scale, f"max speed {v:.3e} m/s after the stage switch (tolerance {1e-6 * scale:.1e})"
    # total stress still carries the geostatic state (materials see the total)
    sy2 = sim.comm.allreduce(float(np.min(sim.particles.stress[:, 1, 1], initial=0.0)), op=MPI.MIN)
    assert abs(sy2 / sy - 1) < 1e-6


def test_without_initial_stress_the_column_rebounds():
    """Control: removing gravity but keeping the full stress in the internal force makes the
    column spring up (so the equilibrium above is not trivial)."""
    sim, ex = _gravity_stage()
    sim.start_stage(fm.Newmark(), dt=5e-3, gravity=(0.0, 0.0), initial_stress=False)
    sim.run(steps=20)
    assert _max_speed(sim) > 1e-3


def test_dashpot_base_creeps_under_gravity_spring_dashpot_does_not():
    """Keeping gravity and the total stress, a purely viscous base lets the column sink at a
    steady rate (a dashpot carries a static load only by moving), a viscoelastic base does not
    (BENCHMARKS W: pure dashpots under static stress creep)."""
    rates = {}
    for kind in ("viscous", "viscoelastic"):
        sim, ex = _gravity_stage(E=1e9)             # c_p = 707 m/s: sinks ~0.14 m/s if viscous
        sim.start_stage(fm.Newmark(), dt=5e-3, initial_stress=False)
        sim.release(base, [1])
        bc = (fm.Viscous(base) if kind == "viscous" else
              fm.Viscoelastic(base, r_b=10.0))
        sim.add_boundary(bc)
        probe = sim.probe((0.5, 0.25), ["displacement"])
        sim.run(steps=200)
        d = probe.data()
        t, u = d["t"], d["displacement_y"]
        late = t > 0.8 * t[-1]
        rates[kind] = abs(np.polyfit(t[late], u[late], 1)[0])
    # viscous: sinks at about rho g H / (rho c_p) = g H / c_p = 0.14 m/s
    assert 0.5 < rates["viscous"] / (10.0 * 10.0 / np.sqrt(1e9 / 2000.0)) < 1.5, rates
    assert rates["viscous"] > 100 * rates["viscoelastic"], rates


def test_gravity_ramp_follows_seed_002_eq_4_13():
    """L1 ramp: g(t) = g [sin(2 pi t / T - pi/2) + 1] / 2 up to T/2, then g: the nodal gravity
    force at a few times equals m_i times that (relative 1e-14)."""
    import math
    from fenicsmpm.problems.elastic import vibrating_bar
    sim, _ = vibrating_bar(fm.Explicit(), n_cells=4)
    sim = fm.Simulation(sim.grid, sim.particles, fm.Explicit(), dt=sim.dt, gravity=(0.0, -10.0),
                        gravity_ramp=20.0)
    sim.locate_and_shape()
    m = sim.nodal_mass()
    sim.grid.accumulate(m)
    for t in (0.0, 2.5, 5.0, 9.9, 10.0, 30.0):
        f = sim.external_force(t, m)
        g = 10.0 * (0.5 * (math.sin(2 * math.pi * t / 20.0 - 0.5 * math.pi) + 1) if t < 10 else 1.0)
        assert np.allclose(f[:, 1], -g * m, rtol=1e-14, atol=1e-300), t
    with pytest.raises(ValueError, match="'gravity_ramp' must be a time > 0"):
        sim.start_stage(gravity_ramp=-1.0)


def test_keeping_gravity_with_initial_stress_warns_and_sinks():
    """A stage that keeps gravity while sigma_ini balances the geostatic stress loads the column
    with its weight again: a RuntimeWarning names the two ways out, and the column does sink
    (the mistake the warning is for); gravity=(0, 0) or initial_stress=False: no warning."""
    import warnings
    sim, ex = _gravity_stage()
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        sim.start_stage(fm.Newmark(), dt=5e-3)
    hit = [str(w.message) for w in rec if "carries these loads a second time" in str(w.message)]
    assert len(hit) == (1 if sim.comm.rank == 0 else 0), hit
    if hit:
        assert hit[0].startswith("start_stage: gravity (0.0, -10.0) act"), hit[0]
        assert "gravity=(0, 0)" in hit[0] and "initial_stress=False" in hit[0], hit[0]
    sim.run(steps=20)
    assert _max_speed(sim) > 0.5                     # measured 0.97 m/s (47 mm in 0.1 s)
    # measured 0 and 1.5e-3 m/s (the quasi-static stage's tolerance)
    for kw, most in ((dict(gravity=(0.0, 0.0)), 1e-9), (dict(initial_stress=False), 0.01)):
        sim, ex = _gravity_stage()
        with warnings.catch_warnings(record=True) as rec:
            warnings.simplefilter("always")
            sim.start_stage(fm.Newmark(), dt=5e-3, **kw)
        assert not [w for w in rec if "second time" in str(w.message)], kw
        sim.run(steps=20)
        assert _max_speed(sim) < most, kw


def test_a_traction_kept_with_initial_stress_warns():
    """The same for a traction that is not zero at the stage's start (a strip load on a layer,
    kept into a dynamic stage with gravity removed: it loads the layer again); one that is
    zero from the stage on is not named."""
    import warnings
    from dolfinx import mesh as dmesh
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [2.0, 4.0]], [4, 8],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    pts = fm.Particles.fill(grid, fm.LinearElastic(E=20e6, nu=0.3, density=2000.0), per_cell=2)
    sim = fm.Simulation(grid, pts, fm.QuasiStatic(load_steps=2), dt=1.0, gravity=(0, -9.81))
    sim.fix(base)
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], 2.0), [0])
    strip = lambda x: np.isclose(x[:, 1], 4.0) & (x[:, 0] < 0.5 + 1e-9)     # noqa: E731
    sim.add_traction(strip, lambda t: (0.0, -50e3))
    sim.add_traction(strip, lambda t: (0.0, -1e4 if t < 1.5 else 0.0))
    sim.run(steps=2)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        sim.start_stage(fm.Newmark(), dt=5e-3, gravity=(0.0, 0.0))
    hit = [str(w.message) for w in rec if "a second time" in str(w.message)]
    assert len(hit) == (1 if sim.comm.rank == 0 else 0), hit
    if hit:
        assert hit[0].startswith("start_stage: add_traction #0 act in this stage"), hit[0]
        assert "#1" not in hit[0], hit[0]
    sim.run(t_end=sim.t + 0.2)
    uy = sim.comm.allreduce(float(np.min(pts.u[:, 1], initial=0.0)), op=MPI.MIN)
    print(f"\nstrip load kept into the stage: {uy * 1e3:.3f} mm more settlement in 0.2 s")
    assert uy < -2.5e-3, uy                        # measured -5.002 mm (serial, 2 ranks)
