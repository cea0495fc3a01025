"""Compressible neo-Hookean hyperelasticity (Bonet & Wood).

F = dF F_old, J = det F, b = F F^T,
    sigma = (mu / J)(b - I) + (lambda ln J / J) I
(Bonet & Wood, *Nonlinear Continuum Mechanics for Finite Element Analysis*,
2nd ed., 2008, eq. 6.29).  Tangent with respect to the increment dF
(d F = d dF F_old, dJ = J tr(dF^-1 d dF)):
    d sigma_ij / d dF_kl = [lambda (1 - ln J) d_ij - mu (b - I)_ij] / J * (dF^-1)_lk
                         + (mu / J) [d_ik (F_old F^T)_lj + d_jk (F F_old^T)_il].
For J <= 0 (inverted element) the stress and tangent of that particle are NaN.
"""
import math

import numba
import numpy as np

from .linear_elastic import IsotropicElasticParameters
from .piola import det3, inv3
from .spectral import current_F, nan_stress, nan_tangent, old_times_current

__all__ = ["NeoHookean", "neo_hookean_stress_kernel", "neo_hookean_tangent_kernel"]


@numba.njit(cache=True)
def neo_hookean_stress_kernel(idx, dF, F_old, sigma_new, lam, mu):
    """sigma = (mu/J)(F F^T - I) + (lam ln J / J) I with F = dF F_old; NaN if J <= 0."""
    F = np.empty((3, 3))
    for q in range(idx.shape[0]):
        p = idx[q]
        current_F(dF, F_old, p, F)
        J = det3(F)
        if not J > 0.0:
            nan_stress(sigma_new, p)
            continue
        pv = lam * math.log(J) / J
        for i in range(3):
            for j in range(3):
                b = F[i, 0] * F[j, 0] + F[i, 1] * F[j, 1] + F[i, 2] * F[j, 2]
                if i == j:
                    b -= 1.0
                s = mu / J * b
                if i == j:
                    s += pv
                sigma_new[p, i, j] = s


@numba.njit(cache=True)
def neo_hookean_tangent_kernel(idx, dF, F_old, dsig, lam, mu):
    """dsig[p,i,j,k,l] = d sigma_ij / d dF_kl (see module docstring); NaN if J <= 0."""
    F = np.empty((3, 3))
    dFinv = np.empty((3, 3))
    G0 = np.empty((3, 3))    # F_old F^T
    A = np.empty((3, 3))     # [lam (1 - ln J) d_ij - mu (b - I)_ij] / J
    for q in range(idx.shape[0]):
        p = idx[q]
        current_F(dF, F_old, p, F)
        J = det3(F)
        if not J > 0.0:
            nan_tangent(dsig, p)
            continue
        inv3(dF[p], dFinv)
        lnJ = math.log(J)
        old_times_current(F_old, p, F, G0)
        for i in range(3):
            for j in range(3):
                b = 0.0
                for m in range(3):
                    b += F[i, m] * F[j, m]
                a = -mu * b
                if i == j:
                    a += mu + lam * (1.0 - lnJ)
                A[i, j] = a / J
        c = mu / J
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    for l in range(3):
                        v = A[i, j] * dFinv[l, k]
                        if i == k:
                            v += c * G0[l, j]
                        if j == k:
                            v += c * G0[l, i]   # (F F_old^T)_il = (F_old F^T)_li
                        dsig[p, i, j, k, l] = v


class IsotropicHyperelastic(IsotropicElasticParameters):
    """Base of the isotropic hyperelastic materials: sigma depends on F = dF F_old only, through
    the numba kernels `stress_kernel(idx, dF, F_old, sigma_new, lam, mu)` and
    `tangent_kernel(idx, dF, F_old, dsig, lam, mu)` of the subclass. No history (n_state = 0);
    particles with J <= 0 get NaN stress (no exception; the commit refuses such increments)."""

    n_state = 0

    def __init__(self, E, nu, density):
        self._set_parameters(E, nu, density)

    def stress(self, idx, dF, F_old, sigma_old, sigma_new, state):
        """Write sigma_new[idx]; ``sigma_old`` and ``state`` are unused (hyperelastic)."""
        type(self).stress_kernel(np.asarray(idx, dtype=np.int64), dF, F_old, sigma_new,
                                 self.lame_lambda, self.shear_modulus)

    def tangent(self, idx, dF, F_old, sigma_old, sigma_new, state, dsig):
        """Write dsig[idx] = d sigma_new / d dF (analytic, consistent with ``stress``)."""
        type(self).tangent_kernel(np.asarray(idx, dtype=np.int64), dF, F_old, dsig,
                                  self.lame_lambda, self.shear_modulus)


class NeoHookean(IsotropicHyperelastic):
    """Compressible neo-Hookean solid (Bonet & Wood 2008, eq. 6.29).

    sigma = (mu/J)(b - I) + (lambda ln J / J) I,  F = dF F_old, b = F F^T, J = det F;
    mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu)).

    Parameters: E > 0, -1 < nu < 0.5, density > 0 (finite reals).
    Particles with J <= 0 get NaN stress (no exception).
    """

    name = "NeoHookean"
    stress_kernel = neo_hookean_stress_kernel
    tangent_kernel = neo_hookean_tangent_kernel
