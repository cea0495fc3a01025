"""V3: the axis-aligned manufactured solution (BENCHMARKS.md V3; Kamojjala et al. 2013,
"Verification tests in solid mechanics", the test also used by Wallstedt & Guilkey 2008).

A unit square of compressible neo-Hookean material (fenicsmpm.NeoHookean) follows the
prescribed large-deformation motion
    u_x = A sin(2 pi X) sin(c pi t),   u_y = A sin(2 pi Y) sin(c pi t + pi),   c = sqrt(E / rho0),
(X, Y the reference position), so F = diag(F11(X, t), F22(Y, t), 1) with
    F11 = 1 + 2 pi A cos(2 pi X) sin(c pi t),   F22 = 1 - 2 pi A cos(2 pi Y) sin(c pi t).
The first Piola stress of the neo-Hookean model, P = mu (F - F^-T) + lambda ln J F^-T, gives
    dP11/dX = dF11/dX [mu (1 + 1/F11^2) + lambda (1 - ln J) / F11^2]   (likewise P22 in Y),
and the body force per unit mass that makes the motion exact is
    b = d2u/dt2 - Div P / rho0.
It is applied per particle, f_i += sum_p N_ip m_p b(X_p, t), by `BodyForceSimulation`
(a Simulation whose external force adds that term; any shape family, explicit or implicit).
The normal displacement vanishes on all four sides (u_x = 0 at X = 0, 1 and u_y = 0 at
Y = 0, 1) and the shear stress is zero, so rollers on the sides are exact boundary
conditions. The particles start at rest in the reference configuration with velocity
du/dt(X, 0); the default end time t_end = 1 / (2 c) is the displacement peak.

Error norms at the particles (V0_p the initial volumes; `errors`):
    displacement  sqrt(sum_p V0_p |u_p - u(X_p)|^2 / sum_p V0_p |u(X_p)|^2)
    stress        sqrt(sum_p V0_p |sigma_p - sigma(X_p)|_F^2 / sum_p V0_p |sigma(X_p)|_F^2)
with X_p = x_p - u_p and sigma the exact Cauchy stress (3 x 3, plane strain).
"""
import math

import numpy as np
from mpi4py import MPI
from dolfinx import mesh as dmesh

from ..grid import Grid, vertex_ghost_partitioner
from ..kernels import transfer as kt
from ..materials import NeoHookean
from ..particles import Particles
from ..simulation import Simulation

__all__ = ["BodyForceSimulation", "AxisAligned", "axis_aligned", "errors"]


class BodyForceSimulation(Simulation):
    """A Simulation with a body force per unit mass b(X, t) (X the particles' reference
    positions x - u), added to the external force as sum_p N_ip m_p b(X_p, t)."""

    def __init__(self, *args, body_force=None, **kw):
        if not callable(body_force):
            raise TypeError("BodyForceSimulation: 'body_force' must be a callable b(X, t) -> (n, gdim)")
        self.body_force = body_force
        super().__init__(*args, **kw)

    def external_force(self, t, m, gravity_scale=1.0, active=None):
        f = super().external_force(t, m, gravity_scale, active)
        p = self.particles
        fb = np.zeros_like(f)
        if len(p):
            b = np.ascontiguousarray(self.body_force(p.x - p.u, t), dtype=np.float64)
            kt.p2g_weighted(self.grid.D, self.nodes, self.N, p.mass, b, fb)
        self.grid.accumulate(fb)
        return f + fb


