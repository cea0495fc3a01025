"""Constitutive models for fenicsmpm (pure numpy + numba).

Conventions: 3x3 tensors (plane strain in 2D), Cauchy stress, tension
positive; kernels act only on the particle rows listed in ``idx``.

Interface of a material (see LinearElastic):
    n_state                      number of history variables per particle (p.state columns)
    stress(idx, dF, F_old, sigma_old, sigma_new, state)
                                 trial stress for the increment dF; `state` holds the committed
                                 history on entry and receives the trial history (the
                                 Simulation commits it only when the step is accepted)
    tangent(idx, dF, F_old, sigma_old, sigma_new, state, dsig)
                                 dsig = d sigma_new / d dF, with `state` the committed history
    density, p_wave_speed        for masses and the critical time step
"""
from .biot import BiotElastic
from .hencky import Hencky
from .hypoplastic import Hypoplastic
from .linear_elastic import LinearElastic
from .mohr_coulomb import MohrCoulomb
from .neo_hookean import NeoHookean
from .von_mises import VonMises
from .piola import first_piola, first_piola_tangent, strain_energy_increment

__all__ = ["BiotElastic", "Hencky", "Hypoplastic", "LinearElastic", "NeoHookean", "MohrCoulomb", "VonMises", "first_piola",
           "first_piola_tangent", "strain_energy_increment", "constrained_moduli"]


def constrained_moduli(materials):
    """M = rho c_p^2 of each material (its initial constrained modulus), as an array: the
    stiffness scale of penalties (boundaries.particle_motion, integrators.ghost)."""
    import numpy as np
    return np.array([m.density * m.p_wave_speed ** 2 for m in materials], dtype=float)
