"""Rigid bodies driven by a force, for fm.ExplicitContact (`rigid={body: RigidLoad(...)}`).

A rigid body of mass M (the sum of its particles' masses; per radian on an axisymmetric
grid, like every force) moves with one velocity v that follows
    max(M, m_c) (v^{n+1} - v^n) / dt = F(t^n) + M g + F_c^n,
F the applied force (a vector or t -> vector, e.g. hammer blows on a pile head), g its
gravity and F_c the contact force of the other bodies on it in the step just taken (the
reaction to the contact forces on the deformable bodies at the nodes it shares with them,
eqs 2.37-2.39 of seed 004). m_c is the nodal mass of the other bodies at the nodes where
contact acted (multi-velocity contact; 0 for penalty contact). The multi-velocity reaction
is m_c (v_R - v) / dt, a dashpot m_c / dt lagged by one step: with mass M alone the
velocity error is multiplied by 1 - m_c / M each step, which oscillates once m_c > M and
grows once m_c > 2 M (measured: a driven pile ejected soil particles). Dividing by max(M,
m_c) keeps the factor in [0, 1); while m_c <= M nothing is changed and the momentum of the
bodies follows the impulse to round-off (an added mass M + m_c in every step lost
m_c (v^{n+1} - v^n) of momentum per step: 2.7 % after 1.5 s in tests/test_rigid_load.py).
A steady motion (F_c balancing F + M g) is unchanged. On an axisymmetric grid the body moves along
the axis only: the radial components of the per-radian forces of a body of revolution
cancel around it, so v_r stays 0.
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

    def start(self, mass, gdim, axisymmetric=False):
        """Set the body's (global) mass; the velocity starts at zero unless given; on an
        axisymmetric grid only the axial component moves."""
        if not (mass > 0):
            raise ValueError("RigidLoad: the rigid body has no mass (no particles)")
        self.mass = float(mass)
        self.free = np.ones(gdim)
        if axisymmetric:
            self.free[0] = 0.0
        if self.v is None:
            self.v = np.zeros(gdim)
        force = None if callable(self.force) else np.asarray(self.force, dtype=np.float64)
        for name, val in (("velocity", self.v), ("gravity", self.gravity), ("force", force)):
            if val is not None and val.shape != (gdim,):
                raise ValueError(f"RigidLoad: '{name}' must have length {gdim}, got shape {val.shape}")

    def advance(self, t, dt, contact_force, added_mass=0.0):
        """v += dt (F(t) + M g + F_c) / max(M, m_c) (module docstring)."""
        f = np.asarray(self.force(t) if callable(self.force) else self.force, dtype=np.float64)
        total = f + np.asarray(contact_force, dtype=np.float64)
        if self.gravity is not None:
            total = total + self.mass * self.gravity
        self.v = self.v + self.free * dt * total / max(self.mass, added_mass)
