"""Contact between bodies on one background grid: multi-velocity (Bardenhagen) contact with
Coulomb friction (multi_velocity: fm.ExplicitContact, set_body), the penalty alternative with
rigid polylines (penalty) and force-driven rigid bodies (rigid: fm.RigidLoad)."""
from .multi_velocity import ExplicitContact, set_body
from .rigid import RigidLoad

__all__ = ["ExplicitContact", "RigidLoad", "set_body"]
