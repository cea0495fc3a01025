"""Simulation: puts the pipeline stages of one step in order and runs the time loop.

Stages (DESIGN.md): locate -> shape -> P2G -> grid solve (the integrator) -> G2P ->
constitutive update. The integrator decides the order; the stage functions live here. The set-up
API (fix, add_traction, add_boundary, start_stage, probe, ...) is inherited from
setup.SetupMixin, the energy monitor from energy.EnergyMixin; Probe and Output live in io/."""
import contextlib
import logging
import math
import time
import warnings

import numpy as np
from mpi4py import MPI

from .boundaries import TractionForms
from .boundaries import particle_layer as kl
from .checkpoint import CheckpointMixin
from .energy import EnergyMixin
from .errors import raise_together
from .guards import ParticlesLeftMesh, check_particles, check_wave_speed, particles_left
from .io import Progress
from .kernels import axisymmetric as axi
from .kernels import transfer as kt
from .kernels.smoothing import smoothed_stress
from .materials.regularisation import regularise
from .setup import SetupMixin
from .kernels.fbar import fbar
from .kernels.fused import elastic_step
from .materials.linear_elastic import LinearElastic
from .shapes import choose_shape, resolve_shape, standard as ks, wide_shape

_NOT_RIGID = np.zeros(1, dtype=np.bool_)
MANY_STEPS = 1_000_000         # dt="auto" runs longer than this many steps are warned about
STAGES = ("locate", "shape", "p2g", "solve", "g2p", "constitutive", "guards")  # sim.timers
SUBSTAGES = ("assembly", "ksp")      # parts of "solve" (implicit), also in sim.timers
WAVE_CHECK_EVERY = 100         # steps between guards.check_wave_speed checks
DT_BAND = 1.1                  # dt="auto" changes when the state's critical step moves by 10 %


