"""Explicit symplectic-Euler MPM with the USF, USL and MUSL update orders.

Grid momentum balance on active nodes (seed 002 §2.4, lumped mass):
    v_i^n = (m v)_i / m_i,   v_i^{n+1} = v_i^n + dt f_i / m_i,
particles: x_p += dt sum N v^{n+1}, v_p by the velocity transfer, and the stress from
dF = I + dt L with L = sum v_i (x) grad N_i, taken from
    USF:  v^n            before the forces (stress updated first),
    USL:  v^{n+1}        after the grid update,
    MUSL: v^{n+1} re-mapped from the updated particle momenta (Sulsky et al. 1995),
    AVG:  half steps: dt/2 with v^n before the forces, dt/2 with the re-mapped v^{n+1}
          after them (seed 002 §4.4, "combining the two formulations", steps 1-8).
Nodes with a mass below the simulation's mass tolerance are inactive: zero velocity,
no division by their mass.

Velocity transfer (`transfer`):
    "flip": v_p += sum N (v^{n+1} - v^n) blended with PIC by `flip` (1: FLIP, 0: PIC);
    "apic": the affine particle-in-cell transfer (Jiang et al. 2015; kernels.transfer
            p2g_affine/g2p_affine): each particle carries C_p = sum v_i (x) grad N_ip and
            gives the nodes m_p (v_p + C_p (x_i - x_p)), so an affine velocity field (a rigid
            rotation) is transferred exactly; per-particle field `apic_C` (migrates, and is
            checkpointed; set from the initial velocities by Explicit.initial_affine);
    "aflip": the affine FLIP of Fei et al. 2021: APIC's C_p and affine P2G with FLIP's
            velocity increment (blended with PIC by `flip`), so the non-affine motion is not
            damped as by APIC (colliding discs: energy -3.0 % against -15.5 %; FLIP -0.31 %)
            while a rigid rotation keeps its angular momentum (bench transfer);
    "xpic": XPIC(m) of Hammerquist & Nairn 2017 (m = `xpic_order`): with S the grid-to-particle
            interpolation, S+ the mass-weighted particle-to-grid map and Q = S+ S,
                v* = sum_{k=1}^{m} (-1)^(k+1) C(m, k) Q^(k-1) v^L,   v^L = S+ v_p^n,
                v_p^(n+1) = S (v^(n+1) - v^L + v*)     (on free components),
            i.e. FLIP with (I - S S+)^m v_p^n taken off: the part of the particle velocities
            the grid cannot see (null-space noise) goes, the rest is kept as FLIP keeps it.
            XPIC(1) is PIC; each order past 1 costs one more grid-particle-grid pass."""
import logging
import time

import numpy as np

from ..kernels import nodal
from ..kernels import transfer as kt

_log = logging.getLogger("fenicsmpm")

SCHEMES = ("USF", "USL", "MUSL", "AVG")
TRANSFERS = ("aflip", "apic", "flip", "xpic")
STARTS = ("euler", "leapfrog")
AFFINE = ("aflip", "apic")      # the transfers that carry the affine matrix apic_C
NO_FLIP = ("apic", "xpic")      # the transfers without a FLIP fraction
PLASTIC_FLIP = 0.99     # the default FLIP fraction when a material flows plastically


def default_flip(materials):
    """The FLIP fraction `flip=None` resolves to: 1 (pure FLIP) for elastic scenes, PLASTIC_FLIP
    when a material flows plastically (`plastic = True`: Mohr-Coulomb, von Mises,
    Hypoplastic). Decided by data (issue 21, `python -m fenicsmpm.bench granular-collapse`):
    on a rough base pure FLIP keeps particle-velocity noise that the held base nodes cannot
    see, so a granular collapse never comes to rest and runs out 26-120 % beyond Lube et al.'s
    law; with 1 % PIC every aspect ratio 0.5-4 stops by 3.8 T and runs out within 18 %. Elastic
    scenes keep pure FLIP: there the blend would damp the waves (bench transfer)."""
    return PLASTIC_FLIP if any(getattr(m, "plastic", False) for m in materials) else 1.0


