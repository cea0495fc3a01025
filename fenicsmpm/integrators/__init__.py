"""Time integrators: explicit (USF/USL/MUSL), Newmark and quasi-static (Newton + PETSc KSP)."""
from .explicit import Explicit
from .implicit import Newmark, QuasiStatic

__all__ = ["Explicit", "Newmark", "QuasiStatic"]
