"""Generalized-alpha time integrators: explicit (Hulbert & Chung 1996, alpha_f = 0) and
implicit (Chung & Hulbert 1993), parametrized by a spectral radius (BENCHMARKS.md section P;
seed 003 §2.2, eqs 1-5, whose printed equations are missing from the seed text).

Explicit, spectral radius rho_b in [0, 1] (BENCHMARKS P "Explicit generalized-alpha"):
    alpha_m = (2 rho_b - 1) / (1 + rho_b),
    beta    = (5 - 3 rho_b) / ((1 + rho_b)^2 (2 - rho_b)),   gamma = 3/2 - alpha_m,
    M a^{n+1-alpha_m} = f_ext(t^n) - f_int(u^n)                           (P step 1)
    a^{n+1} = (a^{n+1-alpha_m} - alpha_m a^n) / (1 - alpha_m)             (P step 2)
    v^{n+1} = v^n + dt ((1 - gamma) a^n + gamma a^{n+1})                  (P step 3)
    du      = dt v^n + dt^2 ((1/2 - beta) a^n + beta a^{n+1})             (P step 4)
Stability limit (P, checked against the amplification matrix of this update, see
tests/test_generalized_alpha.py):
    Omega_s = sqrt(12 (1 + rho_b)(2 - rho_b) / (10 - 5 rho_b + rho_b^2)),
and bifurcation point, where the three eigenvalues of the amplification matrix meet at
-rho_b (derived here from the characteristic polynomial (lambda + rho_b)^3 of the update;
not printed in BENCHMARKS): Omega_b = (1 + rho_b) sqrt(2 - rho_b). Omega = omega dt.
rho_b = 1 gives alpha_m = 1/2, beta = 1/2, gamma = 1: central difference (leapfrog with
V^{n+1/2} = v^n + dt a^{n+1} / 2), Omega_s = Omega_b = 2.

Implicit, spectral radius at infinite frequency rho_inf in [0, 1] (BENCHMARKS P "Implicit
generalized-alpha"):
    alpha_m = (2 rho_inf - 1) / (rho_inf + 1),   alpha_f = rho_inf / (rho_inf + 1),
    gamma = 1/2 - alpha_m + alpha_f,             beta = (1 - alpha_m + alpha_f)^2 / 4,
    M a^{n+1-alpha_m} = f(t^{n+1-alpha_f}),  x^{n+1-alpha} = (1 - alpha) x^{n+1} + alpha x^n,
with the Newmark updates of v and u; see implicit.Newmark.step for the residual.
"""
import time
from collections import namedtuple

import numpy as np
from numba import njit

from ..kernels import nodal
from ..kernels import transfer as kt
from .implicit import Newmark, _Newton

ExplicitParameters = namedtuple("ExplicitParameters", "rho_b alpha_m beta gamma omega_s omega_b")
ImplicitParameters = namedtuple("ImplicitParameters", "rho_inf alpha_m alpha_f beta gamma")


def _radius(value, name, owner):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or not (0.0 <= value <= 1.0):
        raise ValueError(f"{owner}: '{name}' must be a number in [0, 1], got {value!r}")
    return float(value)


def explicit_parameters(rho_b):
    """alpha_m, beta, gamma, Omega_s and Omega_b of explicit generalized-alpha (module
    docstring; BENCHMARKS P, Hulbert & Chung 1996) for the spectral radius rho_b in [0, 1]."""
    r = _radius(rho_b, "rho_b", "explicit_parameters")
    alpha_m = (2.0 * r - 1.0) / (1.0 + r)
    return ExplicitParameters(
        rho_b=r, alpha_m=alpha_m,
        beta=(5.0 - 3.0 * r) / ((1.0 + r) ** 2 * (2.0 - r)),
        gamma=1.5 - alpha_m,
        omega_s=np.sqrt(12.0 * (1.0 + r) * (2.0 - r) / (10.0 - 5.0 * r + r * r)),
        omega_b=(1.0 + r) * np.sqrt(2.0 - r))


