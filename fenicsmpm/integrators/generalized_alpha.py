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
      1. P2G: m_i, (m v)_i, (m a)_i from the particles; the start-of-step grid velocity is
           v_i^n = (m v)_i / m_i + (gamma - 1/2) dt (a_i^n - (m a)_i / m_i).
      2. a_i^{n+1-alpha_m} = (f_ext - f_int)_i / m_i from the start-of-step stress, then
         a^{n+1}, v^{n+1}, du from `explicit_update` (BENCHMARKS P steps 2-4).
      3. Particles (`g2p_generalized_alpha`): x, u += sum N du; the velocity is integrated at
         the particles (FLIP; PIC blend by `flip`); a_p = sum N a^{n+1}.
      4. Stress from dF = I + grad du (as USL); Robin and particle-layer forces, as in
         Explicit, come from the start-of-step state.

    a^n is kept per node between steps (seed 003 step 9). It is rebuilt from the particles,
    a_i^n = (m a)_i / m_i = sum_p N_ip m_p a_p / m_i, at the nodes that were not active in the
    previous step (all nodes in the first step after setup, where p.a = 0 gives the seed's
    a^0 = 0), and set to zero at inactive nodes.

    Why the correction in step 1: the transported particle quantity is
    s_p = v_p - (gamma - 1/2) dt a_p, for which step 3 is s_p += dt sum N (a^n + a^{n+1}) / 2.
    With v_i^n = P2G(v_p) alone, the P2G of the G2P of a^n (not the identity in MPM) leaves
    du with an extra dt^2 (P2G G2P - I) a^n / 2 at rho_b = 1, so the scheme would not be
    central difference (and the V1 bar at rho_b = 1 blows up within 2000 steps even at
    cfl 0.1). With the correction, rho_b = 1 reproduces symplectic-Euler USL
    (fm.Explicit("USL", flip)) exactly for any a^n: same x, u, stress, and
    v_p - dt a_p / 2 equals its particle velocity."""
    explicit = True

    def __init__(self, rho_b=0.8, flip=1.0):
        self.params = explicit_parameters(_radius(rho_b, "rho_b", "ExplicitGeneralizedAlpha"))
        if isinstance(flip, bool) or not isinstance(flip, (int, float)) or not (0.0 <= flip <= 1.0):
            raise ValueError(f"ExplicitGeneralizedAlpha: 'flip' must be in [0, 1], got {flip!r}")
        self.rho_b, self.flip = self.params.rho_b, float(flip)
        self.stability_factor = 0.5 * self.params.omega_s
        self._a = self._active = None

    def setup(self, sim):
        self._a = np.zeros((sim.grid.n_nodes, sim.gdim))
        self._active = np.zeros(sim.grid.n_nodes, dtype=bool)

    def step(self, sim, dt):
        p, grid, T, prm = sim.particles, sim.grid, sim.timers, self.params
        shift = prm.gamma - 0.5
        sim.locate_and_shape()
        t0 = time.perf_counter()
        m, mv = sim.nodal_mass_momentum()
        ma = sim.nodal_weighted(p.a)
        grid.accumulate(m, mv, ma)
        T["p2g"] += time.perf_counter() - t0
        active = sim.active_mask(m)
        t0 = time.perf_counter()
        inv_m = np.divide(1.0, m, out=np.zeros_like(m), where=active)
        free = ~sim.fixed
        a_p2g = ma * inv_m[:, None]
        a0 = np.where((active & ~self._active)[:, None], a_p2g, self._a)
        a0 *= active[:, None] & free
        v0 = (mv * inv_m[:, None] + shift * dt * (a0 - a_p2g)) * free
        T["solve"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        f = np.zeros_like(mv)
        sim.internal_force(sim.dynamic_stress(p.stress), f)
        grid.accumulate(f)
        f += sim.external_force(sim.t, m, active=active)
        fr = sim.boundary_force(v0)
        if fr is not None:
            f += fr
        t1 = time.perf_counter()
        a1, v1, du = explicit_update(prm, dt, v0, a0, f * inv_m[:, None] * free)
        t2 = time.perf_counter()
        g2p_generalized_alpha(grid.D, sim.nodes, sim.N, du, a0, a1, v1, shift, dt, self.flip,
                              p.x, p.u, p.v, p.a)
        t3 = time.perf_counter()
        T["p2g"] += t1 - t0
        T["solve"] += t2 - t1
        T["g2p"] += t3 - t2
        kt.incremental_F(grid.D, sim.nodes, sim.dN, du, 1.0, sim._dF)
        T["constitutive"] += time.perf_counter() - t3
        sim.trial_stress(sim._dF)
        sim.commit(sim._dF)
        if sim.robin is not None:
            sim.robin_u += du
        self._a, self._active = a1, active
        sim.nodal = dict(mass=m, velocity=v1, active=active)


class ImplicitGeneralizedAlpha(Newmark):
    """Implicit generalized-alpha (Chung & Hulbert 1993), spectral radius at infinite
    frequency rho_inf in [0, 1] (module docstring), solved by Newton with PETSc KSP like
    Newmark (whose step handles alpha_m and alpha_f). rho_inf = 1 is the trapezoidal rule
    in generalized-midpoint form; smaller rho_inf damps the high frequencies more.
    Keyword arguments (rtol, utol, max_iter, flip, petsc_options, prefix) as for Newmark."""

    def __init__(self, rho_inf=0.8, **kw):
        prm = implicit_parameters(_radius(rho_inf, "rho_inf", "ImplicitGeneralizedAlpha"))
        _Newton.__init__(self, **kw)
        self.params = prm
        self.rho_inf = prm.rho_inf
        self.alpha_m, self.alpha_f, self.beta, self.gamma = prm.alpha_m, prm.alpha_f, prm.beta, prm.gamma
