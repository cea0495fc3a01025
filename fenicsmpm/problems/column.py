"""V2, large deformation: the AMPLE elastic column under self-weight (BENCHMARKS.md V2;
Coombs & Augarde 2020).

Plane strain, height l0 = 50 m, one cell wide (width h = l0 / n_y), 2 x 2 particles per
cell, rollers on both sides and the base; Hencky material (fenicsmpm.materials.hencky)
with E = 1e4 Pa, nu = 0, rho0 = 80 kg/m^3; g = 10 m/s^2. The top settles 25.94 m (52 %).

Exact solution for a particle of initial height Y:
    sigma_yy = -rho0 g (l0 - Y), sigma_xx = 0,
    the stretch l(Y) solves E ln(l) / l = -rho0 g (l0 - Y), u(Y) = -int_0^Y (1 - l) dY.
Error norms (`errors`):
    stress (AMPLE's)  sum_p |sigma_yy,p - sigma_a(Y_p)| V0_p / (rho0 g l0 sum_p V0_p)
    displacement      sqrt(sum_p V0_p (u_y,p - u_a(Y_p))^2 / sum_p V0_p u_a(Y_p)^2)

Two ways to reach the static state:
  - implicit: fm.QuasiStatic(load_steps=40) (gravity ramped linearly over 40 load steps,
    as AMPLE; every shape family: wide ones get a wider matrix pattern);
  - explicit (any shape family): `DampedExplicit`, an fm.Explicit with mass-proportional
    viscous damping (the grid force -c m_i v_i in the momentum balance, dv/dt = ... - c v),
    with gravity ramped by the seed-002 sine over T/2 (gravity_ramp=T);
    the damping does not change the static equilibrium. Defaults: c = 2 w1 (critical for the
    small-strain first mode w1 = pi c_p / (2 l0)), T = 2 pi / w1 (the first period), and the
    run lasts `explicit_time` = T / 2 + 16 / w1.
"""
import math

import numpy as np
from mpi4py import MPI
from dolfinx import mesh as dmesh

from ..grid import Grid, vertex_ghost_partitioner
from ..integrators import Explicit
from ..materials.hencky import Hencky
from ..particles import Particles
from ..simulation import Simulation

__all__ = ["DampedExplicit", "ColumnExact", "large_deformation_column", "errors",
           "explicit_time"]

AMPLE = dict(height=50.0, E=1e4, nu=0.0, density=80.0, g=10.0)


class DampedExplicit(Explicit):
    """fm.Explicit with mass-proportional viscous damping: the grid force -damping m_i v_i^n
    in every step's momentum balance (Explicit.damping). `damping` (1/s) may be set after
    construction (large_deformation_column sets it to 2 w1 when it is None)."""

    def __init__(self, scheme="MUSL", flip=None, damping=None, transfer=None):
        super().__init__(scheme, flip, transfer)
        self.damping = damping


class ColumnExact:
    """Exact solution of the Hencky column: stretch l(Y), stress and displacement."""

    def __init__(self, height, E, density, g):
        self.l0, self.E, self.rho, self.g = float(height), float(E), float(density), float(g)
        # tabulate l(Y) and u(Y) once, on a fine Gauss-Legendre composite rule
        self._Y = np.linspace(0.0, self.l0, 4001)
        lam = self.stretch(self._Y)
        # u(Y) = -int_0^Y (1 - l) dY, by the trapezoid rule on the fine table plus a
        # 5-point Gauss correction per interval
        gx, gw = np.polynomial.legendre.leggauss(5)
        a, b = self._Y[:-1], self._Y[1:]
        pts = 0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * gx[None, :]
        seg = (0.5 * (b - a)[:, None] * gw[None, :] * (1.0 - self.stretch(pts.ravel()).reshape(pts.shape))).sum(1)
        self._u = -np.concatenate([[0.0], np.cumsum(seg)])
        self._lam = lam
        self.top_settlement = -float(self._u[-1])

    def stress_yy(self, Y):
        return -self.rho * self.g * (self.l0 - np.asarray(Y, dtype=float))

    def stretch(self, Y):
        """Solve E ln(l) / l = s (s = sigma_yy(Y) <= 0) for l in (0, 1] by Newton (monotone)."""
        s = self.stress_yy(Y) / self.E
        lam = np.ones_like(s)
        for _ in range(100):
            f = np.log(lam) / lam - s
            df = (1.0 - np.log(lam)) / lam ** 2
            step = f / df
            lam = np.clip(lam - step, 0.5 * lam, 1.0)
            if np.max(np.abs(step)) < 1e-15:
                break
        return lam

    def displacement_y(self, Y):
        """u_y(Y) = -int_0^Y (1 - l) dY (cubic-accurate interpolation of the fine table)."""
        Y = np.asarray(Y, dtype=float)
        from scipy.interpolate import CubicSpline
        if not hasattr(self, "_spline"):
            self._spline = CubicSpline(self._Y, self._u)
        return self._spline(Y)


