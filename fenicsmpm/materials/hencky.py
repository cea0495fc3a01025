"""Hencky (logarithmic-strain) hyperelasticity, the material of the AMPLE large-deformation
column (BENCHMARKS.md V2; Coombs & Augarde 2020).

F = dF F_old, J = det F, b = F F^T, eps = ln(b) / 2 (the logarithmic strain),
    tau   = lambda tr(eps) I + 2 mu eps           (Kirchhoff stress),
    sigma = tau / J                                (Cauchy stress).
In uniaxial strain with nu = 0 (stretch l): sigma_yy = E ln(l) / l, the relation of the V2
exact solution.

Tangent with respect to the increment dF (exact, consistent with `stress`):
    db / d dF_kl = e_k (x) (F_old F^T)_l. + transpose,
    d ln(b) = sum_ab f_ab (n_a . db n_b) n_a (x) n_b   (Daleckii-Krein, b = sum_a l_a n_a (x) n_a),
      f_ab = (ln l_a - ln l_b) / (l_a - l_b), f_aa = 1 / l_a (the limit, used for close l),
    d sigma = (lambda tr(d eps) I + 2 mu d eps) / J - sigma tr(dF^-1 d dF).
For J <= 0 (inverted element) the stress and tangent of that particle are NaN.
"""
import math

import numba
import numpy as np

from .neo_hookean import IsotropicHyperelastic, _current_F
from .piola import det3, eigh3, inv3

__all__ = ["Hencky", "hencky_stress_kernel", "hencky_tangent_kernel"]


@numba.njit(cache=True)
def _log_divided_difference(a, b):
    """(ln a - ln b) / (a - b), with its series for a close to b (the limit 1/b)."""
    r = (a - b) / b
    if abs(r) < 1e-5:
        return (1.0 - 0.5 * r + r * r / 3.0) / b
    return (math.log(a) - math.log(b)) / (a - b)


@numba.njit(cache=True)
def _eig_b(F, lam, Q):
    """Eigenvalues lam and eigenvectors (columns of Q) of b = F F^T."""
    b = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            b[i, j] = F[i, 0] * F[j, 0] + F[i, 1] * F[j, 1] + F[i, 2] * F[j, 2]
    eigh3(b, lam, Q)


@numba.njit(cache=True)
def _tau(lam, Q, la, mu, tau):
    """Kirchhoff stress lambda tr(eps) I + 2 mu eps, eps = 1/2 sum_a ln(l_a) n_a n_a."""
    e = np.empty(3)
    for a in range(3):
        e[a] = 0.5 * math.log(lam[a])
    tr = e[0] + e[1] + e[2]
    for i in range(3):
        for j in range(3):
            s = 0.0
            for a in range(3):
                s += 2.0 * mu * e[a] * Q[i, a] * Q[j, a]
            if i == j:
                s += la * tr
            tau[i, j] = s


@numba.njit(cache=True)
def hencky_stress_kernel(idx, dF, F_old, sigma_new, la, mu):
    """sigma = (lambda tr(eps) I + 2 mu eps) / J, eps = ln(F F^T) / 2, F = dF F_old; NaN if J <= 0."""
    F = np.empty((3, 3))
    lam = np.empty(3)
    Q = np.empty((3, 3))
    tau = np.empty((3, 3))
    for q in range(idx.shape[0]):
        p = idx[q]
        _current_F(dF, F_old, p, F)
        J = det3(F)
        if not J > 0.0:
            for i in range(3):
                for j in range(3):
                    sigma_new[p, i, j] = np.nan
            continue
        _eig_b(F, lam, Q)
        _tau(lam, Q, la, mu, tau)
        for i in range(3):
            for j in range(3):
                sigma_new[p, i, j] = tau[i, j] / J


@numba.njit(cache=True)
def hencky_tangent_kernel(idx, dF, F_old, dsig, la, mu):
    """dsig[p,i,j,k,l] = d sigma_ij / d dF_kl (see module docstring); NaN if J <= 0."""
    F = np.empty((3, 3))
    lam = np.empty(3)
    Q = np.empty((3, 3))
    tau = np.empty((3, 3))
    dFinv = np.empty((3, 3))
    G0 = np.empty((3, 3))     # F_old F^T
    f = np.empty((3, 3))
    db = np.empty((3, 3))
    bq = np.empty((3, 3))     # Q^T db Q, then scaled by f / 2 (d eps in the eigenbasis)
    tmp = np.empty((3, 3))
    for q in range(idx.shape[0]):
        p = idx[q]
        _current_F(dF, F_old, p, F)
        J = det3(F)
        if not J > 0.0:
            for i in range(3):
                for j in range(3):
                    for k in range(3):
                        for l in range(3):
                            dsig[p, i, j, k, l] = np.nan
            continue
        _eig_b(F, lam, Q)
        _tau(lam, Q, la, mu, tau)
        inv3(dF[p], dFinv)
        for i in range(3):
            for j in range(3):
                g = 0.0
                for m in range(3):
                    g += F_old[p, i, m] * F[j, m]
                G0[i, j] = g
        for a in range(3):
            for c in range(3):
                f[a, c] = 1.0 / lam[a] if a == c else _log_divided_difference(lam[a], lam[c])
        for k in range(3):
            for l in range(3):
                # db_ij = d_ik G0_lj + d_jk G0_li
                for i in range(3):
                    for j in range(3):
                        v = 0.0
                        if i == k:
                            v += G0[l, j]
                        if j == k:
                            v += G0[l, i]
                        db[i, j] = v
                # bq = Q^T db Q, scaled
                for i in range(3):
                    for c in range(3):
                        s = 0.0
                        for m in range(3):
                            s += db[i, m] * Q[m, c]
                        tmp[i, c] = s
                for a in range(3):
                    for c in range(3):
                        s = 0.0
                        for m in range(3):
                            s += Q[m, a] * tmp[m, c]
                        bq[a, c] = 0.5 * f[a, c] * s
                tr = bq[0, 0] + bq[1, 1] + bq[2, 2]
                # d eps = Q bq Q^T
                for i in range(3):
                    for c in range(3):
                        s = 0.0
                        for a in range(3):
                            s += Q[i, a] * bq[a, c]
                        tmp[i, c] = s
                for i in range(3):
                    for j in range(3):
                        de = 0.0
                        for c in range(3):
                            de += tmp[i, c] * Q[j, c]
                        dt = 2.0 * mu * de
                        if i == j:
                            dt += la * tr
                        dsig[p, i, j, k, l] = dt / J - tau[i, j] / J * dFinv[l, k]


class Hencky(IsotropicHyperelastic):
    """Hencky (logarithmic-strain) hyperelastic solid.

    sigma = (lambda tr(eps) I + 2 mu eps) / J,  eps = ln(b) / 2, b = F F^T, J = det F;
    mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu)).

    Parameters: E > 0, -1 < nu < 0.5, density > 0 (finite reals).
    Particles with J <= 0 get NaN stress (no exception).
    """

    name = "Hencky"
    stress_kernel = hencky_stress_kernel
    tangent_kernel = hencky_tangent_kernel
