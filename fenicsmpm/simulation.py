"""Simulation: puts the pipeline stages of one step in order and runs the time loop.

Stages (DESIGN.md): locate -> shape -> P2G -> grid solve (the integrator) -> G2P ->
constitutive update. The integrator decides the order; the stage functions live here."""
import math
import time
import warnings

import numpy as np

from .kernels import axisymmetric as axi
from .boundaries import ParticleLayer, Robin, RobinForms, Traction, TractionForms, fixed_dofs
from .boundaries import particle_layer as kl
from .boundaries.friction import FrictionalBoundary
from .boundaries.robin import facets_on_boundary
from .guards import ParticlesLeftMesh, check_particles
from .kernels.smoothing import smoothed_stress
from .splitting import Splitting
from .io import ParticleWriter, Progress, ProbeWriter
from .shapes import standard as ks
from .kernels import transfer as kt

FORCE_INTEGRATIONS = ("particles", "mixed")
_NOT_RIGID = np.zeros(1, dtype=np.bool_)
LEAVE_POLICIES = ("error", "remove", "periodic")
SHAPES = ("mpm", "ugimp", "cpgimp", "cpdi1", "cpdi2", "gauss")
PROBE_FIELDS = {"velocity": "v", "displacement": "u", "position": "x", "stress": "stress",
                "acceleration": "a"}


def _check_ramp(T, owner):
    if T is None:
        return None
    if not (isinstance(T, (int, float, np.floating)) and math.isfinite(T) and T > 0):
        raise ValueError(f"{owner}: 'gravity_ramp' must be a time > 0 or None, got {T!r}")
    return float(T)


