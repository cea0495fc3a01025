"""Kernels shared by the isotropic hyperelastic models whose Kirchhoff stress is a function of
b = F F^T through its eigenvalues l_a and eigenvectors n_a (fm.Hencky, fm.BiotElastic), and the
NaN convention of every hyperelastic model (fm.NeoHookean too).

Kirchhoff stress (sigma = tau / J):
    HENCKY  tau = lambda tr(eps) I + 2 mu eps,            eps = ln(b) / 2
    BIOT    tau = lambda (tr V - 3) V + 2 mu (b - V),     V = sqrt(b)
Tangent with respect to the increment dF (F = dF F_old; exact, consistent with the stress):
    db / d dF_kl = e_k (x) (F_old F^T)_l. + transpose,
    dX = sum_ac f_ac (n_a . db n_c) n_a (x) n_c   (Daleckii-Krein for X = sum_a g(l_a) n_a n_a,
         f_ac = (g(l_a) - g(l_c)) / (l_a - l_c), f_aa = g'(l_a)),
         HENCKY: X = eps, g = ln(l) / 2;  BIOT: X = V, g = sqrt(l), f_ac = 1 / (sqrt l_a + sqrt l_c),
    HENCKY  d tau = lambda tr(d eps) I + 2 mu d eps,
    BIOT    d tau = lambda tr(dV) V + lambda (tr V - 3) dV + 2 mu (db - dV),
    d sigma = d tau / J - sigma tr(dF^-1 d dF).
For J <= 0 (inverted element) the stress and tangent of that particle are NaN.
"""
import math

import numba
import numpy as np

from .piola import det3, eigh3, inv3
from ..kernels.threads import PRANGE, chunk, particle_chunks

HENCKY, BIOT = 0, 1


@numba.njit(cache=True)
def current_F(dF, F_old, p, F):
    """F = dF[p] F_old[p]."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += dF[p, i, m] * F_old[p, m, j]
            F[i, j] = s


@numba.njit(cache=True)
def nan_stress(sigma, p):
    """sigma[p] = NaN (an inverted particle, J <= 0)."""
    for i in range(3):
        for j in range(3):
            sigma[p, i, j] = np.nan


@numba.njit(cache=True)
def nan_tangent(dsig, p):
    """dsig[p] = NaN (an inverted particle, J <= 0)."""
    for i in range(3):
        for j in range(3):
            for k in range(3):
                for l in range(3):
                    dsig[p, i, j, k, l] = np.nan


@numba.njit(cache=True)
def old_times_current(F_old, p, F, G0):
    """G0 = F_old[p] F^T (the factor of db / d dF)."""
    for i in range(3):
        for j in range(3):
            g = 0.0
            for m in range(3):
                g += F_old[p, i, m] * F[j, m]
            G0[i, j] = g


@numba.njit(cache=True)
def log_divided_difference(a, b):
    """(ln a - ln b) / (a - b), with its series for a close to b (the limit 1/b)."""
    r = (a - b) / b
    if abs(r) < 1e-5:
        return (1.0 - 0.5 * r + r * r / 3.0) / b
    return (math.log(a) - math.log(b)) / (a - b)


@numba.njit(cache=True)
def eig_b(F, lam, Q):
    """Eigenvalues lam and eigenvectors (columns of Q) of b = F F^T."""
    b = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            b[i, j] = F[i, 0] * F[j, 0] + F[i, 1] * F[j, 1] + F[i, 2] * F[j, 2]
    eigh3(b, lam, Q)


@numba.njit(cache=True)
def congruence(Q, A, out, to_eigenbasis):
    """out = Q^T A Q (to_eigenbasis) or Q A Q^T (3 x 3)."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for a in range(3):
                for b in range(3):
                    if to_eigenbasis:
                        s += Q[a, i] * A[a, b] * Q[b, j]
                    else:
                        s += Q[i, a] * A[a, b] * Q[j, b]
            out[i, j] = s


@numba.njit(cache=True)
def kirchhoff(model, lam, Q, la, mu, X, tau):
    """tau of `model` (module docstring) from the eigenpairs (lam, Q) of b; X = eps (HENCKY) or
    V (BIOT). Returns tr(X) (BIOT: tr V - 3)."""
    g = np.empty(3)
    for a in range(3):
        g[a] = 0.5 * math.log(lam[a]) if model == HENCKY else math.sqrt(lam[a])
    tr = g[0] + g[1] + g[2] - (0.0 if model == HENCKY else 3.0)
    for i in range(3):
        for j in range(3):
            x = 0.0
            t = 0.0
            for a in range(3):
                qq = Q[i, a] * Q[j, a]
                x += g[a] * qq
                if model == HENCKY:
                    t += 2.0 * mu * g[a] * qq
                else:
                    t += (la * tr * g[a] + 2.0 * mu * (lam[a] - g[a])) * qq
            X[i, j] = x
            tau[i, j] = t + (la * tr if model == HENCKY and i == j else 0.0)
    return tr