class Simulation(SetupMixin, EnergyMixin, CheckpointMixin):
    """An MPM simulation of `particles` on `grid`, advanced by `integrator`.

    dt: time step (> 0), or "auto" for explicit integrators (cfl * h / max c_p, then
    following the state: follow_state_dt).
    gravity: body acceleration vector (length gdim), default zero.
    mass_tolerance: nodes with mass below this fraction of the largest nodal mass are
    inactive (no velocity, no division by a vanishing mass; constrained in implicit solves).
    Default (None) 1e-12: the quadratic tails of GIMP weights put masses of 1e-10 on nodes that
    carry forces, and 1e-9 lost momentum at that level (tests/test_traction.py); 1e-4 for an
    implicit run of a wide family with a particle layer (add_boundary; LAYER_MASS_TOLERANCE).
    on_leave: what happens to particles that leave the mesh: "error" (stop with their ids and
    positions) or "remove" (drop them; the removed mass is counted in `removed_mass`, and
    reported as a warning) or "periodic" (re-enter through the opposite periodic face, see
    set_periodic; particles leaving elsewhere stop the run as with "error").
    max_dt_cuts: implicit runs only: when Newton or the KSP fails, retry the step as two
    half steps, at most this many halvings deep (one warning a step that needed cuts, with
    the first failure, the number of cuts and the smallest dt; each cut is logged at INFO on
    the "fenicsmpm" logger).
    gravity_ramp: None, or a time T: gravity grows smoothly over the first T/2 of the stage,
    g(t) = g [sin(2 pi t / T - pi / 2) + 1] / 2 (seed 002 eq 4.13), then stays at g.
    stress_feedback: None, or "smoothed": explicit runs compute the internal force from the
    grid-smoothed stress (fenicsmpm.kernels.smoothing, seed 002 eqs 4.18-4.19) instead of the
    particle stress; the constitutive update still acts on the particle stress.
    shape: the shape-function family, one of SHAPES: "auto" (shapes.choose_shape: the most
    accurate family the mesh and options support, cpGIMP on structured grids, CPDI2 on other
    2D meshes, CPDI1 on other 3D meshes, else "mpm"; the choice and its reason are `shape` and `shape_reason`, and are
    logged on rank 0), "mpm" (the Lagrange basis of the
    particle's cell), "ugimp"/"cpgimp" (shapes.gimp: structured quadrilateral/hexahedral
    grids), "cpdi1"/"cpdi2" (shapes.cpdi: any 2D or 3D P1/Q1 mesh), "gauss" (shapes.gauss_gimp:
    deformed-voxel GIMP by 2 x 2 Gauss points pushed forward by F, seed 002 §3.3.1; any 2D
    P1/Q1 mesh), "bspline2" (shapes.bspline: boundary-modified quadratic B-splines on the
    structured grids of GIMP; never picked by "auto"). The wider families need, in parallel, the vertex ghost layer: a mesh
    without it (dolfinx's default partitioner) is rebuilt from the same cells with the same
    owners (Grid.ensure_vertex_ring; grid.mesh is then a new dolfinx mesh); implicit
    integrators then use a wider matrix pattern (integrators.linear_system.stencil_rings).
    force_integration: "particles" (the internal force as a particle sum), or "mixed" (MPM
    with Gauss-point integration of the internal force, fenicsmpm.integrators.mixed_integration).
    fbar: the incremental deformation gradient's volume change is averaged over each cell
    (kernels.fbar, F-bar) against volumetric locking under isochoric plastic flow (the Prandtl
    footing's limit pressure, problems.footing); explicit integrators, and implicit ones on
    plane or 3D grids (F-bar's consistent, unsymmetric tangent, kernels.fbar.fbar_stiffness,
    every shape family); not the DM-GC integrators. "auto" (default): on where a
    deformable particle is VonMises and the integrator supports it, off otherwise (chosen by
    data, setup.SetupMixin._resolve_fbar); the choice and its reason are `fbar` and
    `fbar_reason`.
    Axisymmetric analysis is a property of the grid (fm.Grid(mesh, axisymmetric=True),
    fenicsmpm.kernels.axisymmetric): hoop terms are added to the strain, force and tangent, and the
    radial displacement of nodes on the axis r = 0 is fixed."""

    def __init__(self, grid, particles, integrator, dt, gravity=None, cfl=0.5,
                 mass_tolerance=None, on_leave="error", max_dt_cuts=0, shape="auto", fbar="auto",
                 stress_feedback=None, gravity_ramp=None, force_integration="particles"):
        self.grid = grid
        self.particles = particles
        if not all(hasattr(integrator, a) for a in ("explicit", "setup", "step")):
            raise TypeError(f"Simulation: 'integrator' must be an integrator such as fm.Explicit(), "
                            f"fm.Newmark() or fm.QuasiStatic(), got {integrator!r}")
        self.integrator = integrator
        self.comm = grid.comm
        d = self.gdim = grid.gdim
        if particles.grid is not grid:
            raise ValueError("Simulation: 'particles' were created on a different grid")
        self.gravity = np.zeros(d) if gravity is None else np.asarray(gravity, dtype=np.float64)
        if self.gravity.shape != (d,) or not np.all(np.isfinite(self.gravity)):
            raise ValueError(f"Simulation: 'gravity' must be a finite vector of length {d}, got {gravity!r}")
        if not (0 < cfl <= 1):
            raise ValueError(f"Simulation: 'cfl' must be in (0, 1], got {cfl!r}")
        self.cfl = cfl
        self._wave_materials = self._deformable_materials()
        self.dt = self._check_dt(dt)
        self._mass_tolerance_default = mass_tolerance is None
        mass_tolerance = 1e-12 if mass_tolerance is None else mass_tolerance
        if not (isinstance(mass_tolerance, (int, float, np.floating)) and 0 < mass_tolerance < 1):
            raise ValueError(f"Simulation: 'mass_tolerance' must be a number in (0, 1), got {mass_tolerance!r}")
        self.mass_tolerance = float(mass_tolerance)
        self.t = 0.0
        self.step_count = 0
        self.fixed = np.zeros((grid.n_nodes, d), dtype=bool)
        self.motions = []                            # fix(..., displacement=/velocity=)
        if grid.axisymmetric:                        # symmetry axis: u_r = 0 at r = 0
            self.fixed[:, 0] = np.abs(grid.node_x[:, 0]) <= 1e-9 * grid.h
        self.tractions = []
        self._traction_forms = None
        self._warned_traction = False
        self.particle_loads = []
        self.surface_pressures = []                  # add_surface_pressure
        self.particle_motions = []
        self.frictions = []
        self.splitting = None
        self.boundaries = []
        self._robin = None
        self.layers = []
        self._layer_version = None
        self.robin_u = np.zeros((grid.n_nodes, d))   # displacement seen by Robin boundaries
        self.initial_stress = False                  # internal force from sigma - sigma_ini
        self.stage_start = 0.0
        self.probes = []
        self.observers = []
        self.nodal = {}
        self.stats = {}
        self.timers = dict.fromkeys(STAGES + SUBSTAGES, 0.0)
        self.axisymmetric = grid.axisymmetric
        self._field = np.zeros(0, dtype=np.int32)
        self._check_options(on_leave, max_dt_cuts, shape, stress_feedback, gravity_ramp,
                            force_integration, fbar)
        self.removed_mass = 0.0
        self.removed_count = 0
        self.base_motion = None                      # boundaries.base_motion.RigidBase (relative frame)
        self._work = None                            # local [external, boundary] work (monitor)
        self._n_alloc = -1
        self._scratch = {}                           # per-particle work arrays (_per_particle)
        self._all = np.zeros(0, dtype=np.int64)
        self._inverted = np.zeros(0, dtype=np.int8)  # flagged by commit, reported by the guards
        self.shape_auto = shape == "auto"
        self.shape, self.shape_reason = resolve_shape(self, shape)
        self._resolve_fbar()
        if self.shape != "mpm" and grid.ensure_vertex_ring():   # wide families: vertex ghosts
            self._on_new_mesh()
        try:
            self._wide = wide_shape(self, self.shape)    # GIMP/CPDI evaluator; None for "mpm"
        except (ValueError, NotImplementedError) as e:   # a family the mesh cannot support
            if self.shape_auto:
                raise
            raise type(e)(f"Simulation: shape={self.shape!r} is not available here: {e}; "
                          f"shape='auto' would pick {choose_shape(self)[0]!r}") from e
        integrator.setup(self)

    @property
    def dt_critical(self):
        """Explicit stability limit: stability_factor * h / max c_p (over the materials of the
        deformable particles, _deformable_materials), where an integrator's
        `stability_factor` (default 1, symplectic Euler / central difference) scales the
        central-difference limit, e.g. Omega_s(rho_b) / 2 for explicit generalized-alpha."""
        c = max(m.p_wave_speed for m in self._wave_materials)
        return getattr(self.integrator, "stability_factor", 1.0) * self.grid.h / c

    @property
    def courant(self):
        """Courant number dt max c_p / h of the current step (reported on the progress line of
        implicit runs; explicit runs are limited to their stability factor)."""
        c = max(m.p_wave_speed for m in self._wave_materials)
        return self.dt * c / self.grid.h

    def _check_dt(self, dt):
        if isinstance(dt, str):
            if dt != "auto":
                raise ValueError(f"Simulation: 'dt' must be a positive number or 'auto', got {dt!r}")
            if not self.integrator.explicit:
                raise ValueError("Simulation: dt='auto' is only defined for explicit integrators")
            self._dt_auto = True
            self._dt_base = self.cfl * self.dt_critical      # the bound follow_state_dt keeps
            return self._dt_base
        self._dt_auto = False
        if not isinstance(dt, (int, float, np.floating)) or not math.isfinite(dt) or dt <= 0:
            raise ValueError(f"Simulation: 'dt' must be > 0, got {dt!r}")
        if self.integrator.explicit and dt > self.dt_critical * (1.0 + 1e-12):   # round-off in h
            raise ValueError(f"Simulation: dt = {dt:.4g} exceeds the explicit critical time step "
                             f"{self.dt_critical:.4g} s (h = {self.grid.h:.4g}, stability factor "
                             f"{getattr(self.integrator, 'stability_factor', 1.0):.4g} x h / c_p)")
        return float(dt)

    # ------------------------------------------------------------------ boundary stages
    def layer_particles(self):
        """Indices of the particles in a particle-layer boundary (cached between migrations)."""
        p = self.particles
        if self._layer_version != (p.version, len(p)):
            self._layer = np.flatnonzero(np.any(p.layer_an0 != 0.0, axis=1)).astype(np.int64)
            self._layer_version = (p.version, len(p))
        return self._layer

    def boundary_force(self, v_grid, v_particles=None):
        """Robin (mesh facets) and particle-layer tractions of the start-of-step state with nodal
        velocities v_grid and particle velocities v_particles (default p.v), summed over ranks;
        None when there are no such boundaries."""
        if self.robin is None and not self.layers:
            return None
        p = self.particles
        fr = np.zeros((self.grid.n_nodes, self.gdim))
        if self.robin is not None:
            self.robin.force(self.robin_u, v_grid, fr)
        if self.layers:
            self.layer_force(p.u - p.layer_u0, p.v if v_particles is None else v_particles, fr)
        self.grid.accumulate(fr)
        return fr

    def layer_force(self, u_rel, v, out):
        """out += local particle-layer tractions for particle displacements u_rel (since the
        layer was added) and velocities v."""
        p = self.particles
        kl.layer_force(self.grid.D, self.layer_particles(), self.nodes, self.N, p.F,
                       p.layer_an0, p.layer_coef, u_rel, v, out)


    # ------------------------------------------------------------------ stages
    def locate_and_shape(self):
        """Locate particles (only the ones that left their cell are searched on unstructured
        meshes) and evaluate the shape functions (of the family `shape`) at their positions."""
        p, g = self.particles, self.grid
        t0 = time.perf_counter()
        p.cell, p.xi = g.locate(p.x, p.cell)
        ids, xs = p.send_to_owners()
        if len(ids):
            particles_left(self, ids, xs)
        cells, xi = p.cell, p.xi
        if self.axisymmetric:
            self._r = p.x[:, 0].copy()        # start-of-step radius (the step's reference)
            if len(self._field) != len(p):    # the single nodal field of axi.hoop_*
                self._field = np.zeros(len(p), dtype=np.int32)
        t1 = time.perf_counter()
        n, nv = len(p), g.cell_nodes.shape[1]
        if n != self._n_alloc:
            if self._wide is None:
                self.nodes = np.empty((n, nv), dtype=np.int32)
                self.N = np.empty((n, nv))
                self.dN = np.empty((n, nv, self.gdim))
            self._n_alloc = n
        if self._wide is None:
            ks.mpm_shape(g.D, g.kind, cells, xi, g.cell_nodes, g.node_x, g.simplex_grad,
                         g.affine_Jinv, self.nodes, self.N, self.dN)
        else:
            self.nodes, self.N, self.dN = raise_together(self.comm, self._wide.evaluate, self)
        self.timers["locate"] += t1 - t0
        self.timers["shape"] += time.perf_counter() - t1

    @contextlib.contextmanager
    def timed(self, stage):
        """Time a block as `stage` (one of STAGES), less what the stages timed inside it took
        (those count as themselves, a nested block of the same stage once), so the stages of a
        step add up to its wall time."""
        T = self.timers
        t0, inner = time.perf_counter(), sum(T[k] for k in STAGES)
        try:
            yield
        finally:
            T[stage] += time.perf_counter() - t0 - (sum(T[k] for k in STAGES) - inner)

    def nodal_mass_momentum(self):
        """Local nodal mass and momentum in one particle pass (not yet summed over ranks)."""
        m = np.zeros(self.grid.n_nodes)
        mv = np.zeros((self.grid.n_nodes, self.gdim))
        kt.p2g_mass_momentum(self.grid.D, self.nodes, self.N, self.particles.mass,
                             self.particles.v, m, mv)
        return m, mv

    def nodal_mass(self):
        """Local nodal mass (not yet summed over ranks)."""
        m = np.zeros(self.grid.n_nodes)
        kt.p2g_mass(self.nodes, self.N, self.particles.mass, m)
        return m

    def nodal_weighted(self, q):
        """Local nodal sums sum_p N_ip m_p q_p of a per-particle quantity q (not yet summed over ranks)."""
        out = np.zeros((self.grid.n_nodes, self.gdim))
        kt.p2g_weighted(self.grid.D, self.nodes, self.N, self.particles.mass, q, out)
        return out

    def active_mask(self, m, restrict=True):
        """Active nodes: mass above mass_tolerance times the global largest nodal mass.

        Also restricts the particles' shape gradients to the active nodes (see
        kernels.transfer.restrict_gradients), so all later stages use consistent gradients;
        restrict=False leaves that to the caller's next internal_force(..., active=...),
        which applies it in its own particle pass (before any other use of the gradients)."""
        mmax = m.max() if len(m) else 0.0
        if self.comm.size > 1:
            from mpi4py import MPI
            mmax = self.comm.allreduce(mmax, op=MPI.MAX)
        active = m > self.mass_tolerance * mmax
        if restrict:
            self.restrict_gradients(active)
        return active

    def restrict_gradients(self, active):
        """Restrict the particles' shape gradients to the active nodes
        (kernels.transfer.restrict_gradients; timed as "shape")."""
        t0 = time.perf_counter()
        kt.restrict_gradients(self.grid.D, self.nodes, self.N, self.dN, active[:, None],
                              np.zeros(len(self.nodes), dtype=np.int64))
        self.timers["shape"] += time.perf_counter() - t0

    def external_force(self, t, m, gravity_scale=1.0, active=None):
        """Nodal external force, already summed over ranks: gravity sum_p N_ip m_p g = m_i g
        (m: the summed nodal mass) plus the traction forms at time t. With `active`, warns
        (once) when traction lands on nodes without mass: the mesh facets no longer touch
        the material there and that part of the load is lost."""
        if self.gravity_ramp is not None:
            tau = (t - self.stage_start) / self.gravity_ramp
            if tau < 0.5:
                gravity_scale *= 0.5 * (math.sin(2 * math.pi * tau - 0.5 * math.pi) + 1.0)
        f = m[:, None] * (gravity_scale * self.gravity)
        if self.base_motion is not None:             # relative frame of a rigid base: -m a_g(t)
            f -= m[:, None] * self.base_motion.frame_acceleration(t, self.gdim)
        if self.tractions:
            if self._traction_forms is None:
                self._traction_forms = TractionForms(self.grid, self.tractions)
            ft = np.zeros_like(f)
            self._traction_forms.assemble(t, ft)
            self.grid.accumulate(ft)
            f += ft
            if active is not None and not self._warned_traction:
                lost = float(np.abs(ft[~active]).sum())
                if self.comm.size > 1:
                    lost = self.comm.allreduce(lost)
                if lost > 1e-12 * max(float(np.abs(ft).sum()), 1e-300):
                    self._warned_traction = True
                    if self.comm.rank == 0:
                        warnings.warn(f"step {self.step_count}, t = {self.t:.6g}: part of a traction "
                                      f"acts on grid nodes without material (the material left the "
                                      f"loaded facets); that part of the load is lost",
                                      RuntimeWarning, stacklevel=2)
        if self.particle_loads or self.surface_pressures:
            fl = np.zeros_like(f)
            self._particle_load_force(t, fl)
            self.grid.accumulate(fl)
            f += fl
        return f

    def dynamic_stress(self, stress):
        """stress - sigma_ini in a stage started with initial_stress=True (seed 000 §3.5: the
        internal force comes from sigma_dyn), else stress itself; grid-smoothed with
        stress_feedback="smoothed"."""
        s = stress - self.particles.stress_initial if self.initial_stress else stress
        return smoothed_stress(self, s) if self.stress_feedback == "smoothed" else s

    def smoothed_stress(self):
        """The grid-smoothed particle stress (seed 002 eqs 4.18-4.19) at the current particle
        positions, e.g. for output (Output particle field "stress_smoothed"); collective."""
        self.locate_and_shape()
        return smoothed_stress(self, self.particles.stress)

    def incremental_F(self, w, scale, out):
        """dF_p = I + scale sum_i w_i (x) grad N_ip (kernels.transfer.incremental_F) for every
        particle, into out (n, 3, 3); axisymmetric grids add the hoop stretch."""
        kt.incremental_F(self.grid.D, self.nodes, self.dN, w, scale, out)
        if self.axisymmetric:
            axi.hoop_strain(self.nodes, self.N, self._field, _NOT_RIGID, w[:, None, :], scale, self._r, out)
        if self.fbar:
            self.average_volume_change(out)

    def average_volume_change(self, dF, body=None, n_bodies=1):
        """F-bar (kernels.fbar): dF's volume change averaged over the particles of each cell,
        per body when `body` (the particles' body ids, n_bodies of them) is given."""
        p = self.particles
        group = p.cell if body is None else p.cell.astype(np.int64) * n_bodies + body
        fbar(group, p.V, dF, self.grid.n_cells * n_bodies,
             3 if self.gdim == 3 or self.axisymmetric else 2)

    def internal_force(self, stress, out, volume=None, active=None):
        """out += -sum_p V_p stress_p . grad N_ip (no body force). active: the mask of an
        active_mask(m, restrict=False) call, whose gradient restriction this applies first
        (in the force's particle pass)."""
        p = self.particles
        if self.force_integration == "mixed":
            if active is not None:
                self.restrict_gradients(active)
            from .integrators.mixed_integration import internal_force as mixed_force
            mixed_force(self, stress, out, volume)
            return
        V = p.V if volume is None else volume
        kt.p2g_force(self.grid.D, self.nodes, self.N, self.dN, p.mass, V, stress,
                     np.zeros(self.gdim), out, None if active is None else active[:, None])
        if self.axisymmetric:
            axi.hoop_force(self.nodes, self.N, self._field, V, stress, self._r, out[:, None, :])

    def material_groups(self):
        """(material, particle indices) per material present."""
        p = self.particles
        if len(p.materials) == 1:
            if len(self._all) != len(p):
                self._all = np.arange(len(p), dtype=np.int64)
            return [(p.materials[0], self._all)]
        return [(m, np.flatnonzero(p.material_id == k)) for k, m in enumerate(p.materials)]

    def trial_stress(self, dF):
        """Stress for the incremental deformation dF (not committed), in self._sigma_new.

        History variables: `state` handed to a material holds the committed values on entry and
        the material overwrites them with its trial values (self._state_new), so a Newton
        iteration always starts from the committed state; `commit` accepts them."""
        p = self.particles
        t0 = time.perf_counter()
        state = p.state
        if p.state.shape[1]:
            state = self._state_new
            state[:] = p.state
        for mat, idx in self.material_groups():
            mat.stress(idx, dF, p.F, p.stress, self._sigma_new, state)
        self.timers["constitutive"] += time.perf_counter() - t0
        return self._sigma_new

    def _per_particle(self, name, shape):
        """A float64 work array (n_particles,) + shape, kept between steps, allocated at first
        use (contents undefined)."""
        shape = (len(self.particles),) + tuple(shape)
        a = self._scratch.get(name)
        if a is None or a.shape != shape:
            a = self._scratch[name] = np.empty(shape)
        return a

    @property
    def _dF(self):
        """The step's incremental deformation gradients (n, 3, 3) (the fused elastic pass of
        stress_update needs none)."""
        return self._per_particle("dF", (3, 3))

    @property
    def _state_new(self):
        """The trial history (n, columns of particles.state) of trial_stress."""
        return self._per_particle("state_new", self.particles.state.shape[1:])

    @property
    def _sigma_new(self):
        """The trial stresses (n, 3, 3) of trial_stress."""
        return self._per_particle("sigma_new", (3, 3))

    def _inversion_flags(self):
        """The per-particle flags of inverted increments (set by the commit, read by guards)."""
        if len(self._inverted) != len(self.particles):
            self._inverted = np.zeros(len(self.particles), dtype=np.int8)
        return self._inverted

    def stress_update(self, w, scale):
        """The stress update of an explicit step for the nodal field w (a velocity, scale = dt;
        or a displacement, scale = 1): dF = I + scale sum_i w_i (x) grad N_ip (incremental_F),
        the materials' stress (trial_stress) and commit. For a body of one LinearElastic
        material without F-bar, axisymmetry or splitting the three run as one fused particle
        pass (kernels.fused.elastic_step: the same result to the bit)."""
        p = self.particles
        mat = p.materials[0]
        if (len(p.materials) > 1 or type(mat) is not LinearElastic or self.fbar
                or self.axisymmetric or self.splitting is not None):
            t0 = time.perf_counter()
            self.incremental_F(w, scale, self._dF)
            self.timers["constitutive"] += time.perf_counter() - t0
            self.trial_stress(self._dF)
            self.commit(self._dF)
            return
        t0 = time.perf_counter()
        elastic_step(self.grid.D, self.nodes, self.dN, w, scale, mat.lame_lambda,
                     mat.shear_modulus, p.F, p.V, p.stress, p.work, self._inversion_flags())
        self.timers["constitutive"] += time.perf_counter() - t0

    def commit(self, dF):
        """Accept dF, the trial stress and history: update F, V, stress, state and stress work."""
        p = self.particles
        t0 = time.perf_counter()
        kt.commit_step(dF, p.F, p.V, p.stress, self._sigma_new, p.work, self._inversion_flags())
        if self.splitting is not None:
            self.splitting.push_forward(self, dF)
        if p.state.shape[1]:
            p.state[:] = self._state_new
        self.timers["constitutive"] += time.perf_counter() - t0


    # ------------------------------------------------------------------ time loop
    def _save_last_state(self, output, checkpoint):
        """Write the last accepted state after a failed step (collective: every rank raises)."""
        if output is not None and self.step_count % output.every != 0:
            output.write(self)
        if checkpoint is not None:
            self.checkpoint(checkpoint)

    def _advance(self, dt, cuts_left, cuts):
        """integrator.step over dt; on a Newton/KSP failure of an implicit integrator (raised
        before any state changed) retry as two steps of dt/2, at most `cuts_left` deep, each
        cut appended to `cuts` as (dt/2, error) for step's one warning. The
        nonlocal softening variables are first computed from the committed state
        (materials.regularisation)."""
        regularise(self, dt)
        try:
            self.integrator.step(self, dt)
        except (RuntimeError, FloatingPointError) as err:
            # implicit integrators change particles only after convergence
            err.state_intact = isinstance(err, ParticlesLeftMesh) or not self.integrator.explicit
            if self.integrator.explicit or cuts_left == 0 or isinstance(err, ParticlesLeftMesh):
                raise
            cuts.append((dt / 2, str(err)))
            if self.comm.rank == 0:
                logging.getLogger("fenicsmpm").info("%s; retrying with two steps of dt = %.6g",
                                                    err, dt / 2)
            self._advance(dt / 2, cuts_left - 1, cuts)
            self._advance(dt / 2, cuts_left - 1, cuts)
            return
        if self._wide is not None:
            self._wide.after_step(self, dt)
        self.t += dt

    def _cuts_summary(self, cuts):
        """The one warning of a step that was cut (_advance's `cuts`: (dt, error) per cut): the
        first failure, the number of cuts and the smallest dt tried."""
        small = min(d for d, _ in cuts)
        return (f"{cuts[0][1]}; the step was retried in smaller steps: {len(cuts)} "
                f"cut(s), down to dt = {small:.6g} ({self.dt / small:.0f}x smaller; every "
                f"cut is logged at INFO on the 'fenicsmpm' logger)")

    def follow_state_dt(self):
        """dt="auto" (explicit): the step of the current state, cfl * stability_factor * h /
        c_p with c_p = guards.state_wave_speed (density and stiffness of the deformed
        particles), at most the initial step. Taken when it differs from the step in use by
        more than DT_BAND (10 %), so small-strain runs keep their initial dt. Collective;
        called before every explicit step (issue 21: the critical step follows the state)."""
        from .guards import state_wave_speed
        c = state_wave_speed(self)
        sf = getattr(self.integrator, "stability_factor", 1.0)
        new = min(self.cfl * sf * self.grid.h / c, self._dt_base) if c > 0 else self._dt_base
        if new * DT_BAND < self.dt or (self.dt < self._dt_base and new > DT_BAND * self.dt):
            self.dt = new

    def step(self):
        """Advance one time step (see `max_dt_cuts` for implicit retries; dt="auto" follows the
        state, follow_state_dt)."""
        if self._dt_auto and self.integrator.explicit:
            with self.timed("guards"):                # a check of the state's dt
                self.follow_state_dt()
        cuts = []
        try:
            self._advance(self.dt, self.max_dt_cuts, cuts)
        finally:
            if cuts and self.comm.rank == 0:
                warnings.warn(self._cuts_summary(cuts), stacklevel=2)
        self.step_count += 1
        t0 = time.perf_counter()
        check_particles(self)
        if self.step_count % WAVE_CHECK_EVERY == 0:
            check_wave_speed(self)
        self.timers["guards"] += time.perf_counter() - t0
        if self.splitting is not None:
            self.stats["split"] = self.splitting.apply(self)
        for pr in self.probes:
            pr.record()
        for callback, every in self.observers:
            if self.step_count % every == 0:
                callback(self)

    def _check_run(self, steps):
        """Before a run: warn when dt="auto" gives more than MANY_STEPS steps (naming the
        material that limits dt), warn when a material's state has outgrown the wave speed dt
        came from (guards.check_wave_speed), and refuse an explicit run whose particles would
        cross more than a cell in one step (max |v| dt > h)."""
        mats = self.particles.materials
        if getattr(self, "_dt_auto", False) and steps > MANY_STEPS and self.comm.rank == 0:
            m = max(mats, key=lambda q: q.p_wave_speed)
            warnings.warn(f"run: dt='auto' gives {steps:,} steps of dt = {self.dt:.3g} s; the "
                          f"limit cfl * h / c_p comes from {type(m).__name__} (material "
                          f"{mats.index(m)}, c_p = {m.p_wave_speed:.4g} m/s, h = "
                          f"{self.grid.h:.4g}); check the units, or use an implicit integrator",
                          RuntimeWarning, stacklevel=3)
        if not self.integrator.explicit:
            return
        check_wave_speed(self)
        v = self.particles.v
        vmax = float(np.sqrt(np.max(np.einsum("pi,pi->p", v, v)))) if len(v) else 0.0
        if self.comm.size > 1:
            vmax = self.comm.allreduce(vmax, op=MPI.MAX)
        if vmax * self.dt > self.grid.h:
            what = "initial particle velocity" if self.step_count == 0 else "particle velocity"
            raise ValueError(f"run: the {what} |v| = {vmax:.4g} m/s exceeds the explicit "
                             f"stability limit h / dt = {self.grid.h / self.dt:.4g} m/s "
                             f"(h = {self.grid.h:.4g}, dt = {self.dt:.4g}): a particle would "
                             f"cross more than a cell per step; reduce dt or the velocity")

    def run(self, t_end=None, steps=None, output=None, progress=None, checkpoint=None,
            checkpoint_every=None):
        """Run until t_end or for a number of steps; write `output` (an Output) as configured.

        progress: None (a line on a TTY for runs longer than a few seconds), True or False.
        checkpoint, checkpoint_every: write a checkpoint to directory `checkpoint` every that
        many steps (and at the end of the run).
        When a step fails before changing the state (a Newton/KSP failure after the allowed
        dt cuts, particles leaving the mesh), the last accepted state is written to `output`
        and `checkpoint` before the error propagates."""
        if (t_end is None) == (steps is None):
            raise ValueError("run: give exactly one of 't_end' or 'steps'")
        if steps is None:
            if isinstance(t_end, bool) or not (isinstance(t_end, (int, float, np.floating))
                                               and math.isfinite(t_end) and t_end > self.t):
                raise ValueError(f"run: 't_end' is the end time, not a duration: it must be > the "
                                 f"current time t = {self.t:.6g} s (time runs on across "
                                 f"stages), got {t_end!r}; for a duration T pass "
                                 f"t_end=sim.t + T")
            steps = int(math.ceil((t_end - self.t) / self.dt - 1e-9))
        elif isinstance(steps, bool) or not (isinstance(steps, (int, np.integer)) and steps >= 0):
            raise ValueError(f"run: 'steps' must be a non-negative integer, got {steps!r}")
        if (checkpoint is None) != (checkpoint_every is None):
            raise ValueError("run: give both 'checkpoint' (a directory) and 'checkpoint_every'")
        if checkpoint_every is not None and not (
                isinstance(checkpoint_every, (int, np.integer)) and checkpoint_every >= 1):
            raise ValueError(f"run: 'checkpoint_every' must be a positive integer, got {checkpoint_every!r}")
        # with t_end, a dt that follows the state (dt="auto", explicit) may change during the
        # run: step until t_end instead of a fixed count (the same count while dt stays)
        follow = t_end is not None and self._dt_auto and self.integrator.explicit
        self._check_run(steps)
        t_final = t_end if follow else self.t + steps * self.dt
        self.stats["courant"] = self.courant
        note = "" if self.integrator.explicit else f"Courant {self.courant:.3g}"
        bar = Progress(steps, t_final, self.comm, force=progress, note=note)
        if output is not None:
            output.open(self)
            if self.step_count == 0:
                output.write(self)
        def done(k):          # t_end reached (dt follows the state), or the step count
            return self.t >= t_end - 1e-9 * self.dt if follow else k >= steps

        try:
            k = 0
            while not done(k):
                try:
                    self.step()
                except (RuntimeError, FloatingPointError) as err:
                    if getattr(err, "state_intact", False):
                        self._save_last_state(output, checkpoint)
                    raise
                k += 1
                last = done(k)
                if follow:    # dt follows the state: the count so far plus the time left / dt
                    bar.total_steps = k + max(int(np.ceil((t_end - self.t) / self.dt - 1e-6)), 0)
                bar.update(k, self.t)
                if output is not None and self.step_count % output.every == 0:
                    output.write(self)
                if checkpoint is not None and (self.step_count % checkpoint_every == 0 or last):
                    self.checkpoint(checkpoint)
        finally:
            bar.close()
            if output is not None:
                output.close()
        return self
