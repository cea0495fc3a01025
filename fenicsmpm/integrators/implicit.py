"""Implicit MPM: Newmark dynamics and quasi-static loading, solved by Newton with PETSc KSP.

Updated-Lagrangian step on the grid, with the start-of-step configuration as reference:
unknown nodal displacement increment du, dF_p = I + sum du_i (x) grad N_ip,
  f_int,i = sum_p V_p P_p grad N_ip,   P = det(dF) sigma dF^-T   (first Piola of the step),
  K_ij    = sum_p V_p grad N_i . A_p . grad N_j,   A = dP/d(dF)   (consistent tangent).
Newmark (beta, gamma) with lumped mass (seed 000 eqs 2.30-2.32, errata: 1/(beta dt^2), not 1/dt):
  a^{n+1} = (du - dt v^n - dt^2 (1/2 - beta) a^n) / (beta dt^2),
  v^{n+1} = v^n + dt ((1 - gamma) a^n + gamma a^{n+1}),
  R = f_ext(t^{n+1}) - f_int(du) - M a^{n+1},   J = K + M / (beta dt^2).
Generalized-alpha (Chung & Hulbert 1993, BENCHMARKS P; generalized_alpha.py) weights the
inertia at n+1-alpha_m and the forces at n+1-alpha_f; its residual, divided by 1 - alpha_f,
  R = f(t^{n+1}; du) + alpha_f / (1 - alpha_f) f(t^n) - M ((1 - alpha_m) a^{n+1} + alpha_m a^n) / (1 - alpha_f),
  J = K + (1 - alpha_m) / (1 - alpha_f) M / (beta dt^2),
with f = f_ext - f_int (+ Robin, particle layers) and f(t^n) from the committed state;
alpha_m = alpha_f = 0 is Newmark.
Particle velocities and accelerations are updated FLIP-style from the nodal changes (a PIC
projection of the acceleration loses about 1 % of the energy per 5 periods of the V1 bar at
5x the critical step; FLIP about 0.1 %). Quasi-static drops the inertia terms and ramps gravity over `load_steps` steps.
Inactive (massless) nodes and Dirichlet dofs are constrained (unit diagonal, zero residual).
Newton options (all implicit integrators): rtol, utol, max_iter, and line_search = k >= 0: a
correction that raises |R| or makes it non-finite is halved up to k times (backtracking; 0:
the full Newton step), or
"auto" (the default): the full Newton step, and if Newton fails on a step (diverges, reaches
max_iter or a non-finite residual) the same step once more from du = 0 with
line_search = AUTO_LINE_SEARCH (6), its trial corrections no longer than AUTO_TRUST = 0.05 cell
sizes on any node (a trust radius: the retry starts each backtracking at
alpha = min(1, 0.05 h / max|delta|), so it moves no node more than max_iter x 0.05 h), before the
step is given up (a dt cut, max_dt_cuts). Steps that converge with the full step are therefore
unchanged. Measured (`tests/test_line_search.py`): the
Prandtl footing of a smooth rigid strip on von Mises soil (h = 0.1 m, 1 mm steps, no step cuts)
diverges at step 27 with the full step and runs to the end with line_search=6 and with "auto";
in the softening shear layer of test_regularisation line_search=6 on every step raises the
worst step's Newton iterations from 5 to 9, "auto" leaves them at 5.
Newton stops early, as not converged (a step cut then retries it), once |R| exceeds
_Newton.DIVERGED = 1e3 times its value at the start of the step; the error names the
closest |R|/|f| reached. (The W5 footing at 4.5 cells, 2026-12-04: Newton reached 4.8e-5,
then grew to 1e15 over the remaining 20 of its 25 iterations.)"""
import logging
import time

import numpy as np

from ..kernels import axisymmetric as axi
from ..boundaries import particle_layer as kl
from ..boundaries import particle_motion as pm
from ..boundaries.dirichlet import prescribed_rates
from ..collective import gmax_of
from ..kernels import transfer as kt
from ..materials import first_piola, first_piola_tangent
from .linear_system import DEFAULT_PREFIX, LinearSystem, OutsidePattern, stencil_rings

