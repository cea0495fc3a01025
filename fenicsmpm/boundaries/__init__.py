"""Boundary conditions on the grid: Dirichlet sets and UFL traction forms."""
from .dirichlet import fixed_dofs
from .traction import Traction, TractionForms

__all__ = ["fixed_dofs", "Traction", "TractionForms"]
