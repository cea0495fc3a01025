"""Semi-linear (Biot-strain) hyperelasticity: linear elasticity in the Biot strain U - I.

F = dF F_old = R U = V R, J = det F, b = F F^T = V^2; stored energy
W(U) = lambda/2 tr(U - I)^2 + mu |U - I|^2 (linear elasticity in the Biot strain U - I of
the Seth-Hill strain family; Ogden, *Non-linear Elastic Deformations*, 1984, on strain
measures and their conjugate stresses), whose Biot stress T = dW/dU =
lambda tr(U - I) I + 2 mu (U - I) is coaxial with U, so
    tau   = R T U R^T = lambda (tr V - 3) V + 2 mu (b - V)      (Kirchhoff stress),
    sigma = tau / J                                               (Cauchy stress).
Its nominal stress in uniaxial strain with nu = 0 (stretch l) is exactly E (l - 1): a 1D
column or bar follows the small-strain (linear) wave equation at any amplitude, where the
Jaumann-rate fm.LinearElastic gives E ln(l) and the Hencky model E ln(l) / l. A rigid rotation
leaves it stress-free; at small strain it is fm.LinearElastic. Under strong compression it is
not stable (the nominal stress stays finite as l -> 0): for elastic strains of a few percent.

Tangent with respect to the increment dF (exact, consistent with `stress`; materials.spectral):
    dV = sum_ac (n_a . db n_c) n_a (x) n_c / (sqrt(l_a) + sqrt(l_c))   (Daleckii-Krein for
         V = sqrt(b), b = sum_a l_a n_a (x) n_a; no singular limit),
    d tau = lambda tr(dV) V + lambda (tr V - 3) dV + 2 mu (db - dV),
    d sigma = d tau / J - sigma tr(dF^-1 d dF).
For J <= 0 (inverted element) the stress and tangent of that particle are NaN.
"""
import math

import numba
import numpy as np

from .neo_hookean import IsotropicHyperelastic
from .piola import det3
from .spectral import BIOT, current_F, nan_stress, spectral_stress, spectral_tangent
from ..kernels.threads import PRANGE, chunk, particle_chunks

__all__ = ["BiotElastic", "biot_stress_kernel", "biot_tangent_kernel"]


@numba.njit(cache=True)
def _plane_sigma(F, J, la, mu, s):
    """sigma of an in-plane F (F_i2 = F_2i = 0 for i < 2) without an eigensolve: the in-plane
    block of V = sqrt(b) is (b + sqrt(det b) I) / sqrt(tr b + 2 sqrt(det b)) (2 x 2 SPD
    square root), V_22 = |F_22|."""
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
def _stress(idx, dF, F_old, sigma_new, la, mu, lo, hi):
    F = np.empty((3, 3))
    for q in range(lo, hi):
        p = idx[q]
        current_F(dF, F_old, p, F)
        J = det3(F)
        if not J > 0.0:
            nan_stress(sigma_new, p)
        elif F[0, 2] == 0.0 and F[1, 2] == 0.0 and F[2, 0] == 0.0 and F[2, 1] == 0.0:
            _plane_sigma(F, J, la, mu, sigma_new[p])
        else:
            spectral_stress(BIOT, idx, dF, F_old, sigma_new, la, mu, q, q + 1)


@numba.njit(parallel=PRANGE, cache=True)
def biot_stress_kernel(idx, dF, F_old, sigma_new, la, mu):
    """sigma = (lambda (tr V - 3) V + 2 mu (b - V)) / J, V = sqrt(F F^T), F = dF F_old; NaN if
    J <= 0 (threaded over chunks of idx, kernels.threads; in-plane F: _plane_sigma)."""
    n = idx.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        _stress(idx, dF, F_old, sigma_new, la, mu, np.int64(0), n)
        return
    for c in numba.prange(nc):
        lo, hi = chunk(n, nc, c)
        _stress(idx, dF, F_old, sigma_new, la, mu, lo, hi)


@numba.njit(cache=True)
def biot_tangent_kernel(idx, dF, F_old, dsig, la, mu):
    """dsig[p,i,j,k,l] = d sigma_ij / d dF_kl (module docstring, materials.spectral); NaN if
    J <= 0."""
    spectral_tangent(BIOT, idx, dF, F_old, dsig, la, mu)


class BiotElastic(IsotropicHyperelastic):
    """Semi-linear (Biot-strain) hyperelastic solid: linear elasticity in U - I.

    sigma = (lambda (tr V - 3) V + 2 mu (b - V)) / J,  V = sqrt(b), b = F F^T, J = det F;
    mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu)). In uniaxial strain with
    nu = 0 the nominal stress is E (l - 1), the linear relation at any stretch (module
    docstring); use it to compare with small-strain elastic solutions at finite amplitude.

    Parameters: E > 0, -1 < nu < 0.5, density > 0 (finite reals).
    Particles with J <= 0 get NaN stress (no exception).
    """

    name = "BiotElastic"
    stress_kernel = biot_stress_kernel
    tangent_kernel = biot_tangent_kernel