MAX_RINGS = 4           # the widest implicit pattern _Newton._plan grows to (cell rings)
AUTO_LINE_SEARCH = 6    # line_search="auto": the backtracking depth of the retry of a failed step
# line_search="auto": the retry's longest trial correction on any node, in cell sizes. Measured
# (the footing of tests/test_line_search.py with E scaled by 1 + 1e-9 k, k = 0..119, serially):
# the full step fails on every run; without the radius the retry then failed on 5 of the 90
# runs k = 0..89 (Newton corrections of 6-20 h at a step that moves the soil 0.02 h, of which
# the last backtracking, alpha = 1/64, still took 0.1-0.3 h); with 0.25 h on 3 of 60, with
# 0.05 h on 1 of 120.
AUTO_TRUST = 0.05
log = logging.getLogger("fenicsmpm.newton")


# appended to a KSP failure in the preconditioner's set-up (a zero pivot of the LU)
SINGULAR_HINT = ("; the tangent is singular: some dofs are held only by particles that add "
                 "(almost) no stiffness, typically nodes of a cell the material has just begun "
                 "to enter; the ghost penalty on such cells, e.g. fm.QuasiStatic(ghost=0.01) or "
                 "fm.Newmark(ghost=0.01), removes the zero pivots (docs: integrators)")


# appended to a Newton failure that came within STALL_FACTOR x rtol and stalled there
STALL_FACTOR = 100.0
STALL_HINT = ("; it stalled just above rtol = {rtol:.3g}: the residual has a floor there "
              "(round-off, or a material whose update sub-steps adaptively, fm.Hypoplastic: "
              "demos/biaxial_test.py stalled at 1.2e-8); a larger rtol, e.g. rtol=1e-6, ends "
              "such steps")


class _NotConverged(RuntimeError):
    """Newton failed on this step (before any particle state changed)."""


