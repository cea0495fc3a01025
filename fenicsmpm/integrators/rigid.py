"""Rigid bodies driven by a force, for fm.ExplicitContact (`rigid={body: RigidLoad(...)}`).

A rigid body of mass M (the sum of its particles' masses; per radian on an axisymmetric
grid, like every force) moves with one velocity v that follows
    M (v^{n+1} - v^n) / dt = F(t^n) + M g + F_c^n,
F the applied force (a vector or t -> vector, e.g. hammer blows on a pile head), g its
gravity and F_c the contact force of the other bodies on it in the step just taken (the
reaction to the contact forces on the deformable bodies at the nodes it shares with them,
eqs 2.37-2.39 of seed 004). The update is explicit, one step lagged: stable while dt is well
below 2 sqrt(M / k) for the contact stiffness k the body meets, which holds at the Courant
step of the soil for any body heavier than the soil in one cell around it.
"""
import numpy as np


class RigidLoad:
    """A force-driven rigid body (module docstring). Called with t it returns its current
    velocity, as a prescribed-velocity function does."""

    def __init__(self, force, gravity=None, velocity=None):
        if not callable(force):
            f = np.asarray(force, dtype=np.float64)
            if f.ndim != 1 or not np.all(np.isfinite(f)):
                raise ValueError(f"RigidLoad: 'force' must be a finite vector or t -> vector, got {force!r}")
        self.force = force
        self.gravity = None if gravity is None else np.asarray(gravity, dtype=np.float64)
        self.v = None if velocity is None else np.asarray(velocity, dtype=np.float64).copy()
        self.mass = None

    def __call__(self, t):
        return self.v

    def start(self, mass, gdim):
        """Set the body's (global) mass; the velocity starts at zero unless given."""
        if not (mass > 0):
            raise ValueError("RigidLoad: the rigid body has no mass (no particles)")
        self.mass = float(mass)
        if self.v is None:
            self.v = np.zeros(gdim)
        for name, val in (("velocity", self.v), ("gravity", self.gravity)):
            if val is not None and val.shape != (gdim,):
                raise ValueError(f"RigidLoad: '{name}' must have length {gdim}, got shape {val.shape}")

    def advance(self, t, dt, contact_force):
        """v += dt (F(t) + M g + F_c) / M."""
        f = np.asarray(self.force(t) if callable(self.force) else self.force, dtype=np.float64)
        total = f + np.asarray(contact_force, dtype=np.float64)
        if self.gravity is not None:
            total = total + self.mass * self.gravity
        self.v = self.v + dt * total / self.mass
