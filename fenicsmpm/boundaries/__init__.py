"""Boundary conditions on the grid: Dirichlet sets, UFL traction forms and Robin laws."""
from .dirichlet import PrescribedMotion, fixed_dofs, prescribed_increment
from .particle_layer import ParticleLayer
from .robin import Robin, RobinForms, Viscoelastic, Viscous
from .traction import Traction, TractionForms
from .base_motion import CompliantBase, InputMotion, RigidBase, compliant_base, rigid_base
from .periodic import PeriodicTie

__all__ = ["fixed_dofs", "ParticleLayer", "Robin", "RobinForms", "Traction", "TractionForms", "Viscoelastic",
           "Viscous"]
