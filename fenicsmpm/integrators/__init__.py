"""Time integrators: explicit (USF/USL/MUSL), explicit and implicit generalized-alpha, Newmark
and quasi-static (Newton + PETSc KSP)."""
from .explicit import Explicit
from .implicit import Newmark, QuasiStatic
from .generalized_alpha import ExplicitGeneralizedAlpha, ImplicitGeneralizedAlpha
from .dmgc import DoubleMappingNewmark, DoubleMappingQuasiStatic

__all__ = ["Explicit", "Newmark", "QuasiStatic", "ExplicitGeneralizedAlpha", "ImplicitGeneralizedAlpha"]
__all__ += ["DoubleMappingNewmark", "DoubleMappingQuasiStatic"]
