"""kernels.nodal: the explicit grid update's passes give the bits of the numpy expressions
they replace (integrators.explicit before issue 16's change), on a grid large enough for
several chunks (threads) and with inactive nodes, fixed components and negative values."""
import numpy as np
import pytest

from fenicsmpm.kernels import nodal


@pytest.fixture(params=[50, 40_000], ids=["one-chunk", "chunks"])
def nodal_state(request):
    n = request.param
    rng = np.random.default_rng(7)
    m = rng.random(n) * 10.0
    m[rng.random(n) < 0.1] = 0.0
    active = m > 0.5
    mv = rng.normal(size=(n, 2)) * m[:, None]
    f = rng.normal(size=(n, 2)) * 1e3
    fixed = rng.random((n, 2)) < 0.2
    return m, active, mv, f, fixed


def test_grid_update_is_the_numpy_expressions_bit_for_bit(nodal_state):
    m, active, mv, f, fixed = nodal_state
    free, kick = ~fixed, 3.7e-4
    inv_ref = np.divide(1.0, m, out=np.zeros_like(m), where=active)
    inv = np.empty_like(m)
    nodal.inverse_mass(m, active, inv)
    assert np.array_equal(inv, inv_ref)
    v0_ref = mv * inv_ref[:, None] * free
    v0 = np.empty_like(mv)
    nodal.grid_velocity(mv, inv, free, v0)
    assert np.array_equal(v0, v0_ref)
    assert np.array_equal(np.signbit(v0), np.signbit(v0_ref))       # -0.0 where fixed
    v1_ref = v0_ref + kick * f * inv_ref[:, None] * free
    v1 = np.empty_like(mv)
    nodal.kicked_velocity(v0, f, inv, free, kick, v1)
    assert np.array_equal(v1, v1_ref)
    v1_ref[fixed] += 0.25                                          # a prescribed motion
    v1[fixed] += 0.25
    r_ref = np.where(fixed & active[:, None],
                     m[:, None] * (v1_ref - (mv + kick * f) * inv_ref[:, None]) / kick, 0.0)
    r = np.empty_like(mv)
    nodal.fixed_reaction(fixed, active, m, v1, mv, f, inv, kick, r)
    assert np.array_equal(r, r_ref)
    assert np.abs(r).max() > 0.0


def test_particle_acceleration_is_the_velocity_change_over_the_kick(nodal_state):
    _, _, v_new, v_old, _ = nodal_state
    a = v_old.copy()
    nodal.particle_acceleration(v_new, a, 0.5e-3)
    assert np.array_equal(a, (v_new - v_old) / 0.5e-3)