class Explicit:
    """Explicit symplectic-Euler MPM with the update order `scheme` ("USF", "USL", "MUSL",
    "AVG"; module docstring) and the FLIP/PIC blend `flip` (1: FLIP, 0: PIC) for particle
    velocities. Needs dt below the critical step (dt="auto" gives cfl * h / c_p). Fills the
    particle acceleration a = (v_new - v_old) / dt (dt / 2 on a leapfrog start, `start`).

    `damping` (1/s, default 0; set as an attribute, as problems.column.DampedExplicit does) adds
    the mass-proportional viscous force -damping m_i v_i^n to the grid momentum balance, where
    the transfer and the stress update see it (damping the particle velocities between steps
    instead put AVG's deformation gradient out of step with the particle positions: V2 at 16
    cells, cpGIMP, stress error 0.0183 against 0.0071 with the force;
    tests/test_explicit_damping.py)."""
    explicit = True
    damping = 0.0
    records_work = True
    reports_reaction = True             # sim.nodal["reaction"] after each step
    supports_friction = True
    supports_prescribed_motion = True

    def __init__(self, scheme="MUSL", flip=None, transfer=None, displacement=None,
                 start="euler", xpic_order=2):
        """scheme: one of SCHEMES; transfer: one of TRANSFERS (default "flip"; module
        docstring); xpic_order: m of transfer="xpic" (an int >= 1; 1 is PIC);
        flip: the FLIP fraction of transfer="flip" or "aflip" (default None:
        `default_flip` of the scene's materials,
        1 for elastic scenes, PLASTIC_FLIP = 0.99 where a material flows plastically).

        displacement: None, or u(x, t) -> (n, gdim) for prescribed motion: the fixed dofs
        (sim.fix) move with the velocity (u(x, t + dt) - u(x, t)) / dt in the step (x the node
        coordinates) instead of resting; the force the fixed dofs exert on the material,
        R = m (v - v*) / dt with v* the unconstrained velocity, is sim.nodal["reaction"]
        (summed over ranks), as fm.QuasiStatic(displacement=...) gives it. To move one
        boundary only: sim.fix(where, components, displacement=u(t) or velocity=v).

        start: one of STARTS. "euler" (default): every step updates the velocities over dt,
        v^1 = v^0 + dt f^0 / m on the first, so a load present at t = 0 starts the response
        half a step early (a phase error of order dt). "leapfrog": the run's first step updates
        them over dt / 2 only, v^(1/2) = v^0 + dt/2 f^0 / m (the central-difference start of
        Belytschko, Liu & Moran 2014, Box 6.1), so positions and stresses are second order in
        dt from rest (a body in free fall falls g t^2 / 2 exactly; `bench column-peers`, 1 x 20:
        top-displacement error 1.55 % against 2.14 %), while particle velocities, the kinetic
        energy and the momentum read after step n belong to t_n - dt/2."""
        if start not in STARTS:
            raise ValueError(f"Explicit: 'start' must be one of {STARTS}, got {start!r}")
        self.start = start
        if displacement is not None and not callable(displacement):
            raise TypeError(f"Explicit: 'displacement' must be None or u(x, t), got {displacement!r}")
        self.displacement, self._vp = displacement, None
        scheme = str(scheme).upper()
        if scheme not in SCHEMES:
            raise ValueError(f"Explicit: 'scheme' must be one of {SCHEMES}, got {scheme!r}")
        if transfer is None:
            transfer = "flip"
        if transfer not in TRANSFERS:
            raise ValueError(f"Explicit: 'transfer' must be one of {TRANSFERS}, got {transfer!r}")
        if flip is not None and transfer in NO_FLIP:
            raise ValueError(f"Explicit: 'flip' applies to transfer='flip' or 'aflip', got "
                             f"transfer={transfer!r} and flip={flip!r}")
        if isinstance(xpic_order, bool) or not isinstance(xpic_order, (int, np.integer)) \
                or xpic_order < 1:
            raise ValueError(f"Explicit: 'xpic_order' must be an int >= 1, got {xpic_order!r}")
        self.xpic_order = int(xpic_order)
        self._flip_auto = flip is None and transfer not in NO_FLIP
        flip = 1.0 if flip is None else flip
        if isinstance(flip, bool) or not (isinstance(flip, (int, float, np.floating))
                                          and 0.0 <= flip <= 1.0):
            raise ValueError(f"Explicit: 'flip' must be in [0, 1], got {flip!r}")
        self.scheme, self.flip, self.transfer = scheme, float(flip), transfer
        if transfer == "xpic":
            self.flip = 0.0          # the particle velocity is S (...) (module docstring)

    def setup(self, sim):
        if self._flip_auto:
            self.flip = default_flip(sim.particles.materials)
            if self.flip != 1.0 and sim.comm.rank == 0:
                _log.info("Explicit(flip=None): flip = %g (a material flows plastically; "
                          "pass flip=1.0 for pure FLIP)", self.flip)
        if self.transfer in AFFINE and not hasattr(sim.particles, "apic_C"):
            sim.particles.add_field("apic_C", (sim.gdim, sim.gdim))
            self.initial_affine(sim)

    def initial_affine(self, sim):
        """Set each particle's affine matrix C_p from the current particle velocities
        (collective): two sweeps of the affine P2G (C_p = 0 in the first) and C_p from its grid
        velocity as in kernels.transfer.g2p_affine; v_p and x_p stay. A linear velocity field
        (a rigid rotation) then starts with its gradient instead of C_p = 0, so the affine
        parts count from the first step on (spinning disc, one turn, APIC: kinetic energy
        -0.13 % against -4.5 % from C_p = 0). Called when the field is created; call it again
        after setting p.v by hand."""
        p, g = sim.particles, sim.grid
        if p.n_global() == 0:
            return
        sim.locate_and_shape()
        zero = np.zeros((g.n_nodes, g.gdim))
        v_p = p.v.copy()
        p.apic_C[:] = 0.0
        for _ in range(2):
            m, mv = self._p2g(sim)
            g.accumulate(m, mv)
            active = sim.active_mask(m)
            inv_m = np.divide(1.0, m, out=np.zeros_like(m), where=active)
            v = mv * inv_m[:, None]
            kt.g2p_affine(g.D, sim.nodes, sim.N, sim.dN, g.node_x, zero, v, v, 0.0,
                          p.x, p.v, p.u, p.apic_C)
            p.v[:] = v_p

    def _prescribed(self, sim, dt):
        """The fixed dofs' velocity this step, (u(t + dt) - u(t)) / dt from
        sim.prescribed_increment (this integrator's `displacement` and sim.fix(...,
        displacement=/velocity=)), or None without prescribed motion."""
        du = sim.prescribed_increment(sim.t, sim.t + dt, self.displacement)
        return None if du is None else du / dt

    def _p2g(self, sim):
        """Nodal mass and momentum of the particles, local (not yet summed over ranks): affine
        (APIC, kernels.transfer.p2g_affine) by `transfer`, else the simulation's plain P2G."""
        if self.transfer not in AFFINE:
            return sim.nodal_mass_momentum()
        g, p = sim.grid, sim.particles
        m = np.zeros(g.n_nodes)
        mv = np.zeros((g.n_nodes, g.gdim))
        kt.p2g_affine(g.D, sim.nodes, sim.N, p.mass, p.v, p.apic_C, p.x, g.node_x, m, mv)
        return m, mv

    def _xpic_change(self, sim, vL, inv_m):
        """v^L - v* of XPIC(m) (module docstring): sum_{k=1}^{m} (-1)^(k+1) C(m, k) Q^(k-1) v^L
        subtracted from v^L, each Q = S+ S one interpolation to the particles and one
        mass-weighted P2G (summed over ranks). 0 for m = 1 (PIC)."""
        from math import comb
        g, p, m = sim.grid, sim.particles, self.xpic_order
        change = vL.copy()
        term = vL
        q = np.zeros((len(p), g.gdim))
        for k in range(1, m + 1):
            change -= (-1) ** (k + 1) * comb(m, k) * term
            if k < m:                                   # term = Q term
                q[:] = 0.0
                kt.flip_blend(g.D, sim.nodes, sim.N, term, term, 0.0, q)
                term = np.zeros_like(vL)
                kt.p2g_weighted(g.D, sim.nodes, sim.N, p.mass, q, term)
                g.accumulate(term)
                term *= inv_m[:, None]
        return change

    def _kick(self, sim, dt):
        """The time step of this step's velocity update: dt / 2 on a run's first step with
        start="leapfrog", else dt (constructor docstring)."""
        return 0.5 * dt if self.start == "leapfrog" and sim.step_count == 0 else dt

    def _grid_velocity(self, momentum, inv_m, free):
        """v_i = (m v)_i / m_i on active nodes, 0 on inactive nodes and fixed components."""
        v = np.empty_like(momentum)
        nodal.grid_velocity(momentum, inv_m, free, v)
        return v

    def _contact(self, sim, v, dt, mass):
        """Frictional boundaries project the trial nodal velocities v in place for the gaps of
        the start of the step and decide the contact (boundaries.friction); the Dirichlet
        conditions (sim.fix) hold after it."""
        for b, g in zip(sim.frictions, self._gaps):
            b.apply(v, g, dt, mass)
        v *= ~sim.fixed
        if self._vp is not None:
            v += self._vp

    def _hold(self, sim, v, dt):
        """A velocity the stress update sees keeps the contact the trial projection decided
        (the previous step's for USF's start-of-step velocity)."""
        for b, g in zip(sim.frictions, self._gaps):
            b.hold(v, g, dt)

    def step(self, sim, dt):
        """Advance `sim` by dt (integrator protocol: called by Simulation.step)."""
        p, grid, T = sim.particles, sim.grid, sim.timers
        sim.locate_and_shape()
        with sim.timed("g2p"):
            p.a[:] = p.v                  # the start-of-step velocity, for the acceleration
        t0 = time.perf_counter()
        self._gaps = [b.gaps(sim) for b in sim.frictions]
        m, mv = self._p2g(sim)
        grid.accumulate(m, mv)
        T["p2g"] += time.perf_counter() - t0
        # the gradients' restriction to the active nodes: here (timed as "shape") where the
        # stress is updated before the internal force, else in the force's pass ("p2g")
        early = self.scheme in ("USF", "AVG")
        with sim.timed("solve"):                   # (its restriction pass counts as "shape")
            active = sim.active_mask(m, restrict=early)
        t0 = time.perf_counter()
        inv_m = np.empty_like(m)
        nodal.inverse_mass(m, active, inv_m)
        free = ~sim.fixed
        v0 = self._grid_velocity(mv, inv_m, free)
        vp = self._vp = self._prescribed(sim, dt)      # fixed dofs' velocity this step
        if vp is not None:
            v0 += vp
        if sim.frictions:                # nodes in contact start as fixed nodes do (last status)
            self._hold(sim, v0, dt)
        T["solve"] += time.perf_counter() - t0
        if self.scheme in ("USF", "AVG"):
            sim.stress_update(v0, dt if self.scheme == "USF" else 0.5 * dt)
        t0 = time.perf_counter()
        f = np.zeros_like(mv)
        sim.internal_force(sim.dynamic_stress(p.stress), f, active=None if early else active)
        grid.accumulate(f)
        f_ext = sim.external_force(sim.t, m, active=active)
        f += f_ext
        fr = sim.boundary_force(v0)                # Robin tractions from the start-of-step state
        if fr is not None:
            f += fr
        if self.damping:                           # mass-proportional damping force
            f -= self.damping * m[:, None] * v0
        t1 = time.perf_counter()
        kick = self._kick(sim, dt)                 # dt, or dt / 2 on a leapfrog start
        v1 = np.empty_like(v0)
        nodal.kicked_velocity(v0, f, inv_m, free, kick, v1)
        reaction = np.empty_like(v1)                       # R = m (v - v*) / kick
        nodal.fixed_reaction(sim.fixed, active, m, v1, mv, f, inv_m, kick, reaction)
        if vp is not None:                          # the work of moving the fixed dofs
            fr = reaction if fr is None else fr + reaction
        if sim.frictions:                           # contact force m (v1 - v1_trial) / dt
            v_trial = v1.copy()
            self._contact(sim, v1, kick, m)
            fc = m[:, None] * (v1 - v_trial) / kick
            fr = fc if fr is None else fr + fc
        sim.record_work(f_ext, fr, v0, v1, dt)       # fixed components: v0 = v1 = 0
        t2 = time.perf_counter()
        du = dt * v1                                # what the particles move by (CPDI2 corners)
        affine = self.transfer in AFFINE
        remap = self.scheme in ("MUSL", "AVG")     # the updated velocities mapped back
        mv2 = None
        aflip = self.flip if self.transfer == "aflip" else 0.0
        v_to_p = v1                                  # the velocity the particles interpolate
        if self.transfer == "xpic":
            v_to_p = v1 - self._xpic_change(sim, mv * inv_m[:, None], inv_m) * free
        if affine and remap:                         # G2P and that P2G in one particle pass
            mv2 = np.zeros_like(mv)
            kt.g2p_affine_momentum(grid.D, sim.nodes, sim.N, sim.dN, grid.node_x, du, v0, v1,
                                   aflip, p.x, p.v, p.u, p.apic_C, p.mass, mv2)
        elif affine:
            kt.g2p_affine(grid.D, sim.nodes, sim.N, sim.dN, grid.node_x, du, v0, v1, aflip,
                          p.x, p.v, p.u, p.apic_C)
        elif remap:
            mv2 = np.zeros_like(mv)
            kt.g2p_momentum(grid.D, sim.nodes, sim.N, du, v0, v_to_p, self.flip, p.x, p.v,
                            p.u, p.mass, mv2)
        else:
            kt.g2p(grid.D, sim.nodes, sim.N, du, v0, v_to_p, self.flip, p.x, p.v, p.u)
        t3 = time.perf_counter()
        T["p2g"] += t1 - t0
        T["solve"] += t2 - t1
        T["g2p"] += t3 - t2
        if remap:
            grid.accumulate(mv2)
            v1 = self._grid_velocity(mv2, inv_m, free)
            if vp is not None:
                v1 += vp
            self._hold(sim, v1, dt)
            T["p2g"] += time.perf_counter() - t3
        if self.scheme != "USF":
            sim.stress_update(v1, dt if self.scheme != "AVG" else 0.5 * dt)
        with sim.timed("g2p"):
            if sim.robin is not None:
                sim.robin_u += dt * v1
            sim.nodal = dict(mass=m, velocity=v1, active=active, reaction=reaction,
                             displacement=du)
            nodal.particle_acceleration(p.v, p.a, kick)   # a = (v_new - v_old) / dt