def explicit_time(material=None, height=AMPLE["height"], E=AMPLE["E"], density=AMPLE["density"]):
    """Default (ramp time T, run time, damping c) of the explicit relaxation (module docstring)."""
    w1 = math.pi * math.sqrt(E / density) / (2.0 * height)
    T = 2.0 * math.pi / w1
    return T, 0.5 * T + 16.0 / w1, 2.0 * w1


def large_deformation_column(integrator, n_cells=16, per_cell=2, shape="mpm", height=AMPLE["height"],
                             E=AMPLE["E"], nu=AMPLE["nu"], density=AMPLE["density"], g=AMPLE["g"],
                             dt=None, cfl=0.5, cell_type=dmesh.CellType.quadrilateral,
                             comm=MPI.COMM_WORLD, partitioner=None, material=None, ramp=None,
                             run_time=None):
    """The V2 large-deformation column with n_cells cells along its height; returns
    (sim, exact) with exact a ColumnExact plus `h`, `steps` (the number of steps to run:
    load_steps of a QuasiStatic integrator, or the explicit relaxation time over dt) and,
    for explicit runs, `ramp`, `damping`.

    Explicit integrators get gravity_ramp = T and, for a DampedExplicit without a damping
    coefficient, damping = 2 w1 (see explicit_time); dt defaults to cfl * h / c_p.
    Shapes other than "mpm" use the vertex-ghost partitioner (needed under MPI).
    material: default Hencky(E, nu, density); the exact stress -rho0 g (l0 - Y) holds for any
    material (equilibrium of the 1D column), the exact displacement only for Hencky.
    ramp, run_time: override the explicit ramp time T and run time (e.g. L1: T = 20 s, run
    to 20 s)."""
    h = height / n_cells
    if partitioner is None and shape != "mpm":
        partitioner = vertex_ghost_partitioner()
    kw = {} if partitioner is None else {"partitioner": partitioner}
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [h, height]], [1, n_cells], cell_type, **kw)
    grid = Grid(msh)
    mat = Hencky(E=E, nu=nu, density=density) if material is None else material
    pts = Particles.fill(grid, mat, per_cell=per_cell)
    ex = ColumnExact(height, E, density, g)
    ex.h = h
    if integrator.explicit:
        T, t_run, c = explicit_time(height=height, E=E, density=density)
        if ramp is not None:
            T = float(ramp)
        if run_time is not None:
            t_run = float(run_time)
        if dt is None:
            dt = cfl * h / mat.p_wave_speed
        steps = int(math.ceil(t_run / dt - 1e-9))
        if isinstance(integrator, DampedExplicit) and integrator.damping is None:
            integrator.damping = c
        sim = Simulation(grid, pts, integrator, dt=dt, gravity=(0.0, -g), shape=shape,
                         gravity_ramp=T)
        ex.ramp, ex.damping = T, getattr(integrator, "damping", None)
    else:
        steps = getattr(integrator, "load_steps", 1)
        sim = Simulation(grid, pts, integrator, dt=1.0 if dt is None else dt, gravity=(0.0, -g),
                         shape=shape)
    ex.steps = steps
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], h), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0), [1])
    return sim, ex


def errors(sim, exact):
    """AMPLE's normalized stress error and the normalized L2 displacement error (module
    docstring), global (collective)."""
    p = sim.particles
    Y = (p.x - p.u)[:, 1]
    ua = exact.displacement_y(Y) if len(Y) else np.zeros(0)
    loc = np.array([np.sum(np.abs(p.stress[:, 1, 1] - exact.stress_yy(Y)) * p.V0),
                    np.sum(p.V0),
                    np.sum(p.V0 * (p.u[:, 1] - ua) ** 2),
                    np.sum(p.V0 * ua ** 2)])
    tot = sim.comm.allreduce(loc, op=MPI.SUM) if sim.comm.size > 1 else loc
    return dict(stress=float(tot[0] / (exact.rho * exact.g * exact.l0 * tot[1])),
                displacement=float(np.sqrt(tot[2] / tot[3])))