class AxisAligned:
    """The exact solution of V3 (module docstring): displacement, velocity, acceleration,
    deformation gradient, Cauchy stress and body force as functions of (X, t), X (n, 2)."""

    def __init__(self, A=0.05, E=1e7, nu=0.3, density=1000.0):
        self.A, self.E, self.nu, self.rho = float(A), float(E), float(nu), float(density)
        self.mu = E / (2.0 * (1.0 + nu))
        self.lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
        self.c = math.sqrt(E / density)
        self.w = self.c * math.pi                  # angular frequency c pi
        self.t_end = 1.0 / (2.0 * self.c)          # displacement peak
        if 2.0 * math.pi * self.A >= 1.0:
            raise ValueError(f"AxisAligned: need 2 pi A < 1 (J > 0), got A = {A}")

    def _s(self, X):
        return np.sin(2 * np.pi * X), np.cos(2 * np.pi * X)

    def displacement(self, X, t):
        s = math.sin(self.w * t)
        sx, _ = self._s(X[:, 0])
        sy, _ = self._s(X[:, 1])
        return np.c_[self.A * sx * s, -self.A * sy * s]

    def velocity(self, X, t):
        c = self.w * math.cos(self.w * t)
        sx, _ = self._s(X[:, 0])
        sy, _ = self._s(X[:, 1])
        return np.c_[self.A * sx * c, -self.A * sy * c]

    def acceleration(self, X, t):
        return -self.w ** 2 * self.displacement(X, t)

    def stretches(self, X, t):
        s = math.sin(self.w * t)
        _, cx = self._s(X[:, 0])
        _, cy = self._s(X[:, 1])
        k = 2 * np.pi * self.A * s
        return 1.0 + k * cx, 1.0 - k * cy

    def stress(self, X, t):
        """Exact Cauchy stress (n, 3, 3): (mu / J)(b - I) + (lambda ln J / J) I."""
        F11, F22 = self.stretches(X, t)
        J = F11 * F22
        pv = self.lam * np.log(J) / J
        out = np.zeros((len(X), 3, 3))
        out[:, 0, 0] = self.mu / J * (F11 ** 2 - 1.0) + pv
        out[:, 1, 1] = self.mu / J * (F22 ** 2 - 1.0) + pv
        out[:, 2, 2] = pv
        return out

    def body_force(self, X, t):
        """b = d2u/dt2 - Div P / rho0 (per unit mass), (n, 2)."""
        s = math.sin(self.w * t)
        F11, F22 = self.stretches(X, t)
        lnJ = np.log(F11 * F22)
        sx, _ = self._s(X[:, 0])
        sy, _ = self._s(X[:, 1])
        dF11 = -4 * np.pi ** 2 * self.A * s * sx      # dF11/dX
        dF22 = 4 * np.pi ** 2 * self.A * s * sy       # dF22/dY
        mu, lam = self.mu, self.lam
        divx = dF11 * (mu * (1.0 + 1.0 / F11 ** 2) + lam * (1.0 - lnJ) / F11 ** 2)
        divy = dF22 * (mu * (1.0 + 1.0 / F22 ** 2) + lam * (1.0 - lnJ) / F22 ** 2)
        return self.acceleration(X, t) - np.c_[divx, divy] / self.rho


def axis_aligned(integrator, n_cells=16, per_cell=2, shape="auto", A=0.05, E=1e7, nu=0.3,
                 density=1000.0, dt=None, cfl=0.2, cell_type=dmesh.CellType.quadrilateral,
                 comm=MPI.COMM_WORLD, partitioner=None, fill="cells"):
    """V3 on the unit square with n_cells x n_cells cells; returns (sim, exact), exact an
    AxisAligned with t_end and h. dt defaults to cfl * h / c_p (explicit) or h / c_p
    (implicit). shape: Simulation(shape=...), the library's default "auto" unless given.
    Shapes other than "mpm" get the vertex-ghost partitioner (needed under MPI) unless
    `partitioner` is given. fill: "cells" (Particles.fill, per_cell per direction) or
    "edges" (Particles.fill_edges on triangles: one particle per edge, per_cell unused)."""
    ex = AxisAligned(A, E, nu, density)
    if partitioner is None and shape != "mpm":
        partitioner = vertex_ghost_partitioner()
    kw = {} if partitioner is None else {"partitioner": partitioner}
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [n_cells, n_cells], cell_type, **kw)
    grid = Grid(msh)
    mat = NeoHookean(E=E, nu=nu, density=density)
    vel = lambda x: ex.velocity(x, 0.0)                                   # noqa: E731
    if fill not in ("cells", "edges"):
        raise ValueError(f"axis_aligned: 'fill' must be 'cells' or 'edges', got {fill!r}")
    pts = (Particles.fill_edges(grid, mat, velocity=vel) if fill == "edges" else
           Particles.fill(grid, mat, per_cell=per_cell, velocity=vel))
    h = 1.0 / n_cells
    if dt is None:
        dt = (cfl if integrator.explicit else 1.0) * h / mat.p_wave_speed
    # an integer number of steps to t_end
    steps = max(1, int(math.ceil(ex.t_end / dt - 1e-9)))
    dt = ex.t_end / steps
    sim = BodyForceSimulation(grid, pts, integrator, dt=dt, shape=shape, body_force=ex.body_force)
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], 1.0), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0) | np.isclose(x[:, 1], 1.0), [1])
    ex.h, ex.steps, ex.dt = h, steps, dt
    return sim, ex


def errors(sim, exact, t=None):
    """Normalized L2 errors of displacement and stress at the particles (module docstring),
    global (collective)."""
    t = sim.t if t is None else t
    p = sim.particles
    X = p.x - p.u
    ua = exact.displacement(X, t)
    sa = exact.stress(X, t)
    V0 = p.V0
    loc = np.array([np.sum(V0 * np.sum((p.u - ua) ** 2, axis=1)),
                    np.sum(V0 * np.sum(ua ** 2, axis=1)),
                    np.sum(V0 * np.sum((p.stress - sa) ** 2, axis=(1, 2))),
                    np.sum(V0 * np.sum(sa ** 2, axis=(1, 2)))])
    tot = sim.comm.allreduce(loc, op=MPI.SUM) if sim.comm.size > 1 else loc
    return dict(displacement=float(np.sqrt(tot[0] / tot[1])), stress=float(np.sqrt(tot[2] / tot[3])))