@numba.njit(cache=True)
def plane_biot_sigma(F, J, la, mu, s):
    """BIOT sigma of an in-plane F (F_i2 = F_2i = 0 for i < 2) without an eigensolve: the
    in-plane block of V = sqrt(b) is (b + sqrt(det b) I) / sqrt(tr b + 2 sqrt(det b)) (2 x 2
    SPD square root), V_22 = |F_22|."""
    b00 = F[0, 0] * F[0, 0] + F[0, 1] * F[0, 1]
    b01 = F[0, 0] * F[1, 0] + F[0, 1] * F[1, 1]
    b11 = F[1, 0] * F[1, 0] + F[1, 1] * F[1, 1]
    r = math.sqrt(b00 * b11 - b01 * b01)
    k = 1.0 / math.sqrt(b00 + b11 + 2.0 * r)
    v00, v01, v11, v22 = (b00 + r) * k, b01 * k, (b11 + r) * k, abs(F[2, 2])
    a = la * (v00 + v11 + v22 - 3.0)
    for i in range(3):
        for j in range(3):
            s[i, j] = 0.0
    s[0, 0] = (a * v00 + 2.0 * mu * (b00 - v00)) / J
    s[1, 1] = (a * v11 + 2.0 * mu * (b11 - v11)) / J
    s[0, 1] = s[1, 0] = (a * v01 + 2.0 * mu * (b01 - v01)) / J
    s[2, 2] = (a * v22 + 2.0 * mu * (v22 * v22 - v22)) / J


@numba.njit(cache=True)
def _stress(model, idx, dF, F_old, sigma_new, la, mu, lo, hi):
    F = np.empty((3, 3))
    lam = np.empty(3)
    Q = np.empty((3, 3))
    X = np.empty((3, 3))
    tau = np.empty((3, 3))
    for q in range(lo, hi):
        p = idx[q]
        current_F(dF, F_old, p, F)
        J = det3(F)
        if not J > 0.0:
            nan_stress(sigma_new, p)
            continue
        if model == BIOT and F[0, 2] == 0.0 and F[1, 2] == 0.0 and F[2, 0] == 0.0 \
                and F[2, 1] == 0.0:
            plane_biot_sigma(F, J, la, mu, sigma_new[p])
            continue
        eig_b(F, lam, Q)
        kirchhoff(model, lam, Q, la, mu, X, tau)
        for i in range(3):
            for j in range(3):
                sigma_new[p, i, j] = tau[i, j] / J


@numba.njit(parallel=PRANGE, cache=True)
def spectral_stress(model, idx, dF, F_old, sigma_new, la, mu):
    """sigma = tau / J of `model` for the particles idx; NaN if J <= 0 (threaded over chunks of
    idx, kernels.threads; BIOT with an in-plane F: plane_biot_sigma)."""
    n = idx.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        _stress(model, idx, dF, F_old, sigma_new, la, mu, np.int64(0), n)
        return
    for c in numba.prange(nc):
        lo, hi = chunk(n, nc, c)
        _stress(model, idx, dF, F_old, sigma_new, la, mu, lo, hi)


@numba.njit(cache=True)
def spectral_tangent(model, idx, dF, F_old, dsig, la, mu):
    """dsig[p,i,j,k,l] = d sigma_ij / d dF_kl of `model` (module docstring); NaN if J <= 0."""
    F = np.empty((3, 3))
    lam = np.empty(3)
    Q = np.empty((3, 3))
    X = np.empty((3, 3))
    tau = np.empty((3, 3))
    dFinv = np.empty((3, 3))
    G0 = np.empty((3, 3))     # F_old F^T
    f = np.empty((3, 3))
    db = np.empty((3, 3))
    bq = np.empty((3, 3))     # f o (Q^T db Q): dX in the eigenbasis
    tmp = np.empty((3, 3))    # dX
    for q in range(idx.shape[0]):
        p = idx[q]
        current_F(dF, F_old, p, F)
        J = det3(F)
        if not J > 0.0:
            nan_tangent(dsig, p)
            continue
        eig_b(F, lam, Q)
        trx = kirchhoff(model, lam, Q, la, mu, X, tau)
        inv3(dF[p], dFinv)
        old_times_current(F_old, p, F, G0)
        for a in range(3):
            for c in range(3):
                if model == HENCKY:
                    f[a, c] = 0.5 / lam[a] if a == c else 0.5 * log_divided_difference(lam[a], lam[c])
                else:
                    f[a, c] = 1.0 / (math.sqrt(lam[a]) + math.sqrt(lam[c]))
        for k in range(3):
            for l in range(3):
                for i in range(3):            # db_ij = d_ik G0_lj + d_jk G0_li
                    for j in range(3):
                        v = 0.0
                        if i == k:
                            v += G0[l, j]
                        if j == k:
                            v += G0[l, i]
                        db[i, j] = v
                congruence(Q, db, bq, True)   # bq = f o (Q^T db Q), dX = Q bq Q^T
                for a in range(3):
                    for c in range(3):
                        bq[a, c] *= f[a, c]
                trdx = bq[0, 0] + bq[1, 1] + bq[2, 2]
                congruence(Q, bq, tmp, False)
                for i in range(3):
                    for j in range(3):
                        dx = tmp[i, j]
                        if model == HENCKY:
                            dtau = 2.0 * mu * dx + (la * trdx if i == j else 0.0)
                        else:
                            dtau = la * trdx * X[i, j] + la * trx * dx + 2.0 * mu * (db[i, j] - dx)
                        dsig[p, i, j, k, l] = dtau / J - tau[i, j] / J * dFinv[l, k]
