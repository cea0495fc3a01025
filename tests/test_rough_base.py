"""Rough (frictional) rigid bases that hold a body at rest (issue 17; boundaries.friction:
unilateral, gap-consistent contact with Coulomb friction, seed 002 §5.1).

Scenes and known answers: fenicsmpm.problems.friction (an elastic block 1 m x 0.5 m on a
rough base, an incline or a rigid body; static settlement 0.1488 mm)."""
import numpy as np
import pytest

from fenicsmpm.problems.friction import G, STATIC, block_on_base, block_on_rigid_body


@pytest.mark.parametrize("scheme,cfl,mu", [("USF", 0.5, 0.5), ("USL", 0.5, 0.5), ("MUSL", 0.5, 0.5),
                                           ("AVG", 0.5, 0.5), ("MUSL", 0.9, 0.5), ("USF", 0.9, 0.5),
                                           ("AVG", 0.9, 0.5), ("MUSL", 0.5, 0.0)])
def test_block_rests_on_rough_base(scheme, cfl, mu):
    """Gravity from t = 0 on a stress-free block, h = 0.1 m, 2 s. The centroid never rises
    above its start (0.05 mm; before the gap-consistent contact it climbed 5.5 mm with MUSL and
    50 mm with USF in 1 s). Its mean settlement over the second second: mu = 0 within 3 % of
    the static one (measured -1.5 %); mu = 0.5 between a no-slip base (a fixed base: 0.897
    STATIC) and free slip (measured 0.924-0.926 STATIC; USL 0.890). Mean energy balance error
    over the second second within 1 % at cfl 0.5 (measured 0.26-0.46 %) and 2.5 % at cfl 0.9
    (1.4-1.8 %); USL dissipates 35 % on a roller or fixed base as well (measured -35.1 %
    here, -34.6 % on a roller). USL at cfl 0.9 inverts particles on a roller base too (an
    instability of USL, not of the base): not run."""
    sim, base, hist = block_on_base(scheme, mu=mu, cfl=cfl, h=0.1)
    sim.monitor_energy(every=50, tolerance=1.0)
    sim.run(t_end=2.0)
    h = np.array(hist)
    assert h[:, 2].max() < 0.05e-3, h[:, 2].max()
    late = -h[:, 2][h[:, 0] > 1.0].mean()
    if mu == 0:
        assert abs(late - STATIC) < 0.03 * STATIC, (late, STATIC)
    else:                        # between a no-slip base (0.897 STATIC) and free slip (STATIC)
        assert 0.85 * STATIC < late < 1.02 * STATIC, (late, STATIC)
    err = np.array([e["balance_error"] for e in sim.energy_history if e["t"] > 1.0])
    print(scheme, cfl, mu, "settlement", late / STATIC, "balance mean", err.mean(), "max", abs(err).max())
    bound = 0.40 if scheme == "USL" else (0.01 if cfl == 0.5 else 0.025)
    assert abs(err.mean()) < bound, err.mean()
    assert abs(h[:, 1]).max() < 1e-6                      # no sideways drift on a flat base
    assert base.reaction()[1] < 0.0                       # the block presses on the base


def test_reaction_carries_the_weight():
    """The mean normal reaction over the last second equals the weight (within 1 %; measured
    -0.05 %) and the tangential one vanishes on a flat base."""
    sim, base, _ = block_on_base("MUSL", mu=0.5, h=0.1)
    r = []
    sim.observe(lambda s: r.append(base.reaction()) if s.t > 1.0 else None)
    sim.run(t_end=2.0)
    r = np.mean(r, axis=0)
    weight = sim.particles.total(sim.particles.mass) * G
    assert abs(-r[1] - weight) < 0.01 * weight, (r, weight)
    assert abs(r[0]) < 1e-3 * weight, r


@pytest.mark.parametrize("inclined_mesh", [False, True])
@pytest.mark.parametrize("mu,start", [(0.7, "geostatic"), (0.7, "ramp"), (0.3, "geostatic"),
                                      (0.0, "geostatic")])
def test_block_on_30_degree_incline(mu, start, inclined_mesh):
    """30 deg incline for 0.5 s (gravity rotated, or the mesh rotated with the base normal
    from its facets): mu = 0.7 sticks (< 0.5 % of the frictionless 613 mm) from a geostatic
    state and from rest with a 0.2 s gravity ramp; mu = 0.3 slides with
    a = g (sin - mu cos) within 2 %, mu = 0 within 0.5 % (measured +0.08 % for both)."""
    th = np.radians(30.0)
    sim, base, hist = block_on_base("MUSL", mu=mu, theta=30.0, geostatic=start == "geostatic",
                             ramp=0.2 if start == "ramp" else None, inclined_mesh=inclined_mesh)
    sim.run(t_end=0.5)
    t, along = hist[-1][0], hist[-1][1]
    free = 0.5 * G * np.sin(th) * t ** 2
    a = G * (np.sin(th) - mu * np.cos(th))
    if a <= 0:
        assert abs(along) < 0.005 * free, (along, free)
        assert max(hh[2] for hh in hist) < 0.05e-3       # no lift
    else:
        exact = 0.5 * a * t ** 2
        assert abs(along - exact) < (0.005 if mu == 0 else 0.02) * exact, (along, exact)