class _Newton:
    explicit = False
    DIVERGED = 1e3                    # Newton stops once |R| exceeds this times its initial value
    iterative_default = False         # default KSP: GMRES + lagged LU (LinearSystem)
    reports_reaction = True             # sim.nodal["reaction"] after each step

    def __init__(self, rtol=1e-8, utol=1e-10, max_iter=25, flip=1.0, petsc_options=None,
                 prefix=DEFAULT_PREFIX, line_search="auto", ghost=0.0, ghost_fill=0.9):
        for name, val in (("rtol", rtol), ("utol", utol)):
            if isinstance(val, bool) or not (isinstance(val, (int, float)) and val > 0):
                raise ValueError(f"{type(self).__name__}: '{name}' must be > 0, got {val!r}")
        if isinstance(flip, bool) or not (isinstance(flip, (int, float)) and 0.0 <= flip <= 1.0):
            raise ValueError(f"{type(self).__name__}: 'flip' must be in [0, 1], got {flip!r}")
        if isinstance(max_iter, bool) or not (isinstance(max_iter, int) and max_iter >= 1):
            raise ValueError(f"{type(self).__name__}: 'max_iter' must be a positive integer, got {max_iter!r}")
        if petsc_options is not None and not isinstance(petsc_options, dict):
            raise TypeError(f"{type(self).__name__}: 'petsc_options' must be a dict of PETSc "
                            f"options or None, got {type(petsc_options).__name__}")
        if line_search != "auto" and (isinstance(line_search, bool) or not (
                isinstance(line_search, int) and 0 <= line_search <= 30)):
            raise ValueError(f"{type(self).__name__}: 'line_search' must be \"auto\" or an integer "
                             f"in [0, 30], got {line_search!r}")
        self.rtol, self.utol, self.max_iter, self.flip = rtol, utol, max_iter, float(flip)
        self.line_search = line_search
        for name, val in (("ghost", ghost), ("ghost_fill", ghost_fill)):
            if isinstance(val, bool) or not (isinstance(val, (int, float)) and val >= 0):
                raise ValueError(f"{type(self).__name__}: '{name}' must be a number >= 0, got {val!r}")
        self.ghost, self.ghost_fill = float(ghost), float(ghost_fill)
        self._ghost = None
        self.petsc_options, self.prefix = petsc_options, prefix
        self.system = None
        self.iterations = []     # Newton iterations per step (a retried step: both attempts)
        self.ksp_iterations = 0
        self.retries = 0         # steps that line_search="auto" retried with backtracking

    def setup(self, sim):
        """Build the PETSc linear system on the grid (integrator protocol: called once)."""
        shape = getattr(sim, "shape", "mpm")        # wide shapes: a pattern over cell rings
        if sim.fbar and sim.axisymmetric:          # particle layers: SetupMixin.add_boundary
            raise NotImplementedError(f"{type(self).__name__}: fbar=True needs a plane or 3D "
                                      f"grid (got an axisymmetric grid)")
        if self.ghost > 0:                  # facet terms couple the nodes of two cells
            from .ghost import GhostPenalty
            self._ghost = GhostPenalty(sim, self.ghost, self.ghost_fill)
        self.system = self._system(sim, stencil_rings(sim), shape)

    def _system(self, sim, rings, shape, iterative=None):
        """The LinearSystem of this integrator's options with a pattern of `rings` cell rings
        (iterative: the KSP default, None for this integrator's)."""
        return LinearSystem(sim.grid, self.petsc_options, self.prefix, rings=rings, shape=shape,
                            iterative=self.iterative_default if iterative is None else iterative)

    def _plan(self, sim):
        """(scatter plan, system) for this step. A wide family's particle domain that has
        grown past the static pattern (a stretched cpGIMP box) widens it by a cell ring
        (collective; logged on rank 0), up to MAX_RINGS, instead of stopping the run."""
        while True:
            try:
                if self._ghost is not None:     # the cell pairs of the penalised facets
                    g = self._ghost
                    self.system.extend(g.version, g.pairs, g.ufl_form)
                return self.system.plan(sim.nodes), self.system
            except OutsidePattern:
                old = self.system
                if old.rings >= MAX_RINGS or getattr(self, "double_mapping", False):
                    raise
                # a system whose iterative default failed keeps LU after the widening
                self.system = self._system(sim, old.rings + 1, old.shape,
                                           iterative=False if old.switched else None)
                self.system.switched = old.switched
                old.destroy()
                if sim.comm.rank == 0:
                    logging.getLogger("fenicsmpm").info(
                        "step %d: a particle domain grew past the implicit matrix pattern; "
                        "widened to %d cell rings", sim.step_count, self.system.rings)

    def strain_increment(self, sim, du):
        """sim._dF <- I + sum_i du_i (x) grad N_ip (the step's incremental deformation gradient);
        with F-bar the increment before averaging is kept in self._dF0 for the tangent."""
        if not sim.fbar:
            sim.incremental_F(du, 1.0, sim._dF)
            return
        if getattr(self, "_dF0", None) is None or self._dF0.shape != sim._dF.shape:
            self._dF0 = np.empty_like(sim._dF)
        kt.incremental_F(sim.grid.D, sim.nodes, sim.dN, du, 1.0, self._dF0)
        sim._dF[:] = self._dF0
        sim.average_volume_change(sim._dF)

    def assemble_tangent(self, sim, A4, plan, diag_add, constrained, extra=None):
        """K = sum_p V_p B^T A_p B + diag(diag_add) (+ extra terms, + the hoop terms of
        fenicsmpm.kernels.axisymmetric) into the PETSc matrix."""
        if sim.axisymmetric:
            def extra(data, more=extra):
                axi.hoop_stiffness(sim.nodes, sim.N, sim.dN, sim.particles.V, A4, sim._r, plan,
                                   self.system.nodeptr, constrained, data)
                if more is not None:
                    more(data)
        fb = None
        if sim.fbar:
            fb = (self._dF0, sim.particles.cell, sim.grid.n_cells, 3 if sim.gdim == 3 else 2)
        self.system.assemble(sim.nodes, sim.dN, sim.particles.V, A4, plan, diag_add, constrained,
                             extra, fb)

    def _norm(self, sim, r):
        own = r[: sim.grid.n_owned_nodes]
        s = float(np.sum(own * own))
        return np.sqrt(sim.comm.allreduce(s) if sim.comm.size > 1 else s)

    def solve_step(self, sim, *args, **kw):
        """_newton_step(sim, ...) (its docstring), timed as "solve" (Simulation.timed: the
        residuals' stress updates inside it count as "constitutive" only)."""
        with sim.timed("solve"):
            return self._newton_step(sim, *args, **kw)

    def _newton_step(self, sim, dt, f_ext, m_coef, inertia, velocity=None, c_v=0.0,
                     v_start=None, du0=None, force_scale=0.0):
        """Newton loop for du. inertia(du) returns the nodal inertial force M a^{n+1}(du) (or 0);
        m_coef is the mass-matrix factor 1/(beta dt^2) (0 for quasi-static); velocity(du) gives
        the end-of-step nodal velocity, with dv/du = c_v, for the Robin boundaries; v_start is
        the start-of-step nodal velocity (particle-layer velocities are updated FLIP-style).

        Converged when |R| <= rtol |f|, or when the last correction is below utol |du| with
        |R| <= sqrt(rtol) |f| (stagnation at round-off). |f| = max(|f_ext|, |f_int|, |R_0|,
        force_scale, and when du0 moves fixed dofs the reactions): the initial residual R_0 and
        force_scale (|M v^n| / dt + |M a^n| for
        Newmark) carry the inertial load when f_ext and f_int vanish (rigid motion), also when
        the predictor du0 is already exact."""
        p, grid, T, sys = sim.particles, sim.grid, sim.timers, self.system
        n = len(p)
        d = sim.gdim
        m = sim.nodal["mass"]
        constrained = (sim.fixed | ~sim.nodal["active"][:, None]).ravel()
        cmask = constrained.reshape(-1, d)
        # du0 keeps its values on active fixed dofs: prescribed increments (displacement control)
        du = (np.zeros((grid.n_nodes, d)) if du0 is None
              else np.where(cmask & ~(sim.fixed & sim.nodal["active"][:, None]), 0.0, du0))
        moving = bool(np.any(du[sim.fixed] != 0.0))     # the reactions then carry the load
        if sim.comm.size > 1:
            moving = sim.comm.allreduce(moving)
        ghost = self._ghost
        if ghost is not None:
            ghost.update(sim, sim.nodal["active"],
                         np.flatnonzero(constrained[: grid.n_owned_nodes * d]).astype(np.int32))
        t0 = time.perf_counter()
        plan, sys = self._plan(sim)
        T["assembly"] += time.perf_counter() - t0
        # work arrays kept between steps (fresh ones cost their page faults every step)
        P = sim._per_particle("newton_P", (3, 3))
        dsig = sim._per_particle("newton_dsig", (3, 3, 3, 3))
        A4 = sim._per_particle("newton_A4", (3, 3, 3, 3))
        # a plane-strain stiffness reads only A4's in-plane entries (first_piola_tangent;
        # F-bar's too: kernels.fbar.fbar_stiffness averages over n = 2 there)
        plane = d == 2 and not sim.axisymmetric
        idx = np.arange(n, dtype=np.int64)
        fext_norm = self._norm(sim, np.where(cmask, 0.0, f_ext))
        motion = pm.targets(sim, sim.t + dt) if sim.particle_motions else None
        if motion is not None:
            f_motion = np.zeros((len(motion[0]), d))

        def newton_residual(du, it):
            """(R, |R|, fint, reaction, sig) at du, Newton iteration `it`; leaves sim._dF (and
            F-bar's dF0) at du. FloatingPointError (on every rank: |R| is global) when |R| is
            not finite."""
            self.strain_increment(sim, du)
            sig = sim.trial_stress(sim._dF)
            first_piola(idx, sim._dF, sim.dynamic_stress(sig), P)
            fint = np.zeros_like(du)
            sim.internal_force(P, fint)          # -f_int (local)
            grid.accumulate(fint)
            R = f_ext + fint - inertia(du)
            if ghost is not None:
                R -= ghost.force(du)
            if motion is not None:
                fm_ = np.zeros_like(du)
                pm.penalty_force(motion[0], sim.nodes, sim.N, du, motion[1], motion[2],
                                 motion[3], fm_, f_motion)
                grid.accumulate(fm_)
                R += fm_
            robin = sim.robin
            if robin is not None or sim.layers:
                fr = np.zeros_like(du)
                if robin is not None:
                    robin.force(sim.robin_u + du, velocity(du), fr)
                if sim.layers:
                    u_rel, v_p = p.u - p.layer_u0, p.v.copy()
                    kt.flip_blend(sim.grid.D, sim.nodes, sim.N, np.zeros_like(du), du, 1.0, u_rel)
                    kt.flip_blend(sim.grid.D, sim.nodes, sim.N, v_start, velocity(du), 1.0, v_p)
                    sim.layer_force(u_rel, v_p, fr)
                grid.accumulate(fr)
                R += fr
            reaction = np.where(sim.fixed, -R, 0.0)
            R[cmask] = 0.0
            rnorm = self._norm(sim, R)
            if not np.isfinite(rnorm):
                raise FloatingPointError(f"step {sim.step_count}, t = {sim.t:.6g}: non-finite "
                                         f"residual in Newton iteration {it}")
            return R, rnorm, fint, reaction, sig

        def newton(du, depth, trust=None):
            """Newton from du (changed in place), halving a correction that raises |R| up to
            `depth` times, from alpha = min(1, trust h / max|delta|) if trust: (du, iterations,
            |R|, |f|, reaction); _NotConverged if it diverges or reaches max_iter."""
            it = 0
            R, rnorm, fint, reaction, sig = newton_residual(du, it)
            r0 = rnorm
            diverged = self.DIVERGED * max(r0, 1e-300)
            dnorm = np.inf
            best = (np.inf, 0)                      # the smallest |R|/|f| so far and its iteration
            for it in range(self.max_iter + 1):
                scale = max(fext_norm, self._norm(sim, np.where(cmask, 0.0, fint)), r0, force_scale,
                            self._norm(sim, reaction) if moving else 0.0, 1e-300)
                if rnorm <= self.rtol * scale or (
                        dnorm <= self.utol * self._norm(sim, du) and rnorm <= np.sqrt(self.rtol) * scale):
                    break
                best = min(best, (rnorm / scale, it))
                # diverged: |R| DIVERGED times its initial value (the internal forces of the
                # diverging iterate then dominate |f|, so |R|/|f| alone would read about 1)
                if it == self.max_iter or rnorm > diverged:
                    why = (f"in {self.max_iter} iterations" if it == self.max_iter else
                           f"(diverged at iteration {it}: |R| = {rnorm / max(r0, 1e-300):.3g}"
                           f" x its initial value)")
                    stalled = it == self.max_iter and best[0] < STALL_FACTOR * self.rtol
                    err = _NotConverged(f"step {sim.step_count}, t = {sim.t:.6g}: Newton did not "
                                        f"converge {why} (|R|/|f| = {rnorm / scale:.3e}; closest "
                                        f"{best[0]:.3e} at iteration {best[1]})"
                                        + (STALL_HINT.format(rtol=self.rtol) if stalled else ""))
                    err.iterations = it
                    raise err
                t2 = time.perf_counter()
                for mat, gidx in sim.material_groups():
                    mat.tangent(gidx, sim._dF, p.F, p.stress, sig, p.state, dsig)
                first_piola_tangent(idx, sim._dF, sim.dynamic_stress(sig), dsig, A4, plane)
                extra = None
                if sim.layers or motion is not None:
                    def extra(data):
                        if sim.layers:
                            kl.layer_tangent(sim.grid.D, sim.layer_particles(), sim.nodes, sim.N,
                                             p.F, p.layer_an0, p.layer_coef, c_v, plan,
                                             sys.nodeptr, constrained, data)
                        if motion is not None:
                            pm.penalty_tangent(motion[0], sim.nodes, sim.N, motion[2], motion[3],
                                               plan, sys.nodeptr, constrained, data)
                self.assemble_tangent(sim, A4, plan, np.repeat(m, d) * m_coef, constrained, extra)
                robin = sim.robin
                if robin is not None:
                    own = np.flatnonzero(constrained[: sys.n_owned_dofs]).astype(np.int32)
                    B = robin.tangent(sim.robin_u + du, velocity(du), c_v, own)
                    if B is not None:
                        sys.add(B)
                if ghost is not None:
                    sys.add(ghost.Gz)
                t3 = time.perf_counter()
                try:
                    delta = sys.solve(R)
                except RuntimeError as err:               # KSP failure: say when and where
                    hint = (SINGULAR_HINT if "PCSETUP" in str(err) and ghost is None else "")
                    raise RuntimeError(f"step {sim.step_count}, t = {sim.t:.6g}, Newton iteration "
                                       f"{it}: {err}{hint}") from err
                t4 = time.perf_counter()
                self.ksp_iterations += sys.iterations
                T["assembly"] += t3 - t2
                T["ksp"] += t4 - t3
                # depth > 0: halve the correction (up to depth times) while it raises |R| or
                # makes it non-finite (module docstring); 0: the full Newton step
                alpha, prev = 1.0, rnorm
                if trust is not None:
                    longest = gmax_of(sim.comm, np.abs(delta[: sim.grid.n_owned_nodes]))
                    alpha = min(1.0, trust * sim.grid.h / max(longest, 1e-300))
                for k in range(depth + 1):
                    try:
                        R, rnorm, fint, reaction, sig = newton_residual(du + alpha * delta, it + 1)
                    except FloatingPointError:
                        if k == depth:
                            raise
                        alpha *= 0.5
                        continue
                    if rnorm <= prev or k == depth:
                        break
                    alpha *= 0.5
                du += alpha * delta
                dnorm = alpha * self._norm(sim, delta)
            return du, it, rnorm, scale, reaction

        depth = 0 if self.line_search == "auto" else self.line_search
        try:
            du, it, rnorm, scale, reaction = newton(du.copy(), depth)
        except (_NotConverged, FloatingPointError) as err:
            if self.line_search != "auto":
                raise
            # line_search="auto": the same step again with backtracking (module docstring)
            self.retries += 1
            first = getattr(err, "iterations", 0)
            if sim.comm.rank == 0:
                log.info("%s; retrying the step with line_search=%d, corrections of at most %g h",
                         err, AUTO_LINE_SEARCH, AUTO_TRUST)
            try:
                du, it, rnorm, scale, reaction = newton(du, AUTO_LINE_SEARCH, AUTO_TRUST)
            except _NotConverged as again:
                raise _NotConverged(f"{again} (full step: {err}; then line_search="
                                    f"{AUTO_LINE_SEARCH}, corrections of at most "
                                    f"{AUTO_TRUST:g} h)") from None
            it += first
        self.iterations.append(it)
        sim.nodal["reaction"] = reaction        # force the fixed dofs exert (summed over ranks)
        if motion is not None:                  # each prescribed particle motion's reaction
            self._motion_reactions(sim, motion[0], f_motion)
        if sim.robin is not None:
            sim.robin_u += du
        sim.stats.update(newton_iterations=it, residual=rnorm / scale, ksp_iterations=sys.iterations)
        return du

    @staticmethod
    def _motion_reactions(sim, sel, f):
        """Store sum_p f_p per prescribed particle motion (summed over ranks)."""
        tag = sim.particles.motion_tag[sel].astype(np.int64) - 1
        n = len(sim.particle_motions)
        r = np.zeros((n, sim.gdim))
        for c in range(sim.gdim):
            r[:, c] = np.bincount(tag, weights=f[:, c], minlength=n)
        if sim.comm.size > 1:
            r = sim.comm.allreduce(r)
        for m in sim.particle_motions:
            m.reaction = r[m.index]


