"""Isotropic linear (hypo)elasticity with the Jaumann objective rate.

Incremental update over one step with h = dF - I:
    eps   = sym(h),  omega = skew(h) = (h - h^T)/2
    sigma_new = sigma_old + lambda tr(eps) I + 2 mu eps + omega sigma_old - sigma_old omega
(Jaumann-rate hypoelasticity, e.g. Belytschko, Liu & Moran, *Nonlinear Finite
Elements for Continua and Structures*, sec. 5.7; the explicit-MPM update of
Sulsky, Zhou & Schreyer 1995).  The update is exactly linear in h, so the
tangent below is exact:
    d sigma_ij / d h_kl = lambda d_ij d_kl + mu (d_ik d_jl + d_il d_jk)
                        + 1/2 (d_ik s_lj - d_il s_kj) - 1/2 (s_ik d_jl - s_il d_jk),
with s = sigma_old.
"""
import math

import numba
import numpy as np

from .validation import check_open_interval, check_positive
from ..kernels.threads import PRANGE, chunk, particle_chunks

__all__ = ["LinearElastic", "IsotropicElasticParameters", "jaumann_tangent", "jaumann_update",
           "strain_spin", "linear_elastic_stress_kernel", "linear_elastic_tangent_kernel"]


class IsotropicElasticParameters:
    """Validated (E, nu, density) and the derived isotropic elastic constants.

    mu = E / (2 (1 + nu)),  lambda = E nu / ((1 + nu)(1 - 2 nu)),
    K = E / (3 (1 - 2 nu)),  M = E (1 - nu) / ((1 + nu)(1 - 2 nu)),
    c_p = sqrt(M / rho),  c_s = sqrt(G / rho).
    """

    n_state = 0
    name = "IsotropicElastic"

    def _set_parameters(self, E, nu, density):
        owner = type(self).__name__
        self._E = check_positive(owner, "E", E)
        self._nu = check_open_interval(owner, "nu", nu, -1.0, 0.5)
        self._density = check_positive(owner, "density", density)

    @property
    def E(self):
        """Young's modulus."""
        return self._E

    @property
    def nu(self):
        """Poisson's ratio."""
        return self._nu

    @property
    def density(self):
        """Mass density (reference)."""
        return self._density

    @property
    def shear_modulus(self):
        """G = mu = E / (2 (1 + nu))."""
        return self._E / (2.0 * (1.0 + self._nu))

    G = shear_modulus
    mu = shear_modulus

    @property
    def lame_lambda(self):
        """lambda = E nu / ((1 + nu)(1 - 2 nu))."""
        return self._E * self._nu / ((1.0 + self._nu) * (1.0 - 2.0 * self._nu))

    @property
    def bulk_modulus(self):
        """K = E / (3 (1 - 2 nu))."""
        return self._E / (3.0 * (1.0 - 2.0 * self._nu))

    K = bulk_modulus

    @property
    def constrained_modulus(self):
        """M = E (1 - nu) / ((1 + nu)(1 - 2 nu)) = lambda + 2 mu (P-wave modulus)."""
        return self._E * (1.0 - self._nu) / ((1.0 + self._nu) * (1.0 - 2.0 * self._nu))

    @property
    def p_wave_speed(self):
        """c_p = sqrt(M / rho)."""
        return math.sqrt(self.constrained_modulus / self._density)

    @property
    def s_wave_speed(self):
        """c_s = sqrt(G / rho)."""
        return math.sqrt(self.shear_modulus / self._density)

    def __repr__(self):
        return (f"{type(self).__name__}(E={self._E!r}, nu={self._nu!r}, "
                f"density={self._density!r})")


@numba.njit(cache=True)
def strain_spin(dF, eps, om, m=3):
    """The step's strain and spin increments of one particle (3x3 arrays):
    eps = sym(dF - I), om = skew(dF - I); m = 2: the in-plane block only."""
    for i in range(m):
        for j in range(m):
            hij = dF[i, j] - (1.0 if i == j else 0.0)
            hji = dF[j, i] - (1.0 if i == j else 0.0)
            eps[i, j] = 0.5 * (hij + hji)
            om[i, j] = 0.5 * (hij - hji)


@numba.njit(cache=True)
def jaumann_update(dF, s_old, lam, mu, s_new, eps, om, m=3):
    """One particle (3x3 arrays): s_new = s_old + lam tr(eps) I + 2 mu eps + om s_old - s_old om,
    eps = sym(dF - I), om = skew(dF - I) (strain_spin; eps, om: 3x3 scratch). m = 2: the
    in-plane block of a plane-strain state (out-of-plane rows of dF those of I, no
    out-of-plane shear), where the terms left out are products with exact zeros; sigma_zz is
    then s_old_zz + lam tr(eps) (kernels.fused). Returns tr(eps)."""
    strain_spin(dF, eps, om, m)
    tr = 0.0
    for i in range(m):
        tr += eps[i, i]
    for i in range(m):
        for j in range(m):
            s = s_old[i, j] + 2.0 * mu * eps[i, j]
            if i == j:
                s += lam * tr
            for k in range(m):
                s += om[i, k] * s_old[k, j] - s_old[i, k] * om[k, j]
            s_new[i, j] = s
    return tr