class Simulation:
    """An MPM simulation of `particles` on `grid`, advanced by `integrator`.

    dt: time step (> 0), or "auto" for explicit integrators (cfl * h / max c_p).
    gravity: body acceleration vector (length gdim), default zero.
    mass_tolerance: nodes with mass below this fraction of the largest nodal mass are
    inactive (no velocity, no division by a vanishing mass; constrained in implicit solves).
    on_leave: what happens to particles that leave the mesh: "error" (stop with their ids and
    positions) or "remove" (drop them; the removed mass is counted in `removed_mass`, and
    reported as a warning) or "periodic" (re-enter through the opposite periodic face, see
    set_periodic; particles leaving elsewhere stop the run as with "error").
    max_dt_cuts: implicit runs only: when Newton or the KSP fails, retry the step as two
    half steps, at most this many halvings deep (each retry is logged as a warning).
    gravity_ramp: None, or a time T: gravity grows smoothly over the first T/2 of the stage,
    g(t) = g [sin(2 pi t / T - pi / 2) + 1] / 2 (seed 002 eq 4.13), then stays at g.
    stress_feedback: None, or "smoothed": explicit runs compute the internal force from the
    grid-smoothed stress (fenicsmpm.kernels.smoothing, seed 002 eqs 4.18-4.19) instead of the
    particle stress; the constitutive update still acts on the particle stress.
    shape: the shape-function family, one of SHAPES: "mpm" (the Lagrange basis of the
    particle's cell), "ugimp"/"cpgimp" (shapes.gimp: structured quadrilateral/hexahedral
    grids), "cpdi1"/"cpdi2" (shapes.cpdi: any 2D P1/Q1 mesh), "gauss" (shapes.gauss_gimp:
    deformed-voxel GIMP by 2 x 2 Gauss points pushed forward by F, seed 002 §3.3.1; any 2D
    P1/Q1 mesh). The wider families need, in
    parallel, a mesh created with partitioner=grid.vertex_ghost_partitioner(); implicit
    integrators then use a wider matrix pattern (integrators.linear_system.stencil_rings).
    force_integration: "particles" (the internal force as a particle sum), or "mixed" (MPM
    with Gauss-point integration of the internal force, fenicsmpm.integrators.mixed_integration).
    Axisymmetric analysis is a property of the grid (fm.Grid(mesh, axisymmetric=True),
    fenicsmpm.kernels.axisymmetric): hoop terms are added to the strain, force and tangent, and the
    radial displacement of nodes on the axis r = 0 is fixed."""

    def __init__(self, grid, particles, integrator, dt, gravity=None, cfl=0.5,
                 mass_tolerance=1e-9, on_leave="error", max_dt_cuts=0, shape="mpm",
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
        self.dt = self._check_dt(dt)
        if not (isinstance(mass_tolerance, (int, float, np.floating)) and 0 < mass_tolerance < 1):
            raise ValueError(f"Simulation: 'mass_tolerance' must be a number in (0, 1), got {mass_tolerance!r}")
        self.mass_tolerance = float(mass_tolerance)
        self.t = 0.0
        self.step_count = 0
        self.fixed = np.zeros((grid.n_nodes, d), dtype=bool)
        if grid.axisymmetric:                        # symmetry axis: u_r = 0 at r = 0
            self.fixed[:, 0] = np.abs(grid.node_x[:, 0]) <= 1e-9 * grid.h
        self.tractions = []
        self._traction_forms = None
        self._warned_traction = False
        self.particle_loads = []
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
        self.timers = dict(locate=0.0, shape=0.0, p2g=0.0, solve=0.0, g2p=0.0, constitutive=0.0,
                           guards=0.0, assembly=0.0, ksp=0.0)
        if on_leave not in LEAVE_POLICIES:
            raise ValueError(f"Simulation: 'on_leave' must be one of {LEAVE_POLICIES}, got {on_leave!r}")
        if not (isinstance(max_dt_cuts, (int, np.integer)) and 0 <= max_dt_cuts <= 20):
            raise ValueError(f"Simulation: 'max_dt_cuts' must be an integer in [0, 20], got {max_dt_cuts!r}")
        self.on_leave, self.max_dt_cuts = on_leave, int(max_dt_cuts)
        if stress_feedback not in (None, "smoothed"):
            raise ValueError(f"Simulation: 'stress_feedback' must be None or 'smoothed', got {stress_feedback!r}")
        if stress_feedback is not None and not integrator.explicit:
            raise NotImplementedError("Simulation: stress_feedback='smoothed' needs an explicit integrator")
        self.stress_feedback = stress_feedback
        self.gravity_ramp = _check_ramp(gravity_ramp, "Simulation")
        if force_integration not in FORCE_INTEGRATIONS:
            raise ValueError(f"Simulation: 'force_integration' must be one of {FORCE_INTEGRATIONS}, "
                             f"got {force_integration!r}")
        if force_integration == "mixed" and shape != "mpm":
            raise NotImplementedError(f"Simulation: force_integration='mixed' needs shape='mpm', got {shape!r}")
        self.force_integration = force_integration
        self.axisymmetric = grid.axisymmetric
        self._field = np.zeros(0, dtype=np.int32)
        if self.axisymmetric and (shape not in ("mpm", "ugimp", "cpgimp") or force_integration != "particles"):
            raise NotImplementedError(f"Simulation: axisymmetric grids support shape 'mpm', 'ugimp' "
                                      f"and 'cpgimp' with particle integration, got shape={shape!r}, "
                                      f"force_integration={force_integration!r}")
        self.removed_mass = 0.0
        self.removed_count = 0
        self.base_motion = None                      # boundaries.base_motion.RigidBase (relative frame)
        self._work = None                            # local [external, boundary] work (monitor)
        self._n_alloc = -1
        self._all = np.zeros(0, dtype=np.int64)
        self._inverted = np.zeros(0, dtype=np.int8)  # flagged by commit, reported by the guards
        if shape not in SHAPES:
            raise ValueError(f"Simulation: 'shape' must be one of {SHAPES}, got {shape!r}")
        self.shape = shape
        self._wide = None                            # GIMP/CPDI evaluator; None for "mpm"
        if shape in ("ugimp", "cpgimp"):
            from .shapes.gimp import GimpShape
            self._wide = GimpShape(self, contiguous=shape == "cpgimp")
        elif shape in ("cpdi1", "cpdi2"):
            from .shapes.cpdi import CpdiShape
            self._wide = CpdiShape(self, version=int(shape[-1]))
        elif shape == "gauss":
            from .shapes.gauss_gimp import GaussGimpShape
            self._wide = GaussGimpShape(self)
        integrator.setup(self)

    @property
    def dt_critical(self):
        """Explicit stability limit: stability_factor * h / max c_p, where an integrator's
        `stability_factor` (default 1, symplectic Euler / central difference) scales the
        central-difference limit, e.g. Omega_s(rho_b) / 2 for explicit generalized-alpha."""
        c = max(m.p_wave_speed for m in self.particles.materials)
        return getattr(self.integrator, "stability_factor", 1.0) * self.grid.h / c

    @property
    def courant(self):
        """Courant number dt max c_p / h of the current step (reported on the progress line of
        implicit runs; explicit runs are limited to their stability factor)."""
        c = max(m.p_wave_speed for m in self.particles.materials)
        return self.dt * c / self.grid.h

    def _check_dt(self, dt):
        if isinstance(dt, str):
            if dt != "auto":
                raise ValueError(f"Simulation: 'dt' must be a positive number or 'auto', got {dt!r}")
            if not self.integrator.explicit:
                raise ValueError("Simulation: dt='auto' is only defined for explicit integrators")
            return self.cfl * self.dt_critical
        if not isinstance(dt, (int, float, np.floating)) or not math.isfinite(dt) or dt <= 0:
            raise ValueError(f"Simulation: 'dt' must be > 0, got {dt!r}")
        if self.integrator.explicit and dt > self.dt_critical * (1.0 + 1e-12):   # round-off in h
            raise ValueError(f"Simulation: dt = {dt:.4g} exceeds the explicit critical time step "
                             f"{self.dt_critical:.4g} s (h = {self.grid.h:.4g}, stability factor "
                             f"{getattr(self.integrator, 'stability_factor', 1.0):.4g} x h / c_p)")
        return float(dt)

    # ------------------------------------------------------------------ set-up API
    def fix(self, where, components=None):
        """Fix the given displacement components (default: all) at nodes where(x) is True.

        A roller is one component, e.g. fix(lambda x: np.isclose(x[:, 1], 0), [1])."""
        self.fixed |= fixed_dofs(self.grid, where, components)

    def add_particle_load(self, region, value):
        """A force value(t) (a vector; per unit thickness in 2D) shared equally by the particles
        selected by region(x) now, mapped to the grid with their shape functions,
        f_i += sum_p N_ip value(t) / n. Unlike a facet traction it follows the material (the
        thesis's point load "applied to the top material points"). Returns the global number
        of loaded particles."""
        if not (callable(region) and (callable(value) or np.ndim(value) == 1)):
            raise TypeError("add_particle_load: need region(x) -> bool and a vector or t -> vector")
        p = self.particles
        sel = np.asarray(region(p.x), dtype=bool)
        n = int(np.count_nonzero(sel))
        n = self.comm.allreduce(n) if self.comm.size > 1 else n
        if n == 0:
            raise ValueError("add_particle_load: 'region' selects no particle")
        name = f"load_share_{len(self.particle_loads)}"
        p.add_field(name)[sel] = 1.0 / n
        self.particle_loads.append((name, Traction(lambda x: True, value)))
        return n

    def _particle_load_force(self, t, out):
        p = self.particles
        for name, load in self.particle_loads:
            share = getattr(p, name)
            sel = np.flatnonzero(share)
            if len(sel):
                vec = np.ascontiguousarray(np.broadcast_to(load.at(t, self.gdim), (len(sel), self.gdim)))
                kt.p2g_weighted(self.grid.D, self.nodes[sel], self.N[sel], share[sel], vec, out)

    def release(self, where=None, components=None):
        """Remove Dirichlet conditions at nodes where(x) (default: everywhere) on the given
        components (default: all), e.g. to replace a fixed base by an absorbing one."""
        mask = (np.ones((self.grid.n_nodes, self.gdim), dtype=bool) if where is None
                else fixed_dofs(self.grid, where, components))
        self.fixed &= ~mask

    def start_stage(self, integrator=None, dt=None, gravity=None, initial_stress=True,
                    reset_displacement=True, gravity_ramp=None):
        """Begin a new stage on this simulation (seed 000 §3.5), e.g. after a static gravity
        stage: `sim.start_stage(fm.Newmark(), dt=5e-3, gravity=(0, 0))` then swap boundaries
        with `release` and `add_boundary`.

        initial_stress: keep the current stress as sigma_ini; from now on the internal force
          comes from sigma_dyn = sigma - sigma_ini while materials see the total stress, so
          removing gravity together with sigma_ini leaves the body in equilibrium.
        reset_displacement: measure particle displacements (and Robin spring displacements)
          from the start of the stage.
        gravity_ramp: ramp time T of this stage's gravity (see Simulation), None: no ramp."""
        p = self.particles
        if integrator is not None:
            if self.frictions and not getattr(integrator, "supports_friction", False):
                raise NotImplementedError("start_stage: frictional boundaries need fm.Explicit, "
                                          f"not {type(integrator).__name__}")
            self.integrator = integrator
            integrator.setup(self)
            self._robin = None                    # recompile for the new integrator
        if dt is not None or integrator is not None:
            self.dt = self._check_dt(self.dt if dt is None else dt)
        if gravity is not None:
            g = np.asarray(gravity, dtype=np.float64)
            if g.shape != (self.gdim,) or not np.all(np.isfinite(g)):
                raise ValueError(f"start_stage: 'gravity' must be a finite vector of length "
                                 f"{self.gdim}, got {gravity!r}")
            self.gravity = g
        self.gravity_ramp = _check_ramp(gravity_ramp, "start_stage")
        self.initial_stress = bool(initial_stress)
        if initial_stress:
            p.add_field("stress_initial", (3, 3))[:] = p.stress
        if reset_displacement:
            p.u[:] = 0.0
            self.robin_u[:] = 0.0
            if hasattr(p, "layer_u0"):
                p.layer_u0[:] = 0.0
        p.a[:] = 0.0
        self.stage_start = self.t

    def set_periodic(self, axis=0):
        """Periodic sides normal to `axis` (boundaries.periodic): the node pairs at equal
        position on the two faces are tied (masses, momenta, forces summed; one solution, in
        explicit and implicit runs). With on_leave="periodic" a particle leaving through one
        face re-enters through the other. shape="mpm" only. Returns the PeriodicTie."""
        from .boundaries.periodic import PeriodicTie
        if self.shape != "mpm":
            raise NotImplementedError(f"set_periodic: shape={self.shape!r}; periodic sides "
                                      f"support shape='mpm' only")
        self.grid.periodic = PeriodicTie(self.grid, axis)
        return self.grid.periodic

    def add_friction(self, where, mu, normal):
        """A rigid, flat frictional boundary on the grid nodes where(x) with outward unit normal
        `normal` and Coulomb coefficient `mu` (boundaries.friction; seed 002 §5.1): no
        penetration, separation allowed, stick or slip. Explicit integrators only; do not also
        `fix` the normal component there."""
        if not getattr(self.integrator, "supports_friction", False):
            raise NotImplementedError(f"add_friction: frictional boundaries need fm.Explicit, "
                                      f"not {type(self.integrator).__name__}")
        self.frictions.append(FrictionalBoundary(where, mu, normal).bind(self.grid))

    def enable_splitting(self, alpha=2.0, beta=0.5, gamma=1.0, every=1):
        """Split particles whose voxel stretched beyond alpha, shrank below beta or sheared
        beyond gamma since their creation (seed 002 §3.4.1 eq 3.25; fenicsmpm.splitting).
        The number split so far is `splitting.count`; the last step's is stats["split"]."""
        if self.layers:
            raise ValueError("enable_splitting: particle-layer boundaries cannot be split")
        self.splitting = Splitting(self, alpha, beta, gamma, every)
        return self.splitting

    def add_traction(self, where, value):
        """Traction (force per area) on boundary facets where(x); value: vector or t -> vector."""
        self.tractions.append(Traction(where, value))
        self._traction_forms = None

    def add_boundary(self, boundary):
        """Add a Robin boundary: fm.Viscous, fm.Viscoelastic or a user fm.Robin law on mesh
        facets, or an fm.ParticleLayer (the law on a layer of particles). Its displacement u
        is measured from the time it is added. Mesh forms are compiled once, at the next step."""
        if isinstance(boundary, ParticleLayer):
            if self.axisymmetric:
                raise NotImplementedError("add_boundary: particle-layer boundaries are not "
                                          "implemented on axisymmetric grids; use a mesh boundary")
            boundary.attach(self.particles)
            self.layers.append(boundary)
            self._layer_version = None
            return
        if not isinstance(boundary, Robin):
            raise TypeError(f"add_boundary: expected fm.Robin, fm.Viscous or fm.Viscoelastic, "
                            f"got {type(boundary).__name__}")
        facets_on_boundary(self.grid, boundary.where, type(boundary).__name__)
        boundary.bind(self.particles.materials)       # checks material constants now
        self.boundaries.append(boundary)
        self._robin = None

    @property
    def robin(self):
        """The compiled Robin forms (built on first use), or None without Robin boundaries."""
        if self._robin is None and self.boundaries:
            self._robin = RobinForms(self.grid, self.boundaries, self.particles.materials,
                                     implicit=not self.integrator.explicit)
        return self._robin

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

    def observe(self, callback, every=1):
        """Call callback(sim) after every `every` steps (energy monitors, custom output)."""
        if not callable(callback):
            raise TypeError(f"observe: 'callback' must be callable, got {type(callback).__name__}")
        if not (isinstance(every, (int, np.integer)) and every >= 1):
            raise ValueError(f"observe: 'every' must be a positive integer, got {every!r}")
        self.observers.append((callback, int(every)))

    def probe(self, point, fields=("velocity",), path=None, every=1):
        """Record fields of the particle nearest to `point` (by its initial position)."""
        pr = Probe(self, point, fields, path, every)
        self.probes.append(pr)
        return pr

    # ------------------------------------------------------------------ stages
    def _particles_left(self, ids, xs):
        """Apply the `on_leave` policy to particles in no cell of the mesh (cell == -1; `ids`
        and `xs` list them globally, the same on every rank)."""
        if self.on_leave == "periodic":             # re-enter through the opposite face
            from .boundaries.periodic import wrap
            if self.grid.periodic is None:
                raise ValueError("Simulation: on_leave='periodic' needs periodic sides "
                                 "(sim.set_periodic(axis))")
            wrap(self, self.grid.periodic)
            ids, xs = self.particles.send_to_owners()
            if len(ids) == 0:
                return
        where = (f"step {self.step_count}, t = {self.t:.6g}: {len(ids)} particle(s) left the mesh, "
                 f"ids {ids[:5].tolist()} at {np.round(xs[:5], 6).tolist()}")
        if self.on_leave == "periodic":
            raise ParticlesLeftMesh(where)
        if self.on_leave == "error":
            raise ParticlesLeftMesh(where)
        p = self.particles
        gone = p.cell < 0
        mass = p.mass[gone].sum()
        if self.comm.size > 1:
            mass = self.comm.allreduce(mass)
        keep = np.flatnonzero(~gone)
        for name in p.field_names():
            setattr(p, name, np.ascontiguousarray(getattr(p, name)[keep]))
        p.version += 1
        self.removed_mass += mass
        self.removed_count += len(ids)
        if self.comm.rank == 0:
            warnings.warn(f"{where}: removed (mass {mass:.6g}; {self.removed_count} particles, "
                          f"mass {self.removed_mass:.6g} removed so far)", stacklevel=3)

    def locate_and_shape(self):
        """Locate particles (only the ones that left their cell are searched on unstructured
        meshes) and evaluate the shape functions (of the family `shape`) at their positions."""
        p, g = self.particles, self.grid
        t0 = time.perf_counter()
        if self._wide is not None:
            self._wide.before_locate(self)
        p.cell, p.xi = g.locate(p.x, p.cell)
        ids, xs = p.send_to_owners()
        if len(ids):
            self._particles_left(ids, xs)
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
            self._dF = np.empty((n, 3, 3))
            self._sigma_new = np.empty((n, 3, 3))
            self._state_new = np.empty_like(p.state)
            self._n_alloc = n
        if self._wide is None:
            ks.mpm_shape(g.D, g.kind, cells, xi, g.cell_nodes, g.node_x, g.simplex_grad,
                         g.affine_Jinv, self.nodes, self.N, self.dN)
        else:
            self.nodes, self.N, self.dN = self._wide.evaluate(self)
        self.timers["locate"] += t1 - t0
        self.timers["shape"] += time.perf_counter() - t1

    def nodal_mass_momentum(self):
        """Local nodal mass and momentum in one particle pass (not yet summed over ranks)."""
        m = np.zeros(self.grid.n_nodes)
        mv = np.zeros((self.grid.n_nodes, self.gdim))
        kt.p2g_mass_momentum(self.grid.D, self.nodes, self.N, self.particles.mass,
                             self.particles.v, m, mv)
        return m, mv

    def nodal_mass(self):
        m = np.zeros(self.grid.n_nodes)
        kt.p2g_mass(self.nodes, self.N, self.particles.mass, m)
        return m

    def nodal_weighted(self, q):
        out = np.zeros((self.grid.n_nodes, self.gdim))
        kt.p2g_weighted(self.grid.D, self.nodes, self.N, self.particles.mass, q, out)
        return out

    def active_mask(self, m):
        """Active nodes: mass above mass_tolerance times the global largest nodal mass.

        Also restricts the particles' shape gradients to the active nodes (see
        kernels.transfer.restrict_gradients), so all later stages use consistent gradients."""
        mmax = m.max() if len(m) else 0.0
        if self.comm.size > 1:
            from mpi4py import MPI
            mmax = self.comm.allreduce(mmax, op=MPI.MAX)
        active = m > self.mass_tolerance * mmax
        t0 = time.perf_counter()
        kt.restrict_gradients(self.grid.D, self.nodes, self.N, self.dN, active[:, None],
                              np.zeros(len(self.nodes), dtype=np.int64))
        self.timers["shape"] += time.perf_counter() - t0
        return active

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
        if self.particle_loads:
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

    def internal_force(self, stress, out, volume=None):
        """out += -sum_p V_p stress_p . grad N_ip (no body force)."""
        p = self.particles
        if self.force_integration == "mixed":
            from .integrators.mixed_integration import internal_force as mixed_force
            mixed_force(self, stress, out, volume)
            return
        V = p.V if volume is None else volume
        kt.p2g_force(self.grid.D, self.nodes, self.N, self.dN, p.mass, V, stress, np.zeros(self.gdim), out)
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
            if self._state_new.shape != p.state.shape:
                self._state_new = np.empty_like(p.state)
            state = self._state_new
            state[:] = p.state
        for mat, idx in self.material_groups():
            mat.stress(idx, dF, p.F, p.stress, self._sigma_new, state)
        self.timers["constitutive"] += time.perf_counter() - t0
        return self._sigma_new

    def commit(self, dF):
        """Accept dF, the trial stress and history: update F, V, stress, state and stress work."""
        p = self.particles
        t0 = time.perf_counter()
        if len(self._inverted) != len(p):
            self._inverted = np.zeros(len(p), dtype=np.int8)
        kt.commit_step(dF, p.F, p.V, p.stress, self._sigma_new, p.work, self._inverted)
        if self.splitting is not None:
            self.splitting.push_forward(self, dF)
        if p.state.shape[1]:
            p.state[:] = self._state_new
        self.timers["constitutive"] += time.perf_counter() - t0

    def energy(self):
        """Global kinetic and strain energy, and with `monitor_energy` the work done by the
        external loads (gravity, tractions, particle loads) and by Robin/absorbing boundaries
        (negative: energy they took out) since monitoring started (collective)."""
        p = self.particles
        e = dict(kinetic=p.kinetic_energy(), strain=p.strain_energy())
        if self._work is not None:
            w = self.comm.allreduce(self._work) if self.comm.size > 1 else self._work
            e.update(external_work=float(w[0]), boundary_work=float(w[1]))
        return e

    @property
    def monitoring_work(self):
        """Whether `monitor_energy` asked the integrator to record the work of the forces."""
        return self._work is not None

    def record_work(self, f_ext, f_boundary, v_start, v_end, dt):
        """Integrators call this once per step when the energy is monitored: the work of the
        nodal external and boundary forces over the step, dt f . (v_start + v_end) / 2, summed
        over owned nodes (kept per rank; `energy` reduces it)."""
        if self._work is None:
            return
        n = self.grid.n_owned_nodes
        vm = 0.5 * (v_start[:n] + v_end[:n])
        self._work[0] += dt * float(np.einsum("ij,ij->", f_ext[:n], vm))
        if f_boundary is not None:
            self._work[1] += dt * float(np.einsum("ij,ij->", f_boundary[:n], vm))

    def monitor_energy(self, every=10, tolerance=0.02, path=None):
        """Track the energy balance E_kin + E_strain - W_ext - W_boundary = E_0 every `every`
        steps (history in `energy_history`, CSV at `path`) and warn, once, when its error
        exceeds `tolerance` times the largest energy seen. fm.Explicit and fm.Newmark record
        the external and boundary work; other integrators raise a ValueError here."""
        if not getattr(self.integrator, "records_work", False):
            raise ValueError(f"monitor_energy: {type(self.integrator).__name__} does not record "
                             f"the work of external and boundary forces")
        if not (isinstance(every, (int, np.integer)) and every >= 1):
            raise ValueError(f"monitor_energy: 'every' must be a positive integer, got {every!r}")
        if not (tolerance > 0):
            raise ValueError(f"monitor_energy: 'tolerance' must be > 0, got {tolerance!r}")
        self._work = np.zeros(2)
        self.energy_history = []
        writer = None
        if path is not None:
            writer = ProbeWriter(path, ["t", "kinetic", "strain", "external_work",
                                        "boundary_work", "balance_error"], self.comm)
        state = dict(e0=None, scale=0.0, warned=False)

        def check(sim):
            e = sim.energy()
            total = e["kinetic"] + e["strain"]
            if state["e0"] is None:
                state["e0"] = total - e["external_work"] - e["boundary_work"]
            state["scale"] = max(state["scale"], total, abs(e["external_work"]),
                                 abs(e["boundary_work"]), 1e-300)
            err = (total - e["external_work"] - e["boundary_work"] - state["e0"]) / state["scale"]
            e.update(t=sim.t, balance_error=err)
            sim.energy_history.append(e)
            if writer is not None and sim.comm.rank == 0:
                writer.write_row(e)
            if abs(err) > tolerance and not state["warned"]:
                state["warned"] = True
                if sim.comm.rank == 0:
                    warnings.warn(f"step {sim.step_count}, t = {sim.t:.6g}: energy balance error "
                                  f"{err:.3%} of the largest energy exceeds {tolerance:.3%}",
                                  RuntimeWarning, stacklevel=2)

        check(self)
        self.observe(check, every)
        return self.energy_history

    # ------------------------------------------------------------------ time loop
    def _save_last_state(self, output, checkpoint):
        """Write the last accepted state after a failed step (collective: every rank raises)."""
        if output is not None and self.step_count % output.every != 0:
            output.write(self)
        if checkpoint is not None:
            self.checkpoint(checkpoint)

    def _advance(self, dt, cuts_left):
        """integrator.step over dt; on a Newton/KSP failure of an implicit integrator (raised
        before any state changed) retry as two steps of dt/2, at most `cuts_left` deep."""
        try:
            self.integrator.step(self, dt)
        except (RuntimeError, FloatingPointError) as err:
            # implicit integrators change particles only after convergence
            err.state_intact = isinstance(err, ParticlesLeftMesh) or not self.integrator.explicit
            if self.integrator.explicit or cuts_left == 0 or isinstance(err, ParticlesLeftMesh):
                raise
            if self.comm.rank == 0:
                warnings.warn(f"{err}; retrying with two steps of dt = {dt / 2:.6g}", stacklevel=3)
            self._advance(dt / 2, cuts_left - 1)
            self._advance(dt / 2, cuts_left - 1)
            return
        self.t += dt

    def step(self):
        """Advance one time step (see `max_dt_cuts` for implicit retries)."""
        self._advance(self.dt, self.max_dt_cuts)
        self.step_count += 1
        t0 = time.perf_counter()
        check_particles(self)
        self.timers["guards"] += time.perf_counter() - t0
        if self.splitting is not None:
            self.stats["split"] = self.splitting.apply(self)
        for pr in self.probes:
            pr.record()
        for callback, every in self.observers:
            if self.step_count % every == 0:
                callback(self)

    def checkpoint(self, path, keep=1):
        """Save the complete state under directory `path` (collective; see fenicsmpm.checkpoint):
        particles with history variables, integrator and boundary state, stage, time, step and
        probe records. Written atomically; the `keep` newest checkpoints are kept."""
        from . import checkpoint
        return checkpoint.write(self, str(path), keep)

    def restore(self, path):
        """Load the newest checkpoint under `path` into this simulation, which must be set up
        as the checkpointed one (mesh, materials, integrator, stage, boundaries, probes)."""
        from . import checkpoint
        return checkpoint.read(self, str(path))

    @classmethod
    def restart(cls, path, build):
        """`build()` sets a simulation up as for the original run; it is restored from the
        newest checkpoint under `path` and returned, ready to `run` on."""
        sim = build()
        if not isinstance(sim, cls):
            raise TypeError(f"restart: 'build' must return a Simulation, got {type(sim).__name__}")
        return sim.restore(path)

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
            if not (isinstance(t_end, (int, float)) and t_end > self.t):
                raise ValueError(f"run: 't_end' must be > current time {self.t}, got {t_end!r}")
            steps = int(math.ceil((t_end - self.t) / self.dt - 1e-9))
        elif not (isinstance(steps, (int, np.integer)) and steps >= 0):
            raise ValueError(f"run: 'steps' must be a non-negative integer, got {steps!r}")
        if (checkpoint is None) != (checkpoint_every is None):
            raise ValueError("run: give both 'checkpoint' (a directory) and 'checkpoint_every'")
        if checkpoint_every is not None and not (
                isinstance(checkpoint_every, (int, np.integer)) and checkpoint_every >= 1):
            raise ValueError(f"run: 'checkpoint_every' must be a positive integer, got {checkpoint_every!r}")
        t_final = self.t + steps * self.dt
        self.stats["courant"] = self.courant
        note = "" if self.integrator.explicit else f"Courant {self.courant:.3g}"
        bar = Progress(steps, t_final, self.comm, force=progress, note=note)
        if output is not None:
            output.open(self)
            if self.step_count == 0:
                output.write(self)
        try:
            for k in range(steps):
                try:
                    self.step()
                except (RuntimeError, FloatingPointError) as err:
                    if getattr(err, "state_intact", False):
                        self._save_last_state(output, checkpoint)
                    raise
                bar.update(k + 1, self.t)
                if output is not None and self.step_count % output.every == 0:
                    output.write(self)
                if checkpoint is not None and (self.step_count % checkpoint_every == 0 or k == steps - 1):
                    self.checkpoint(checkpoint)
        finally:
            bar.close()
            if output is not None:
                output.close()
        return self


class Probe:
    """Time series of fields at the particle nearest to a point (answered by its owner rank)."""

    def __init__(self, sim, point, fields, path, every):
        p = sim.particles
        point = np.asarray(point, dtype=np.float64)
        bad = [f for f in fields if f not in PROBE_FIELDS]
        if bad:
            raise ValueError(f"probe: unknown field(s) {bad}; choose from {sorted(PROBE_FIELDS)}")
        if point.shape != (sim.gdim,):
            raise ValueError(f"probe: 'point' must have length {sim.gdim}, got {point.shape}")
        x0 = p.x - p.u
        dist = np.linalg.norm(x0 - point, axis=1) if len(p) else np.array([np.inf])
        k = int(np.argmin(dist))
        best = (float(dist[k]), sim.comm.rank)
        if sim.comm.size > 1:
            best = min(sim.comm.allgather(best))
        self.owner = best[1]
        self.sim, self.fields, self.every = sim, list(fields), every
        self.pid = int(p.id[k]) if sim.comm.rank == self.owner else -1
        if sim.comm.size > 1:
            self.pid = sim.comm.bcast(self.pid, root=self.owner)
        self._idx = k if sim.comm.rank == self.owner else -1
        self._version = p.version
        self.rows = []
        cols = ["t"]
        for f in self.fields:
            cols += [f"{f}_{c}" for c in self._components(f)]
        self.columns = cols
        self.path = path
        # the CSV is streamed: rank 0 writes the header, then whichever rank owns the particle
        # appends its row (flushed), so a crashed run leaves every row up to its last step
        self.writer = None
        if path:
            self.rewrite_csv([])
            self.writer = ProbeWriter(path, cols, sim.comm, append=True)
        self.record()

    def _components(self, f):
        if f == "stress":
            return ["xx", "yy", "zz", "xy", "yz", "xz"][: 6 if self.sim.gdim == 3 else 4]
        return "xyz"[: self.sim.gdim]

    def _value(self, f, i):
        arr = getattr(self.sim.particles, PROBE_FIELDS[f])[i]
        if f == "stress":
            s = arr
            vals = [s[0, 0], s[1, 1], s[2, 2], s[0, 1], s[1, 2], s[0, 2]]
            return vals[: 6 if self.sim.gdim == 3 else 4]
        return list(arr)

    def record(self):
        if self.sim.step_count % self.every:
            return
        p = self.sim.particles
        if p.version != self._version:          # particles were reshuffled between ranks
            hit = np.flatnonzero(p.id == self.pid)
            self._idx = int(hit[0]) if len(hit) else -1
            self._version = p.version
        if self._idx < 0:
            return
        row = [self.sim.t]
        for f in self.fields:
            row += self._value(f, self._idx)
        self.rows.append(row)
        if self.writer is not None:
            self.writer.write_row(row)

    def data(self):
        """dict column -> array on every rank (collective; call outside the time loop)."""
        rows = self.rows
        if self.sim.comm.size > 1:
            rows = sorted(r for part in self.sim.comm.allgather(rows) for r in part)
        rows = np.array(rows).reshape(-1, len(self.columns))
        return {c: rows[:, j] for j, c in enumerate(self.columns)}

    def rewrite_csv(self, rows):
        """Start the CSV afresh with `rows` (rank 0; collective), e.g. after a restore."""
        comm = self.sim.comm
        if comm.rank == 0:
            w = ProbeWriter(self.path, self.columns, None)
            w._open()
            for row in rows:
                w.write_row(list(row))
            w.close()
        if comm.size > 1:
            comm.barrier()


class Output:
    """Periodic output: particles as VTU (+ .pvd/.pvtu) and nodal fields as XDMF."""

    def __init__(self, path, every=10, particle_fields=("v", "u", "stress", "mass", "V", "id"),
                 grid_fields=True):
        if not (isinstance(every, (int, np.integer)) and every >= 1):
            raise ValueError(f"Output: 'every' must be a positive integer, got {every!r}")
        self.path, self.every = str(path), int(every)
        self.particle_fields, self.grid_fields = particle_fields, grid_fields
        self._pw = self._xdmf = None
        self._mode = "w"

    def open(self, sim):
        import os
        err = None
        if sim.comm.rank == 0:
            try:
                os.makedirs(self.path, exist_ok=True)
                probe = os.path.join(self.path, ".write_test")
                open(probe, "w").close()
                os.remove(probe)
            except OSError as e:
                err = str(e)
        if sim.comm.size > 1:
            err = sim.comm.bcast(err, root=0)
        if err is not None:
            raise ValueError(f"Output: 'path' {self.path!r} cannot be written ({err})")
        if self._pw is None:
            self._pw = ParticleWriter(os.path.join(self.path, "particles"), sim.comm)
        if self.grid_fields and self._xdmf is None:
            from dolfinx import fem, io
            self._xdmf = io.XDMFFile(sim.comm, os.path.join(self.path, "grid.xdmf"), self._mode)
            if self._mode == "w":
                self._xdmf.write_mesh(sim.grid.mesh)
            self._mode = "a"
            self._vel = fem.Function(sim.grid.V, name="velocity")
            self._dens = fem.Function(fem.FunctionSpace(sim.grid.mesh, ("Lagrange", 1)), name="mass")

    def write(self, sim):
        p = sim.particles
        smooth = sim.smoothed_stress() if "stress_smoothed" in self.particle_fields else None
        fields = {f: smooth if f == "stress_smoothed" else getattr(p, f) for f in self.particle_fields}
        self._pw.write(sim.t, p.x, fields)            # after smoothing (it may migrate particles)
        if self._xdmf is not None and "velocity" in sim.nodal:
            self._vel.x.array[:] = sim.nodal["velocity"].ravel()
            self._dens.x.array[:] = sim.nodal["mass"]
            self._xdmf.write_function(self._vel, sim.t)
            self._xdmf.write_function(self._dens, sim.t)

    def close(self):
        if self._xdmf is not None:
            self._xdmf.close()
            self._xdmf = None

    @property
    def pvd(self):
        import os
        return os.path.join(self.path, "particles.pvd")
