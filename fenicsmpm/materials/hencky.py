"""Hencky (logarithmic-strain) hyperelasticity, the material of the AMPLE large-deformation
column (BENCHMARKS.md V2; Coombs & Augarde 2020).

F = dF F_old, J = det F, b = F F^T, eps = ln(b) / 2 (the logarithmic strain),
    tau   = lambda tr(eps) I + 2 mu eps           (Kirchhoff stress),
    sigma = tau / J                                (Cauchy stress).
In uniaxial strain with nu = 0 (stretch l): sigma_yy = E ln(l) / l, the relation of the V2
exact solution.

Tangent with respect to the increment dF (exact, consistent with `stress`; Daleckii-Krein,
materials.spectral):
    d ln(b) = sum_ab f_ab (n_a . db n_b) n_a (x) n_b,  b = sum_a l_a n_a (x) n_a,
      f_ab = (ln l_a - ln l_b) / (l_a - l_b), f_aa = 1 / l_a (the limit, used for close l),
    d sigma = (lambda tr(d eps) I + 2 mu d eps) / J - sigma tr(dF^-1 d dF).
For J <= 0 (inverted element) the stress and tangent of that particle are NaN.
"""
import numba

from .neo_hookean import IsotropicHyperelastic
from .spectral import HENCKY, spectral_stress, spectral_tangent

__all__ = ["Hencky", "hencky_stress_kernel", "hencky_tangent_kernel"]


@numba.njit(cache=True)
def hencky_stress_kernel(idx, dF, F_old, sigma_new, la, mu):
    """sigma = (lambda tr(eps) I + 2 mu eps) / J, eps = ln(F F^T) / 2, F = dF F_old; NaN if J <= 0."""
    spectral_stress(HENCKY, idx, dF, F_old, sigma_new, la, mu)


@numba.njit(cache=True)
def hencky_tangent_kernel(idx, dF, F_old, dsig, la, mu):
    """dsig[p,i,j,k,l] = d sigma_ij / d dF_kl (materials.spectral); NaN if J <= 0."""
    spectral_tangent(HENCKY, idx, dF, F_old, dsig, la, mu)


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