def implicit_parameters(rho_inf):
    """alpha_m, alpha_f, beta, gamma of implicit generalized-alpha (Chung & Hulbert 1993;
    BENCHMARKS P) for the spectral radius at infinite frequency rho_inf in [0, 1]."""
    r = _radius(rho_inf, "rho_inf", "implicit_parameters")
    alpha_m = (2.0 * r - 1.0) / (r + 1.0)
    alpha_f = r / (r + 1.0)
    return ImplicitParameters(rho_inf=r, alpha_m=alpha_m, alpha_f=alpha_f,
                              beta=0.25 * (1.0 - alpha_m + alpha_f) ** 2,
                              gamma=0.5 - alpha_m + alpha_f)


def explicit_update(prm, dt, v, a, a_mid):
    """Steps 2-4 of explicit generalized-alpha (BENCHMARKS P) for the intermediate
    acceleration a_mid = a^{n+1-alpha_m} = M^-1 (f_ext - f_int)(t^n): returns
    (a^{n+1}, v^{n+1}, du). Elementwise, so one call serves a single-DOF oscillator and the
    nodal arrays of the MPM integrator."""
    a1 = (a_mid - prm.alpha_m * a) / (1.0 - prm.alpha_m)
    v1 = v + dt * ((1.0 - prm.gamma) * a + prm.gamma * a1)
    du = dt * v + dt * dt * ((0.5 - prm.beta) * a + prm.beta * a1)
    return a1, v1, du


@njit(cache=True)
def g2p_generalized_alpha(D, nodes, N, du, a0, a1, v1, shift, dt, flip, x, u, v, a):
    """Particle update of explicit generalized-alpha (FLIP/PIC blend):
        x_p += sum N du_i,  u_p likewise,  a_p <- sum N a^{n+1}_i,
        FLIP: s_p <- s_p + dt sum N (a^n + a^{n+1})_i / 2   with s_p = v_p - shift dt a_p,
        PIC:  v_p <- sum N v^{n+1}_i,
    shift = gamma - 1/2, so the FLIP velocity increment is
    dt sum N ((1 - gamma) a^n + gamma a^{n+1}) + shift dt (sum N a^{n+1} - a_p^old)."""
    d = len(D)
    for p in range(nodes.shape[0]):
        for k in range(d):
            dx = 0.0
            am = 0.0
            an = 0.0
            vp = 0.0
            for b in range(nodes.shape[1]):
                i = nodes[p, b]
                w = N[p, b]
                dx += w * du[i, k]
                am += w * (a0[i, k] + a1[i, k])
                an += w * a1[i, k]
                vp += w * v1[i, k]
            x[p, k] += dx
            u[p, k] += dx
            s = v[p, k] - shift * dt * a[p, k] + 0.5 * dt * am
            v[p, k] = flip * (s + shift * dt * an) + (1.0 - flip) * vp
            a[p, k] = an


