"""Parameter checks shared by material models.

Each check raises ``TypeError`` for a non-number (including ``bool``) and
``ValueError`` for a non-finite or out-of-range value.  Messages name the
owner (class), the parameter and the offending value, e.g.
``LinearElastic: parameter 'E' must be > 0, got -1.0``.
"""
import math
import numbers

__all__ = ["check_real", "check_positive", "check_open_interval"]


def check_real(owner, name, value):
    """Return ``value`` as a finite Python float, or raise TypeError/ValueError."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(
            f"{owner}: parameter '{name}' must be a real number, "
            f"got {value!r} of type {type(value).__name__}"
        )
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{owner}: parameter '{name}' must be finite, got {v!r}")
    return v


def check_positive(owner, name, value):
    """Require a finite real ``value > 0``; return it as float."""
    v = check_real(owner, name, value)
    if not v > 0.0:
        raise ValueError(f"{owner}: parameter '{name}' must be > 0, got {v!r}")
    return v


def check_open_interval(owner, name, value, lower, upper):
    """Require a finite real ``lower < value < upper``; return it as float."""
    v = check_real(owner, name, value)
    if not (lower < v < upper):
        raise ValueError(
            f"{owner}: parameter '{name}' must satisfy {lower} < {name} < {upper}, got {v!r}"
        )
    return v