@numba.njit(cache=True)
def _stress(idx, dF, sigma_old, sigma_new, lam, mu, lo, hi):
    eps = np.empty((3, 3))
    om = np.empty((3, 3))
    for q in range(lo, hi):
        p = idx[q]
        jaumann_update(dF[p], sigma_old[p], lam, mu, sigma_new[p], eps, om)


@numba.njit(parallel=PRANGE, cache=True)
def linear_elastic_stress_kernel(idx, dF, sigma_old, sigma_new, lam, mu):
    """sigma_new = sigma_old + lam tr(eps) I + 2 mu eps + omega sigma_old - sigma_old omega
    (threaded over chunks of idx, kernels.threads)."""
    n = idx.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _stress(idx, dF, sigma_old, sigma_new, lam, mu, np.int64(0), n)
    for c in numba.prange(nc):
        lo, hi = chunk(n, nc, c)
        _stress(idx, dF, sigma_old, sigma_new, lam, mu, lo, hi)


@numba.njit(cache=True)
def jaumann_tangent(i, j, k, l, lam, mu, s):
    """d sigma_ij / d dF_kl of the Jaumann-rate elastic update with s = sigma_old:
    lam d_ij d_kl + mu (d_ik d_jl + d_il d_jk) + 1/2 (d_ik s_lj - d_il s_kj)
    - 1/2 (s_ik d_jl - s_il d_jk) (also the elastic predictor of the plastic models)."""
    v = 0.0
    if i == j and k == l:
        v += lam
    if i == k and j == l:
        v += mu
    if i == l and j == k:
        v += mu
    if i == k:
        v += 0.5 * s[l, j]
    if i == l:
        v -= 0.5 * s[k, j]
    if j == l:
        v -= 0.5 * s[i, k]
    if j == k:
        v += 0.5 * s[i, l]
    return v


@numba.njit(cache=True)
def _tangent(idx, sigma_old, dsig, lam, mu, lo, hi):
    for q in range(lo, hi):
        p = idx[q]
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    for l in range(3):
                        dsig[p, i, j, k, l] = jaumann_tangent(i, j, k, l, lam, mu, sigma_old[p])


@numba.njit(parallel=PRANGE, cache=True)
def linear_elastic_tangent_kernel(idx, sigma_old, dsig, lam, mu):
    """dsig[p,i,j,k,l] = lam d_ij d_kl + mu (d_ik d_jl + d_il d_jk)
    + 1/2 (d_ik s_lj - d_il s_kj) - 1/2 (s_ik d_jl - s_il d_jk),  s = sigma_old (threaded
    over chunks of idx, kernels.threads)."""
    n = idx.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        _tangent(idx, sigma_old, dsig, lam, mu, 0, n)
        return
    for c in numba.prange(nc):
        lo, hi = chunk(n, nc, c)
        _tangent(idx, sigma_old, dsig, lam, mu, lo, hi)


class LinearElastic(IsotropicElasticParameters):
    """Isotropic linear elasticity, Jaumann-rate hypoelastic update.

    sigma_new = sigma_old + lambda tr(eps) I + 2 mu eps + omega sigma_old - sigma_old omega,
    eps = sym(dF - I), omega = skew(dF - I)  (Belytschko, Liu & Moran, sec. 5.7).
    At finite strain it is its own material: in uniaxial strain sigma = E ln(l) (nu = 0),
    stiffer in compression than small-strain elasticity (a column at 4 % strain: a period
    0.7 % short). To compare with small-strain elastic solutions at finite amplitude use
    fm.BiotElastic, whose nominal stress in uniaxial strain is M (l - 1).

    Parameters: E > 0, -1 < nu < 0.5, density > 0 (finite reals).
    """

    name = "LinearElastic"
    n_state = 0

    def __init__(self, E, nu, density):
        self._set_parameters(E, nu, density)

    def stress(self, idx, dF, F_old, sigma_old, sigma_new, state):
        """Write sigma_new[idx]; ``F_old`` and ``state`` are unused."""
        linear_elastic_stress_kernel(np.asarray(idx, dtype=np.int64), dF, sigma_old,
                                     sigma_new, self.lame_lambda, self.shear_modulus)

    def tangent(self, idx, dF, F_old, sigma_old, sigma_new, state, dsig):
        """Write dsig[idx] = d sigma_new / d dF (exact; depends only on sigma_old)."""
        linear_elastic_tangent_kernel(np.asarray(idx, dtype=np.int64), sigma_old, dsig,
                                      self.lame_lambda, self.shear_modulus)