class ExplicitGeneralizedAlpha:
    """Explicit generalized-alpha MPM (Hulbert & Chung 1996, alpha_f = 0; seed 003 §2.2,
    computational cycle steps 1-9), spectral radius rho_b in [0, 1] (module docstring).

    Critical step: stability_factor = Omega_s(rho_b) / 2 scales the central-difference
    limit h / c_p (Simulation.dt_critical), so dt="auto" and the refusal of a too large dt
    follow Omega_s(rho_b).

    Step (lumped mass, active nodes; inactive nodes and fixed components hold zero):
      1. P2G: m_i, (m v)_i, (m a)_i from the particles; v_i^n = (m v)_i / m_i and
         a_i^n = (m a)_i / m_i, rebuilt from the particles every step.
      2. a_i^{n+1-alpha_m} = (f_ext - f_int + f_b)_i / m_i from the start-of-step stress, then
         a^{n+1}, v^{n+1}, du from `explicit_update` (BENCHMARKS P steps 2-4).
      3. Particles (`g2p_generalized_alpha`): x, u += sum N du; the velocity is integrated at
         the particles (FLIP; PIC blend by `flip`); a_p = sum N a^{n+1}.
      4. Stress from dF = I + grad du (as USL).
    Robin and particle-layer forces f_b (dashpots) take the transported velocity
    s = v - (gamma - 1/2) dt a (nodal v_i^n - (gamma - 1/2) dt a_i^n, particle
    v_p - (gamma - 1/2) dt a_p), not v^n.

    Why a^n is rebuilt from the particles every step (like v^n; the grid is reset every step):
    a per-node a^n carried between steps (seed 003 step 9) is only sound on a fixed set of
    nodes with fixed masses. When a node's mass changes a lot between steps (a node that has
    just become active with a small mass, a contact front, a Robin/absorbing base), one step's
    a_mid = f_i / m_i at that node can be very large; the carried recursion
    a^{n+1} = (a_mid - alpha_m a^n) / (1 - alpha_m) keeps that spike with the factor
    -alpha_m / (1 - alpha_m) per step (-1 at rho_b = 1: never decays; -1/2 at rho_b = 0.8) while
    the node's mass grows, and it reaches the particles with full weight: on the L2 colliding
    discs (10 cells, cfl 0.3) at rho_b = 1 the nodal a^n grew to ~2e2 (particle velocities
    0.1), so v_p = s_p + dt a_p / 2 and the kinetic energy were garbage (E = 27 E0 at step
    150) although x and s_p stayed equal to USL; at rho_b = 0.8 the spike enters du with the
    coefficient dt^2 (gamma - beta / (1 - alpha_m)) = 0.16 dt^2 and particles inverted at
    step 114. Rebuilt from the particles, a_i^n = sum_p N_ip m_p a_p / m_i is a mass-weighted
    average of particle accelerations, so it is bounded by them whatever the nodal mass, and
    the parasitic mode of a^n is multiplied per step by -alpha_m / (1 - alpha_m) times an
    eigenvalue of P2G G2P (in [0, 1]), so it cannot grow.
    rho_b = 1 is still symplectic-Euler USL (fm.Explicit("USL", flip)) exactly, for any a^n:
    with alpha_m = beta = 1/2, gamma = 1, du = dt (v^n - dt a^n / 2) + dt^2 f / m =
    dt (P2G(s_p) + dt f / m) and s_p += dt sum N f / m, which is USL with v_p^USL = s_p;
    so x, u, stress agree, v_p - dt a_p / 2 equals the USL particle velocity, and the
    dashpot velocity s is the USL start-of-step velocity, so Robin bases agree too.
    (An earlier version carried a^n per node and needed a correction
    v^n = (m v) / m + (gamma - 1/2) dt (a^n - (m a) / m) for that; with a^n = (m a) / m the
    correction is zero.)
    Why the dashpots take s: explicit dashpot forces at v^n are unconditionally unstable at
    rho_b = 1 (pure damper, c dt / m = 0.1: spectral radius 1.105) and a pure damper is stable
    only for c dt / m <= 0.5 at rho_b = 0.8 (W1 column, viscous base: inverted particles at
    rho_b = 1, particles through the base at 0.8); at s a pure damper is stable up to
    c dt / m = 2 (USL's limit) for every rho_b, with stiffness the stable region contains that
    of v^n, and at rho_b = 1 it is USL's, Omega^2 + 2 c dt / m <= 4 (tests: damper stability).
    Near Omega_s the combined limit is tighter for rho_b < 1 than for USL (rho_b = 0.8,
    Omega = 0.9 Omega_s: c dt / m < 0.125).
    Cost: no extra transfers (the P2G of m_p a_p was already done); for rho_b < 1 the
    alpha_m blend uses the transfer-smoothed a^n, P2G G2P a^n = a^n + O(h^2) for smooth
    fields but about a^n / 4 for the grid zigzag, so the algorithmic damping of the grid's
    highest modes is not the single-DOF figure (in MPM the FLIP transfers already remove the
    grid zigzag within ~10 steps at every rho_b, USL included). s lags v^n by
    (gamma - 1/2) dt (dt / 2 at rho_b = 1, as USL's own start-of-step velocity), so a dashpot
    is first order in time, as in USL."""
    explicit = True

    def __init__(self, rho_b=0.8, flip=1.0):
        self.params = explicit_parameters(_radius(rho_b, "rho_b", "ExplicitGeneralizedAlpha"))
        if isinstance(flip, bool) or not isinstance(flip, (int, float)) or not (0.0 <= flip <= 1.0):
            raise ValueError(f"ExplicitGeneralizedAlpha: 'flip' must be in [0, 1], got {flip!r}")
        self.rho_b, self.flip = self.params.rho_b, float(flip)
        self.stability_factor = 0.5 * self.params.omega_s

    def setup(self, sim):
        """Nothing to prepare (integrator protocol: Simulation calls setup(sim) once)."""
        pass

    def step(self, sim, dt):
        """Advance `sim` by dt (integrator protocol: called by Simulation.step)."""
        p, grid, T, prm = sim.particles, sim.grid, sim.timers, self.params
        shift = prm.gamma - 0.5
        sim.locate_and_shape()
        t0 = time.perf_counter()
        m, mv = sim.nodal_mass_momentum()
        ma = sim.nodal_weighted(p.a)
        grid.accumulate(m, mv, ma)
        T["p2g"] += time.perf_counter() - t0
        with sim.timed("solve"):                   # (its restriction pass counts as "shape")
            active = sim.active_mask(m)
        t0 = time.perf_counter()
        inv_m, a0, v0 = np.empty_like(m), np.empty_like(ma), np.empty_like(mv)
        nodal.inverse_mass(m, active, inv_m)
        free = ~sim.fixed
        nodal.grid_velocity(ma, inv_m, free, a0)        # (m a)_i / m_i on free components
        nodal.grid_velocity(mv, inv_m, free, v0)
        T["solve"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        f = np.zeros_like(mv)
        sim.internal_force(sim.dynamic_stress(p.stress), f)
        grid.accumulate(f)
        f += sim.external_force(sim.t, m, active=active)
        # dashpots at the transported velocity (nodal and particle: v - (gamma - 1/2) dt a)
        fr = sim.boundary_force(v0 - shift * dt * a0,
                                p.v - shift * dt * p.a if sim.layers else None)
        if fr is not None:
            f += fr
        t1 = time.perf_counter()
        acc = np.empty_like(f)
        nodal.grid_velocity(f, inv_m, free, acc)          # f_i / m_i on free components
        a1, v1, du = explicit_update(prm, dt, v0, a0, acc)
        t2 = time.perf_counter()
        g2p_generalized_alpha(grid.D, sim.nodes, sim.N, du, a0, a1, v1, shift, dt, self.flip,
                              p.x, p.u, p.v, p.a)
        t3 = time.perf_counter()
        T["p2g"] += t1 - t0
        T["solve"] += t2 - t1
        T["g2p"] += t3 - t2
        sim.stress_update(du, 1.0)
        if sim.robin is not None:
            sim.robin_u += du
        sim.nodal = dict(mass=m, velocity=v1, active=active, displacement=du)


class ImplicitGeneralizedAlpha(Newmark):
    """Implicit generalized-alpha (Chung & Hulbert 1993), spectral radius at infinite
    frequency rho_inf in [0, 1] (module docstring), solved by Newton with PETSc KSP like
    Newmark (whose step handles alpha_m and alpha_f). rho_inf = 1 is the trapezoidal rule
    in generalized-midpoint form; smaller rho_inf damps the high frequencies more.
    Keyword arguments (rtol, utol, max_iter, flip, petsc_options, prefix) as for Newmark."""

    records_work = False            # f_ext here carries alpha_f-weighted start forces
    supports_prescribed_motion = False  # Newmark's moving dofs not checked with alpha_f, alpha_m

    def __init__(self, rho_inf=0.8, **kw):
        prm = implicit_parameters(_radius(rho_inf, "rho_inf", "ImplicitGeneralizedAlpha"))
        _Newton.__init__(self, **kw)
        self.params = prm
        self.rho_inf = prm.rho_inf
        self.alpha_m, self.alpha_f, self.beta, self.gamma = prm.alpha_m, prm.alpha_f, prm.beta, prm.gamma