@pytest.mark.parametrize("theta,mu", [(0.0, 0.5), (30.0, 0.7), (30.0, 0.3)])
@pytest.mark.heavy
def test_rough_base_under_explicit_contact(theta, mu):
    """The same block as two bodies (fm.ExplicitContact, multi-velocity, mu = 0.5 between
    them): each body's field has its own contact status on the base. Flat base: no climb,
    static settlement within 10 %; 30 deg: mu = 0.7 sticks, mu = 0.3 slides within 2 %."""
    sim, base, hist = block_on_base("MUSL", mu=mu, theta=theta, geostatic=theta > 0, contact=True)
    sim.run(t_end=1.0 if theta == 0 else 0.5)
    h = np.array(hist)
    if theta == 0:
        assert h[:, 2].max() < 0.05e-3, h[:, 2].max()
        late = h[:, 2][h[:, 0] > 0.5].mean()
        assert abs(-late - STATIC) < 0.10 * STATIC, (late, STATIC)
        return
    th = np.radians(theta)
    a = G * (np.sin(th) - mu * np.cos(th))
    t, along = h[-1, 0], h[-1, 1]
    if a <= 0:
        assert abs(along) < 0.005 * 0.5 * G * np.sin(th) * t ** 2, along
    else:
        assert abs(along - 0.5 * a * t ** 2) < 0.02 * 0.5 * a * t ** 2, (along, 0.5 * a * t ** 2)


@pytest.mark.parametrize("algorithm,mu,h", [("multi-velocity", 0.7, 0.05), ("multi-velocity", 0.3, 0.05),
                                            ("multi-velocity", 0.0, 0.05), ("penalty", 0.7, 0.05),
                                            ("penalty", 0.3, 0.1), ("penalty", 0.0, 0.1)])
@pytest.mark.heavy
def test_block_on_rigid_incline_body(algorithm, mu, h):
    """The incline as a rigid body, 30 deg, 0.5 s from the geostatic state. Multi-velocity
    (exact gap against the rigid body's particles, prescribed normal): mu = 0.7 sticks
    (measured 0.55 mm, < 0.5 % of the frictionless 613 mm; before: 156 mm) and does not sink
    (measured 0.03 mm; before: 24 mm); mu = 0.3 within 2 % of a t^2 / 2 (measured +0.09 % on
    2026-12-05; before +10 %), mu = 0 within 0.5 % (measured +0.06 %). Penalty (polylines on both faces;
    the springs start in equilibrium with the initial stress, the normal dashpot and MUSL's
    re-mapped vertex motion of contact.penalty "Normal damping"): mu = 0.7 at h = 0.05
    measured 1.03 mm (0.17 %; before 40 mm, 6.5 %), lift 0.035 mm, sinks 0.027 mm; at
    h = 0.1 mu = 0.3 +0.04 %, mu = 0 +0.02 %."""
    sim, hist = block_on_rigid_body(mu, algorithm=algorithm, h=h)
    sim.run(t_end=0.5)
    h = np.array(hist)
    th = np.radians(30.0)
    t, along = h[-1, 0], h[-1, 1]
    a = G * (np.sin(th) - mu * np.cos(th))
    assert h[:, 2].min() > -0.5e-3, h[:, 2].min()          # no sinking into the rigid body
    if a <= 0:
        assert abs(along) < 0.005 * 0.5 * G * np.sin(th) * t ** 2, along
        assert h[:, 2].max() < 0.05e-3, h[:, 2].max()      # no lift
    else:
        exact = 0.5 * a * t ** 2
        assert abs(along - exact) < (0.005 if mu == 0 else 0.02) * exact, (along, exact)


@pytest.mark.parametrize("shape", ["cpgimp", "auto"])
def test_block_rests_on_rough_base_with_wide_shapes(shape):
    """The rest test with cpGIMP (and shape='auto'), MUSL, mu = 0.5, h = 0.1, 2 s: no climb
    (measured -0.023 mm), settlement between no-slip and free slip (measured 0.920 STATIC)."""
    sim, base, hist = block_on_base("MUSL", mu=0.5, h=0.1, shape=shape)
    sim.run(t_end=2.0)
    h = np.array(hist)
    assert h[:, 2].max() < 0.05e-3, h[:, 2].max()
    late = -h[:, 2][h[:, 0] > 1.0].mean()
    assert 0.85 * STATIC < late < 1.02 * STATIC, (late, STATIC)


@pytest.mark.parametrize("scheme", ["MUSL", "USF"])
def test_block_rests_on_rough_base_with_apic(scheme):
    """The rest test with the affine transfer (fm.Explicit(transfer="apic")), cpGIMP,
    mu = 0.5, h = 0.1, 2 s: no climb (measured -0.037 mm, MUSL and USF) and the settlement
    within 10 % of the static one (measured 0.905 / 0.904 STATIC). APIC dissipates: the energy
    balance over the second second is -1.5 % (MUSL) / -1.6 % (USF) with cpGIMP, -25 % with
    the standard family (not asserted)."""
    sim, base, hist = block_on_base(scheme, mu=0.5, h=0.1, shape="cpgimp", transfer="apic")
    sim.run(t_end=2.0)
    h = np.array(hist)
    assert h[:, 2].max() < 0.05e-3, h[:, 2].max()
    late = -h[:, 2][h[:, 0] > 1.0].mean()
    assert 0.9 * STATIC < late < 1.1 * STATIC, (late, STATIC)
