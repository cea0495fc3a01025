"""Tests for fenicsmpm.materials (pure numpy + numba; safe under mpirun)."""
import math

import numpy as np
import pytest

from fenicsmpm.materials import (LinearElastic, NeoHookean, first_piola,
                                 first_piola_tangent, strain_energy_increment)
from fenicsmpm.materials.validation import check_open_interval, check_positive

E, NU, RHO = 2.0e7, 0.3, 2000.0
MODELS = [LinearElastic, NeoHookean]


def _arrays(n):
    dF = np.tile(np.eye(3), (n, 1, 1))
    F_old = np.tile(np.eye(3), (n, 1, 1))
    s_old = np.zeros((n, 3, 3))
    s_new = np.zeros((n, 3, 3))
    state = np.zeros((n, 0))
    return dF, F_old, s_old, s_new, state


def _sym(A):
    return 0.5 * (A + A.T)


def _rotation(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def _random_state(rng, n=3, h=0.05):
    dF = np.eye(3) + h * rng.uniform(-1, 1, (n, 3, 3))
    F_old = np.eye(3) + 0.1 * rng.uniform(-1, 1, (n, 3, 3))
    s_old = np.array([_sym(rng.uniform(-1, 1, (3, 3))) for _ in range(n)]) * 1e5
    return (np.ascontiguousarray(dF), np.ascontiguousarray(F_old),
            np.ascontiguousarray(s_old))


# ---------------------------------------------------------------- validation
@pytest.mark.parametrize("cls", MODELS)
@pytest.mark.parametrize("kwargs,name,val", [
    (dict(E=-1.0, nu=0.3, density=1.0), "E", "-1.0"),
    (dict(E=0.0, nu=0.3, density=1.0), "E", "0.0"),
    (dict(E=1.0, nu=0.5, density=1.0), "nu", "0.5"),
    (dict(E=1.0, nu=-1.0, density=1.0), "nu", "-1.0"),
    (dict(E=1.0, nu=0.3, density=0.0), "density", "0.0"),
    (dict(E=1.0, nu=0.3, density=-5.0), "density", "-5.0"),
    (dict(E=float("nan"), nu=0.3, density=1.0), "E", "nan"),
    (dict(E=1.0, nu=0.3, density=float("inf")), "density", "inf"),
])
def test_invalid_parameters(cls, kwargs, name, val):
    with pytest.raises(ValueError) as exc:
        cls(**kwargs)
    msg = str(exc.value)
    assert cls.__name__ in msg and f"'{name}'" in msg and val in msg


@pytest.mark.parametrize("cls", MODELS)
def test_string_parameter_typeerror(cls):
    with pytest.raises(TypeError) as exc:
        cls("abc", 0.3, 1.0)
    msg = str(exc.value)
    assert cls.__name__ in msg and "'E'" in msg and "abc" in msg
    with pytest.raises(TypeError):
        cls(1.0, True, 1.0)


def test_validation_message_format():
    with pytest.raises(ValueError, match=r"^LinearElastic: parameter 'E' must be > 0, got -1.0$"):
        LinearElastic(-1.0, 0.3, 1.0)
    assert check_positive("X", "a", 3) == 3.0
    assert check_open_interval("X", "b", np.float64(0.1), 0.0, 1.0) == 0.1


@pytest.mark.parametrize("cls", MODELS)
def test_derived_constants(cls):
    m = cls(E, NU, RHO)
    G = E / (2 * (1 + NU))
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    K = E / (3 * (1 - 2 * NU))
    M = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    assert m.E == E and m.nu == NU and m.density == RHO
    assert m.shear_modulus == pytest.approx(G, rel=1e-14)
    assert m.lame_lambda == pytest.approx(lam, rel=1e-14)
    assert m.bulk_modulus == pytest.approx(K, rel=1e-14)
    assert m.constrained_modulus == pytest.approx(M, rel=1e-14)
    assert m.constrained_modulus == pytest.approx(lam + 2 * G, rel=1e-14)
    assert m.bulk_modulus == pytest.approx(lam + 2 * G / 3, rel=1e-14)
    assert m.p_wave_speed == pytest.approx(math.sqrt(M / RHO), rel=1e-14)
    assert m.s_wave_speed == pytest.approx(math.sqrt(G / RHO), rel=1e-14)
    assert m.n_state == 0 and m.name == cls.__name__


# ------------------------------------------------------------- uniaxial strain
def test_uniaxial_strain():
    eps = 1e-6
    res = {}
    for cls in MODELS:
        m = cls(E, NU, RHO)
        dF, F_old, s_old, s_new, state = _arrays(1)
        dF[0, 0, 0] += eps
        m.stress(np.array([0]), dF, F_old, s_old, s_new, state)
        res[cls] = s_new[0].copy()
    M = LinearElastic(E, NU, RHO).constrained_modulus
    lam = LinearElastic(E, NU, RHO).lame_lambda
    lin = res[LinearElastic]
    # strain actually represented by dF (1 + 1e-6 is rounded in binary)
    eps_rep = (1.0 + eps) - 1.0
    assert abs(lin[0, 0] - M * eps_rep) <= 1e-10 * M * eps_rep
    assert abs(lin[1, 1] - lam * eps_rep) <= 1e-10 * M * eps_rep
    assert abs(lin[0, 0] - M * eps) <= 1e-9 * M * eps
    # neo-Hookean agrees with linear to O(eps^2)
    assert np.max(np.abs(res[NeoHookean] - lin)) <= 10 * M * eps ** 2


# ------------------------------------------------------ tangent vs finite diff
def _fd_tangent(m, p, dF, F_old, s_old, state, step=1e-6):
    n = dF.shape[0]
    idx = np.array([p])
    D = np.zeros((3, 3, 3, 3))
    for k in range(3):
        for l in range(3):
            sp = np.zeros((n, 3, 3))
            sm = np.zeros((n, 3, 3))
            d = dF.copy()
            d[p, k, l] += step
            m.stress(idx, d, F_old, s_old, sp, state)
            d[p, k, l] -= 2 * step
            m.stress(idx, d, F_old, s_old, sm, state)
            D[:, :, k, l] = (sp[p] - sm[p]) / (2 * step)
    return D


@pytest.mark.parametrize("cls", MODELS)
def test_tangent_matches_finite_differences(cls):
    rng = np.random.default_rng(1234)
    m = cls(E, NU, RHO)
    n = 3
    dF, F_old, s_old = _random_state(rng, n)
    state = np.zeros((n, 0))
    s_new = np.zeros((n, 3, 3))
    dsig = np.zeros((n, 3, 3, 3, 3))
    idx = np.arange(n, dtype=np.int64)
    m.stress(idx, dF, F_old, s_old, s_new, state)
    m.tangent(idx, dF, F_old, s_old, s_new, state, dsig)
    for p in range(n):
        D = _fd_tangent(m, p, dF, F_old, s_old, state)
        err = np.max(np.abs(D - dsig[p])) / np.linalg.norm(dsig[p])
        assert err < 1e-6, err


def test_first_piola_tangent_matches_finite_differences():
    rng = np.random.default_rng(99)
    n = 2
    idx = np.arange(n, dtype=np.int64)
    for cls in MODELS:
        m = cls(E, NU, RHO)
        dF, F_old, s_old = _random_state(rng, n)
        state = np.zeros((n, 0))
        s_new = np.zeros((n, 3, 3))
        dsig = np.zeros((n, 3, 3, 3, 3))
        A = np.zeros((n, 3, 3, 3, 3))
        m.stress(idx, dF, F_old, s_old, s_new, state)
        m.tangent(idx, dF, F_old, s_old, s_new, state, dsig)
        first_piola_tangent(idx, dF, s_new, dsig, A)

        def P_of(d):
            s = np.zeros((n, 3, 3))
            P = np.zeros((n, 3, 3))
            m.stress(idx, d, F_old, s_old, s, state)
            first_piola(idx, d, s, P)
            return P

        # P = J sigma dF^-T
        P0 = P_of(dF)
        for p in range(n):
            ref = np.linalg.det(dF[p]) * s_new[p] @ np.linalg.inv(dF[p]).T
            assert np.allclose(P0[p], ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
        h = 1e-6
        Afd = np.zeros_like(A)
        for k in range(3):
            for l in range(3):
                d = dF.copy()
                d[:, k, l] += h
                Pp = P_of(d)
                d[:, k, l] -= 2 * h
                Pm = P_of(d)
                Afd[:, :, :, k, l] = (Pp - Pm) / (2 * h)
        for p in range(n):
            err = np.max(np.abs(Afd[p] - A[p])) / np.linalg.norm(A[p])
            assert err < 1e-6, (cls.__name__, err)


# --------------------------------------------------------------- objectivity
@pytest.mark.parametrize("cls", MODELS)
def test_rigid_translation_keeps_stress(cls):
    rng = np.random.default_rng(5)
    m = cls(E, NU, RHO)
    n = 4
    dF, F_old, s_old = _random_state(rng, n)
    dF[:] = np.eye(3)
    state = np.zeros((n, 0))
    idx = np.arange(n, dtype=np.int64)
    if cls is NeoHookean:
        # stress state consistent with F_old
        m.stress(idx, dF, F_old, np.zeros_like(s_old), s_old, state)
    s_new = np.zeros((n, 3, 3))
    m.stress(idx, dF, F_old, s_old, s_new, state)
    assert np.array_equal(s_new, s_old)


def test_neo_hookean_pure_rotation_zero_stress():
    rng = np.random.default_rng(7)
    m = NeoHookean(E, NU, RHO)
    n = 5
    dF, F_old, s_old, s_new, state = _arrays(n)
    for p in range(n):
        dF[p] = _rotation(rng)
    m.stress(np.arange(n), dF, F_old, s_old, s_new, state)
    assert np.max(np.abs(s_new)) <= 1e-12 * E


def test_neo_hookean_objectivity():
    rng = np.random.default_rng(8)
    m = NeoHookean(E, NU, RHO)
    n = 4
    dF, F_old, s_old = _random_state(rng, n, h=0.2)
    state = np.zeros((n, 0))
    idx = np.arange(n, dtype=np.int64)
    s1 = np.zeros((n, 3, 3))
    m.stress(idx, dF, F_old, s_old, s1, state)
    R = np.array([_rotation(rng) for _ in range(n)])
    dF_rot = np.ascontiguousarray(R @ dF)
    s2 = np.zeros((n, 3, 3))
    m.stress(idx, dF_rot, F_old, s_old, s2, state)
    expect = R @ s1 @ np.transpose(R, (0, 2, 1))
    assert np.max(np.abs(s2 - expect)) <= 1e-9 * np.max(np.abs(s1))


def test_linear_elastic_jaumann_rotation_first_order():
    # Small rotation increment: sigma_new = sigma_old + omega s - s omega, exactly.
    m = LinearElastic(E, NU, RHO)
    dF, F_old, s_old, s_new, state = _arrays(1)
    th = 1e-3
    dF[0] = np.eye(3) + np.array([[0, -th, 0], [th, 0, 0], [0, 0, 0]])
    s_old[0] = np.diag([1.0, 0.0, 0.0])
    m.stress(np.array([0]), dF, F_old, s_old, s_new, state)
    assert s_new[0, 0, 1] == pytest.approx(th) and s_new[0, 1, 0] == pytest.approx(th)
    assert s_new[0, 0, 0] == 1.0 and s_new[0, 1, 1] == 0.0


# -------------------------------------------------------------- plane strain
def test_plane_strain_linear_elastic():
    rng = np.random.default_rng(3)
    m = LinearElastic(E, NU, RHO)
    dF, F_old, s_old, s_new, state = _arrays(1)
    dF[0, :2, :2] += 1e-3 * rng.uniform(-1, 1, (2, 2))
    m.stress(np.array([0]), dF, F_old, s_old, s_new, state)
    tr = dF[0, 0, 0] + dF[0, 1, 1] - 2.0
    assert s_new[0, 2, 2] == pytest.approx(m.lame_lambda * tr, rel=1e-12)
    assert s_new[0, 0, 2] == 0.0 and s_new[0, 1, 2] == 0.0 and s_new[0, 2, 0] == 0.0


# ----------------------------------------------------------- subset writing
@pytest.mark.parametrize("cls", MODELS)
def test_only_idx_rows_written(cls):
    rng = np.random.default_rng(11)
    m = cls(E, NU, RHO)
    n = 6
    dF, F_old, s_old = _random_state(rng, n)
    state = np.zeros((n, 0))
    idx = np.array([1, 4], dtype=np.int64)
    others = np.array([0, 2, 3, 5])
    s_new = np.full((n, 3, 3), -7.0)
    dsig = np.full((n, 3, 3, 3, 3), -7.0)
    P = np.full((n, 3, 3), -7.0)
    A = np.full((n, 3, 3, 3, 3), -7.0)
    w = np.full(n, -7.0)
    m.stress(idx, dF, F_old, s_old, s_new, state)
    m.tangent(idx, dF, F_old, s_old, s_new, state, dsig)
    first_piola(idx, dF, s_new, P)
    first_piola_tangent(idx, dF, s_new, dsig, A)
    strain_energy_increment(idx, dF, s_old, s_new, np.ones(n), np.ones(n), w)
    for arr in (s_new, dsig, P, A, w):
        assert np.all(arr[others] == -7.0)
        assert not np.any(arr[idx] == -7.0)


# ------------------------------------------------------------- inversion
def test_neo_hookean_inverted_gives_nan():
    m = NeoHookean(E, NU, RHO)
    dF, F_old, s_old, s_new, state = _arrays(3)
    dF[1] = np.diag([-1.0, 1.0, 1.0])   # J < 0
    dF[2] = np.diag([0.0, 1.0, 1.0])    # J = 0
    dsig = np.zeros((3, 3, 3, 3, 3))
    idx = np.arange(3)
    m.stress(idx, dF, F_old, s_old, s_new, state)
    m.tangent(idx, dF, F_old, s_old, s_new, state, dsig)
    assert np.all(np.isfinite(s_new[0]))
    assert np.all(np.isnan(s_new[1])) and np.all(np.isnan(s_new[2]))
    assert np.all(np.isnan(dsig[1])) and np.all(np.isnan(dsig[2]))


# ------------------------------------------------------------ energy monitor
def test_strain_energy_increment():
    rng = np.random.default_rng(21)
    n = 3
    dF, _, s_old = _random_state(rng, n)
    s_new = s_old + 1e4 * rng.uniform(-1, 1, (n, 3, 3))
    vo = rng.uniform(1, 2, n)
    vn = rng.uniform(1, 2, n)
    w = np.ones(n)
    idx = np.arange(n, dtype=np.int64)
    strain_energy_increment(idx, dF, s_old, s_new, vo, vn, w)
    for p in range(n):
        eps = _sym(dF[p] - np.eye(3))
        ref = 1.0 + 0.5 * (np.sum(s_old[p] * eps) * vo[p] + np.sum(s_new[p] * eps) * vn[p])
        assert w[p] == pytest.approx(ref, rel=1e-13)


def test_uniaxial_energy_matches_half_M_eps2():
    m = LinearElastic(E, NU, RHO)
    dF, F_old, s_old, s_new, state = _arrays(1)
    eps = 1e-4
    dF[0, 0, 0] += eps
    m.stress(np.array([0]), dF, F_old, s_old, s_new, state)
    w = np.zeros(1)
    strain_energy_increment(np.array([0]), dF, s_old, s_new, np.ones(1), np.ones(1), w)
    assert w[0] == pytest.approx(0.5 * m.constrained_modulus * eps ** 2, rel=1e-12)
