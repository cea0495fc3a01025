"""Time integrators: explicit (USF/USL/MUSL), explicit and implicit generalized-alpha, Newmark
and quasi-static (Newton + PETSc KSP)."""
from .explicit import Explicit
from .implicit import Newmark, QuasiStatic
from .generalized_alpha import ExplicitGeneralizedAlpha, ImplicitGeneralizedAlpha
from .contact import ExplicitContact, set_body
from .rigid import RigidLoad
from .dmgc import DoubleMappingNewmark, DoubleMappingQuasiStatic

__all__ = ["Explicit", "Newmark", "QuasiStatic", "ExplicitGeneralizedAlpha", "ImplicitGeneralizedAlpha"]
__all__ += ["ExplicitContact", "RigidLoad", "set_body"]
