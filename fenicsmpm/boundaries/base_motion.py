"""Earthquake input at the base of a model (issue 8; BENCHMARKS.md P1; seed 003 §3).

InputMotion: a time history of acceleration or velocity, from arrays, a two-column text
file (time, value) or a callable, with baseline correction. Sampled histories are
integrated with the trapezium rule (seed 003: "the trapezium rule was used to integrate the
acceleration ... linear baseline correction was applied to eliminate any displacement
drift"). Baseline correction of order k (default 1, linear): a polynomial p(t) of degree k
with p(0) = 0 is fitted to the integrated velocity by least squares and removed,
    v_c = v - p,   a_c = a - p',   u_c = int v_c dt,
so the corrected record starts from rest and its displacement does not drift.

Rigid base (`rigid_base`): the base nodes are fixed and the model is solved in the frame
moving with the base: every node gets the body force -m_i a_g(t) (Simulation.base_motion,
added in Simulation.external_force), so the computed motion is the motion relative to the
base and the absolute motion is relative + base (`RigidBase.absolute`). For a rigid base
this is exact (the stress depends on relative motion only), it works unchanged with every
integrator (explicit, generalized-alpha, implicit), and the mesh need not move with the
ground as in the seed's moving-mesh Dirichlet input: the particles stay where the mesh is.

Compliant base (`compliant_base`, `CompliantBase`): fm.Viscous dashpots on the base facets
with the rock's impedance plus the incident-wave traction (Joyner & Chen 1975; Lysmer &
Kuhlemeyer 1969),
    t = rho_r c_s,r (2 v_in(t) - v_t) [+ rho_r c_p,r (2 v_in,n(t) - v_n) n],
v_in the upgoing incident velocity in the rock (the outcrop motion is 2 v_in). The column's
transfer function over the outcrop motion is then the elastic-bedrock one,
1 / sqrt(cos^2 kH + (alpha_z sin kH)^2), alpha_z = rho_s V_s / (rho_r V_r). The incident
velocity enters the UFL form through a fem.Constant that an observer sets after every step
to v_in(t) (explicit runs evaluate the boundary force at the start of the step) or to
v_in(t + dt) (implicit runs: the residual is taken at the end of the step)."""
import math

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from .robin import Viscous

KINDS = ("acceleration", "velocity")


def _cumtrapz(t, y):
    out = np.zeros_like(y)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))
    return out


def baseline_correct(t, a, order=1):
    """Baseline-corrected (a, v, u) of a sampled acceleration (module docstring): a
    polynomial of degree `order` through the origin is fitted to the velocity and removed."""
    t = np.asarray(t, dtype=float)
    a = np.asarray(a, dtype=float)
    v = _cumtrapz(t, a)
    if order:
        tt = t - t[0]
        A = np.stack([tt ** k for k in range(1, order + 1)], axis=1)
        c, *_ = np.linalg.lstsq(A, v, rcond=None)
        v = v - A @ c
        a = a - np.stack([k * tt ** (k - 1) for k in range(1, order + 1)], axis=1) @ c
    return a, v, _cumtrapz(t, v)


