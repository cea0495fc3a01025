"""Constitutive models for fenicsmpm (pure numpy + numba).

Conventions: 3x3 tensors (plane strain in 2D), Cauchy stress, tension
positive; kernels act only on the particle rows listed in ``idx``.
"""
from .linear_elastic import LinearElastic
from .neo_hookean import NeoHookean
from .piola import first_piola, first_piola_tangent, strain_energy_increment

__all__ = ["LinearElastic", "NeoHookean", "first_piola", "first_piola_tangent",
           "strain_energy_increment"]