class Newmark(_Newton):
    """Implicit Newmark (default beta = 1/4, gamma = 1/2: trapezoidal, unconditionally stable).
    alpha_m = alpha_f = 0 here; ImplicitGeneralizedAlpha sets them (module docstring).
    Newton's options (rtol, utol, max_iter, line_search="auto": a failed step is solved again
    with backtracking, ghost, petsc_options): the module docstring."""

    alpha_m = alpha_f = 0.0
    records_work = True
    iterative_default = True          # default KSP: GMRES + block Jacobi, LU if it fails
    supports_prescribed_motion = True  # sim.fix(..., displacement=/velocity=): Newmark kinematics

    def __init__(self, beta=0.25, gamma=0.5, **kw):
        super().__init__(**kw)
        for name, val in (("beta", beta), ("gamma", gamma)):
            if isinstance(val, bool) or not isinstance(val, (int, float, np.floating)):
                raise TypeError(f"Newmark: '{name}' must be a number, got {val!r}")
        if not 0.5 <= gamma <= 1:
            raise ValueError(f"Newmark: 'gamma' must be in [1/2, 1] (gamma < 1/2 amplifies every "
                             f"mode: unstable), got {gamma}")
        if not 0 < beta <= 0.5:
            raise ValueError(f"Newmark: 'beta' must be in (0, 1/2], got {beta}")
        self.beta, self.gamma = float(beta), float(gamma)

    def step(self, sim, dt):
        """Advance `sim` by dt with Newton (integrator protocol: called by Simulation.step)."""
        p, grid = sim.particles, sim.grid
        b, g = self.beta, self.gamma
        sim.locate_and_shape()
        t0 = time.perf_counter()
        m, mv = sim.nodal_mass_momentum()
        ma = sim.nodal_weighted(p.a)
        grid.accumulate(m, mv, ma)
        sim.timers["p2g"] += time.perf_counter() - t0
        with sim.timed("solve"):                    # (its restriction counts as "shape")
            active = sim.active_mask(m)
            f_ext = sim.external_force(sim.t + dt, m, active=active)
        v0 = np.zeros_like(mv)
        a0 = np.zeros_like(ma)
        v0[active] = mv[active] / m[active, None]
        a0[active] = ma[active] / m[active, None]
        v0[sim.fixed] = 0.0
        a0[sim.fixed] = 0.0
        # dofs moved by sim.fix(..., displacement=/velocity=): their prescribed start-of-step
        # velocity and acceleration, and the step's increment as their predictor
        moving = None
        if sim.motions:
            moving, vp, ap = prescribed_rates(v0.shape, sim.motions, sim.t, dt)
            moving &= sim.fixed
            v0[moving], a0[moving] = vp[moving], ap[moving]
            dup = sim.prescribed_increment(sim.t, sim.t + dt)
        sim.nodal = dict(mass=m, active=active)
        am, af = self.alpha_m, self.alpha_f
        if af:
            f_ext = f_ext + af / (1.0 - af) * self._start_force(sim, m, active, v0)
        wm = (1.0 - am) / (1.0 - af)

        def accel(du):
            a1 = (du - dt * v0 - dt * dt * (0.5 - b) * a0) / (b * dt * dt)
            a1[~active] = 0.0
            return a1

        def velocity(du):
            return v0 + dt * ((1 - g) * a0 + g * accel(du))

        # predictor: constant acceleration (a^{n+1} = a^n, v^{n+1} = v^n + dt a^n)
        du0 = dt * v0 + 0.5 * dt * dt * a0
        if moving is not None:
            du0[moving] = dup[moving]
        du = self.solve_step(sim, dt, f_ext, wm / (b * dt * dt),
                             lambda du: m[:, None] * (wm * accel(du) + am / (1.0 - af) * a0),
                             velocity, g / (b * dt), v0, du0=du0,
                             force_scale=self._norm(sim, m[:, None] * v0) / dt
                             + self._norm(sim, m[:, None] * a0))
        t0 = time.perf_counter()
        a1 = accel(du)
        held = sim.fixed if moving is None else sim.fixed & ~moving
        a1[held] = 0.0
        v1 = v0 + dt * ((1 - g) * a0 + g * a1)
        v1[~active] = 0.0
        v1[held] = 0.0
        kt.flip_blend(sim.grid.D, sim.nodes, sim.N, a0, a1, self.flip, p.a)
        kt.g2p(sim.grid.D, sim.nodes, sim.N, du, v0, v1, self.flip, p.x, p.v, p.u)
        sim.timers["g2p"] += time.perf_counter() - t0
        sim.commit(sim._dF)
        sim.nodal["velocity"] = v1
        sim.nodal["displacement"] = du          # what the particles moved by (CPDI2 corners)
        if sim.monitoring_work:        # trapezoidal work: (f^n + f^{n+1}) / 2 . du, du = dt (v0 + v1) / 2
            f_mid = 0.5 * (f_ext + sim.external_force(sim.t, m))
            sim.record_work(f_mid, sim.boundary_force(v1), v0, v1, dt)

    def _start_force(self, sim, m, active, v0):
        """f(t^n) = f_ext(t^n) - f_int(sigma^n) + Robin and particle-layer forces of the
        start-of-step state (summed over ranks)."""
        p = sim.particles
        f = np.zeros((sim.grid.n_nodes, sim.gdim))
        sim.internal_force(sim.dynamic_stress(p.stress), f)
        if sim.robin is not None:
            sim.robin.force(sim.robin_u, v0, f)
        if sim.layers:
            sim.layer_force(p.u - p.layer_u0, p.v, f)
        sim.grid.accumulate(f)
        return f + sim.external_force(sim.t, m, active=active)


