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
import numba

from .neo_hookean import IsotropicHyperelastic
from .spectral import BIOT, spectral_stress, spectral_tangent

__all__ = ["BiotElastic", "biot_stress_kernel", "biot_tangent_kernel"]


@numba.njit(cache=True)
def biot_stress_kernel(idx, dF, F_old, sigma_new, la, mu):
    """sigma = (lambda (tr V - 3) V + 2 mu (b - V)) / J, V = sqrt(F F^T), F = dF F_old; NaN if
    J <= 0 (materials.spectral: threaded, an in-plane F without an eigensolve)."""
    spectral_stress(BIOT, idx, dF, F_old, sigma_new, la, mu)


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