class InputMotion:
    """A base motion: acceleration(t), velocity(t), displacement(t) (scalars; zero before
    the first and held after the last sample... of acceleration and velocity: zero after).

    InputMotion(t, values, kind="acceleration", baseline=1, scale=1.0): sampled values
      (kind "velocity": differentiated by central differences to the acceleration first);
      baseline: the order of the baseline correction (0 or None: none).
    InputMotion.from_file(path, kind=..., ...): a two-column text file (time, value),
      '#' comments; delimiter whitespace or comma.
    InputMotion.from_callable(f, t_end, dt, kind=...): f(t) sampled on [0, t_end] every dt
      (then as above)."""

    def __init__(self, t, values, kind="acceleration", baseline=1, scale=1.0):
        if kind not in KINDS:
            raise ValueError(f"InputMotion: 'kind' must be one of {KINDS}, got {kind!r}")
        t = np.asarray(t, dtype=float)
        y = scale * np.asarray(values, dtype=float)
        if t.ndim != 1 or len(t) < 3:
            raise ValueError(f"InputMotion: 't' must be a 1D array of at least 3 times, got "
                             f"shape {t.shape}")
        if y.shape != t.shape:
            raise ValueError(f"InputMotion: 'values' must have one value per time in 't', "
                             f"shape {t.shape}, got shape {y.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
            raise ValueError("InputMotion: 't' must increase strictly and be finite")
        if not np.all(np.isfinite(y)):
            raise ValueError("InputMotion: 'values' (times 'scale') must be finite")
        a = np.gradient(y, t) if kind == "velocity" else y
        self.t = t
        self.a, self.v, self.u = baseline_correct(t, a, int(baseline or 0))
        self.kind, self.baseline = kind, int(baseline or 0)

    @classmethod
    def from_file(cls, path, kind="acceleration", baseline=1, scale=1.0):
        """A motion from a two-column text file (time, value); see the class docstring."""
        txt = open(path).read().replace(",", " ")
        data = np.loadtxt(txt.splitlines(), comments="#")
        if data.ndim != 2 or data.shape[1] != 2:
            raise ValueError(f"InputMotion.from_file: {path} must have two columns (time, value)")
        return cls(data[:, 0], data[:, 1], kind, baseline, scale)

    @classmethod
    def from_callable(cls, f, t_end, dt, kind="acceleration", baseline=1, scale=1.0):
        """A motion sampled from f(t) on [0, t_end] every dt; see the class docstring."""
        if not callable(f):
            raise TypeError("InputMotion.from_callable: 'f' must be callable f(t) -> value")
        t = np.arange(int(math.floor(t_end / dt + 1e-9)) + 1) * dt
        return cls(t, [float(f(s)) for s in t], kind, baseline, scale)

    def _at(self, y, s):
        return np.interp(s, self.t, y, left=0.0, right=0.0)

    def acceleration(self, s):
        """Base acceleration at time s (0 outside the record)."""
        return self._at(self.a, s)

    def velocity(self, s):
        """Base velocity at time s (0 outside the record)."""
        return self._at(self.v, s)

    def displacement(self, s):
        """Base displacement at time s (0 before the record, held after it)."""
        return np.interp(s, self.t, self.u, left=0.0)


class RigidBase:
    """The frame acceleration of a rigid base shaken along `component` (module docstring)."""

    def __init__(self, motion, component=0):
        self.motion, self.component = motion, int(component)

    def frame_acceleration(self, t, gdim):
        a = np.zeros(gdim)
        a[self.component] = self.motion.acceleration(t)
        return a

    def absolute(self, t, relative, field="velocity"):
        """Absolute motion (acceleration, velocity or displacement) from the relative one."""
        base = getattr(self.motion, field)(np.asarray(t))
        return np.asarray(relative) + base


def rigid_base(sim, where, motion, component=0):
    """Fix the nodes where(x) and shake them rigidly with `motion` (an InputMotion) along
    `component`: the relative-frame body force -m a_g(t) (module docstring). Returns the
    RigidBase (sim.base_motion)."""
    if not isinstance(motion, InputMotion):
        raise TypeError("rigid_base: 'motion' must be an fm.InputMotion")
    if not (isinstance(component, (int, np.integer)) and 0 <= component < sim.gdim):
        raise ValueError(f"rigid_base: 'component' must be "
                         f"{' or '.join(map(str, range(sim.gdim)))}, got {component!r}")
    sim.fix(where)
    sim.base_motion = RigidBase(motion, component)
    return sim.base_motion


class CompliantBase(Viscous):
    """Viscous (Lysmer-Kuhlemeyer) base with the rock's impedance and the incident-wave
    traction 2 rho_r c_r v_in(t) (module docstring). `incident` is an InputMotion of the
    upgoing incident velocity (half the outcrop motion), along `component`; density,
    s_wave_speed (and p_wave_speed) are the rock's."""

    def __init__(self, where, incident, density, s_wave_speed, p_wave_speed, component=0):
        if not isinstance(incident, InputMotion):
            raise TypeError("CompliantBase: 'incident' must be an fm.InputMotion")
        super().__init__(where, density=density, p_wave_speed=p_wave_speed,
                         s_wave_speed=s_wave_speed)
        self.incident, self.component = incident, int(component)
        self._vin = None
        self._lag = 0.0

    def attach(self, sim):
        """Add this boundary to `sim` and keep v_in(t) current (an observer)."""
        self._vin = fem.Constant(sim.grid.mesh, PETSc.ScalarType((0.0,) * sim.gdim))
        sim.add_boundary(self)

        def update(s):
            lag = 0.0 if s.integrator.explicit else s.dt
            val = np.zeros(s.gdim)
            val[self.component] = self.incident.velocity(s.t + lag)
            self._vin.value[:] = val

        update(sim)
        sim.observe(update)
        self._update = update
        return self

    def on_restore(self, sim):
        """Set v_in for the restored time (the observer set it for the set-up's t = 0)."""
        self._update(sim)

    def _law(self, u, v, n):
        if self._vin is None:
            raise RuntimeError("CompliantBase: use compliant_base(sim, ...) or .attach(sim)")
        vin_n = ufl.dot(self._vin, n)
        inc = 2.0 * self.a * self.rho * self.cp * vin_n * n \
            + 2.0 * self.b * self.rho * self.cs * (self._vin - vin_n * n)
        return self._dashpot(v, n) + inc


def compliant_base(sim, where, incident, density, s_wave_speed, p_wave_speed, component=0):
    """Put a CompliantBase on the facets where(x) of `sim`; returns it."""
    return CompliantBase(where, incident, density, s_wave_speed, p_wave_speed, component).attach(sim)