class QuasiStatic(_Newton):
    """Quasi-static Newton (no inertia). Gravity is ramped linearly over `load_steps` steps and
    then held; tractions follow their own time functions.

    displacement: None, or u(x, t) -> (n, gdim) for displacement control: each step moves the
    fixed dofs (sim.fix) by u(x, t + dt) - u(x, t), x the node coordinates, and starts Newton
    from that increment on the free dofs too (so u should be a plausible field there, e.g. 0);
    the force the fixed dofs exert is sim.nodal["reaction"] after the step. Simpler for one
    boundary: sim.fix(where, components, displacement=u(t) or velocity=v), which moves only
    those dofs (SetupMixin.fix). Newton's options
    (rtol, utol, max_iter, line_search="auto", ghost, petsc_options): as Newmark's."""
    supports_prescribed_motion = True

    def __init__(self, load_steps=1, displacement=None, **kw):
        super().__init__(**kw)
        if not (isinstance(load_steps, int) and load_steps >= 1):
            raise ValueError(f"QuasiStatic: 'load_steps' must be a positive integer, got {load_steps!r}")
        if displacement is not None and not callable(displacement):
            raise TypeError(f"QuasiStatic: 'displacement' must be None or u(x, t), got {displacement!r}")
        self.load_steps = load_steps
        self.displacement = displacement

    def step(self, sim, dt):
        """Advance `sim` by dt with Newton (integrator protocol: called by Simulation.step)."""
        p, grid = sim.particles, sim.grid
        sim.locate_and_shape()
        t0 = time.perf_counter()
        m = sim.nodal_mass()
        grid.accumulate(m)
        sim.timers["p2g"] += time.perf_counter() - t0
        with sim.timed("solve"):
            scale = min(1.0, (sim.step_count + 1) / self.load_steps)
            active = sim.active_mask(m)             # timed as "shape" (gradient restriction)
            f_ext = sim.external_force(sim.t + dt, m, gravity_scale=scale, active=active)
            sim.nodal = dict(mass=m, active=active)
            du0 = sim.prescribed_increment(sim.t, sim.t + dt, self.displacement,
                                           fixed_only=False)
        du = self.solve_step(sim, dt, f_ext, 0.0, lambda du: 0.0, lambda du: du / dt, 1.0 / dt,
                             np.zeros((grid.n_nodes, sim.gdim)), du0=du0)
        t0 = time.perf_counter()
        zero = np.zeros_like(du)
        kt.g2p(sim.grid.D, sim.nodes, sim.N, du, zero, zero, 1.0, p.x, p.v, p.u)
        p.v[:] = 0.0
        sim.timers["g2p"] += time.perf_counter() - t0
        sim.commit(sim._dF)
        sim.nodal["velocity"] = du / dt
        sim.nodal["displacement"] = du
