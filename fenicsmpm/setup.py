"""The set-up API of a Simulation (SetupMixin, inherited by fenicsmpm.Simulation): Dirichlet
conditions, tractions and particle loads, Robin and particle-layer boundaries, frictional
boundaries, periodic sides, particle splitting, stages, observers and probes. These methods
register what the stages of the time loop (simulation.py) then apply."""
import logging
import math
import warnings

import numpy as np

from .boundaries import (ParticleLayer, PrescribedMotion, Robin, RobinForms, Traction, fixed_dofs,
                         prescribed_increment)
from .boundaries.friction import FrictionalBoundary
from .boundaries.particle_layer import pull_back_area, pressure_force
from .boundaries.robin import facets_on_boundary
from .io import Probe
from .io.probe import ReactionProbe
from .shapes import SHAPES
from .kernels import transfer as kt
from .splitting import Splitting

FORCE_INTEGRATIONS = ("particles", "mixed")
LEAVE_POLICIES = ("error", "remove", "periodic")
# why shape="auto" falls back to the standard family for an explicit run with a particle layer
# (python -m fenicsmpm.bench absorbing: W3 rows; implicit runs keep the wide family: W3 Newmark
# reflection 3.4 % / 1.8 % with cpGIMP at dx = 0.25 / 0.125 m against 0.8 % / 3.1 % standard)
LAYER_EXPLICIT = ("explicit run with a particle-layer boundary: a wide family's layer particles "
                  "reach into the empty cells beyond the material, whose small nodal masses make "
                  "the explicit step unstable (W3 reflection 21 % with cpGIMP at dx = 0.25 m, "
                  "1 % standard)")
# the default mass_tolerance of an implicit wide-family run with a particle layer: the layer
# particles' domains reach the empty cells beyond the material with masses down to round-off,
# and those nodes reflect. W1 column, layer 2 m above the mesh's base, Newmark dt 0.005 s
# (tests/test_particle_layer.py): reflection 5.4 % with cpGIMP at 1e-12, 1.28 % at 1e-4 (1.28 %
# standard); W4 (demos/point_load_2d.py, dx = 0.05 m, viscous far field): energy balance
# -0.62 % of the largest work of the load at t = 1 s (-5.6 % standard)
LAYER_MASS_TOLERANCE = 1e-4


def _check_ramp(T, owner):
    if T is None:
        return None
    if not (isinstance(T, (int, float, np.floating)) and math.isfinite(T) and T > 0):
        raise ValueError(f"{owner}: 'gravity_ramp' must be a time > 0 or None, got {T!r}")
    return float(T)


class SetupMixin:
    """Set-up methods of fenicsmpm.Simulation (see there for the attributes they fill)."""

    def fix(self, where, components=None, displacement=None, velocity=None):
        """Fix the given displacement components (default: all) at nodes where(x) is True.

        A roller is one component, e.g. fix(lambda x: np.isclose(x[:, 1], 0), [1]).
        Prescribed motion instead of holding them (fm.Explicit, fm.QuasiStatic, fm.Newmark): either
        displacement=u(t), a function of time giving a number or one value per component
        (each step moves the dofs by u(t + dt) - u(t)), or velocity=v, a constant or v(t)
        (each step moves them by v(t + dt/2) dt); e.g. a platen pushed down 5 cm over 1 s:
        fix(top, [1], displacement=lambda t: -0.05 * t). sim.reaction(where) is the force
        these dofs exert on the material."""
        mask = fixed_dofs(self.grid, where, components)
        if displacement is not None or velocity is not None:
            comps = (list(range(self.gdim)) if components is None
                     else list(np.atleast_1d(components)))
            motion = PrescribedMotion(mask, comps, displacement, velocity)
            self._check_prescribed(self.integrator, "fix", [motion])
            self.motions.append(motion)
        self.fixed |= mask

    @staticmethod
    def _check_prescribed(integrator, owner, motions):
        if motions and not getattr(integrator, "supports_prescribed_motion", False):
            raise NotImplementedError(
                f"{owner}: prescribed motion (fix(..., displacement=... or velocity=...)) needs "
                f"fm.Explicit, fm.QuasiStatic or fm.Newmark; {type(integrator).__name__} holds "
                f"fixed dofs at rest (release(where) the moving dofs first to change integrator)")

    def prescribed_increment(self, t0, t1, u=None, fixed_only=True):
        """(n_nodes, gdim) displacement increments of the fixed dofs over [t0, t1] from
        fix(..., displacement=/velocity=) and the integrator's u(x, t) (boundaries.dirichlet.
        prescribed_increment); None when no dof moves."""
        return prescribed_increment(self.grid.node_x, self.fixed, self.motions, t0, t1, u,
                                    fixed_only)

    def reaction(self, where=None):
        """The total force that the fixed dofs at the nodes where(x) (default: all fixed
        nodes) exerted on the material in the last step, from sim.nodal["reaction"]
        (fm.Explicit, with or without prescribed motion, and fm.QuasiStatic); summed over
        ranks: collective, call it on every rank."""
        R = self.nodal.get("reaction")
        if R is None:
            raise ValueError(f"reaction: {type(self.integrator).__name__} reports no reaction "
                             f"(fm.Explicit and fm.QuasiStatic do), or no step has run yet")
        own = self.grid.n_owned_nodes
        sel = np.ones(own, dtype=bool) if where is None else self.grid.nodes_where(where)[:own]
        r = R[:own][sel].sum(axis=0)
        return self.comm.allreduce(r) if self.comm.size > 1 else r

    def _select_particles(self, region, name):
        """(this rank's mask of the particles region(x) selects now, their global count);
        refuses a region that selects none anywhere (collective)."""
        p = self.particles
        sel = np.asarray(region(p.x))
        if sel.shape != (len(p),):
            raise ValueError(f"{name}: 'region(x)' must return one bool per particle, shape "
                             f"({len(p)},), got shape {sel.shape}")
        sel = sel.astype(bool)
        n = int(np.count_nonzero(sel))
        n = self.comm.allreduce(n) if self.comm.size > 1 else n
        if n == 0:
            raise ValueError(f"{name}: 'region' selects no particle")
        return sel, n

    def add_particle_load(self, region, value):
        """A force value(t) (a vector; per unit thickness in 2D) shared equally by the particles
        selected by region(x) now, mapped to the grid with their shape functions,
        f_i += sum_p N_ip value(t) / n. Unlike a facet traction it follows the material (the
        thesis's point load "applied to the top material points"). Returns the global number
        of loaded particles."""
        name = f"add_particle_load #{len(self.particle_loads)}"
        if not callable(region):
            raise TypeError(f"{name}: 'region' must be a function region(x) -> bool, got "
                            f"{type(region).__name__}")
        load = Traction(lambda x: True, value, name=name)
        load.at(self.t, self.gdim, nonfinite=ValueError)
        p = self.particles
        sel, n = self._select_particles(region, name)
        field = f"load_share_{len(self.particle_loads)}"
        p.add_field(field)[sel] = 1.0 / n
        self.particle_loads.append((field, load))
        return n

    def add_surface_pressure(self, region, normal, pressure, thickness=None):
        """A pressure (compression positive: a number or a function p(t)) on the material
        surface carried by the particles selected by region(x) now, whose outward unit normal
        is now `normal` (a vector): f_i -= sum_p N_ip p(t) a_p n_p, with the current area and
        normal from Nanson's formula a_p n_p = J F^-T (A_p N_p) and A_p = V_p / thickness now
        (default thickness: the particle size V_p^(1/d); boundaries.particle_layer). Unlike a
        facet traction it follows the surface as it moves, stretches and turns: a confining
        pressure on a sample that bulges, a surcharge on a settling crest. The area vectors
        are a particle field (they migrate and are checkpointed); with implicit integrators
        the load is taken at the start of each step (no load stiffness). Returns the global
        number of loaded particles."""
        k = len(self.surface_pressures)
        name = f"add_surface_pressure #{k}"
        if not callable(region):
            raise TypeError(f"{name}: 'region' must be a function region(x) -> bool, got "
                            f"{type(region).__name__}")
        nrm = np.asarray(normal, dtype=float)
        if nrm.shape != (self.gdim,) or not np.all(np.isfinite(nrm)) or not np.any(nrm):
            raise ValueError(f"{name}: 'normal' must be a non-zero vector of length "
                             f"{self.gdim}, got {normal!r}")
        if thickness is not None and not (isinstance(thickness, (int, float, np.floating))
                                          and math.isfinite(thickness) and thickness > 0):
            raise ValueError(f"{name}: 'thickness' must be a length > 0 or None, got {thickness!r}")
        value = pressure if callable(pressure) else (lambda t, q=pressure: q)
        self._pressure_at(value, self.t, name)
        p = self.particles
        sel, n = self._select_particles(region, name)
        d = self.gdim
        t = p.V[sel] ** (1.0 / d) if thickness is None else thickness
        an0 = p.add_field(f"pressure_an0_{k}", (d,))
        an_now = (p.V[sel] / t)[:, None] * (nrm / np.linalg.norm(nrm))
        an0[sel] = pull_back_area(p.F[sel], an_now, d)
        self.surface_pressures.append((f"pressure_an0_{k}", value, name))
        return n

    @staticmethod
    def _pressure_at(value, t, name):
        q = value(t)
        if not (isinstance(q, (int, float, np.floating)) and math.isfinite(q)):
            raise ValueError(f"{name}: 'pressure' must be a finite number or p(t) returning one, "
                             f"got {q!r} at t = {t:.6g}")
        return float(q)

    def move_particles(self, region, displacement, components=None, penalty=100.0):
        """Prescribe the displacement of the particles selected by region(x) now:
        u_p = displacement(X, t) on `components` (default: all), X their positions now, a
        function returning (n, gdim); implicit integrators only, enforced by penalty
        (fenicsmpm.boundaries.particle_motion: springs of `penalty` times the particle's own
        stiffness). A displacement-controlled rigid footing or plate that, unlike fixed mesh
        nodes, moves with the material. Returns the constraint's index for
        particle_reaction(). Collective. The marks travel with the particles (MPI
        migration, checkpoints); the function does not: after a restart, add the constraint
        again, its displacement then counted from the restart."""
        from .boundaries import particle_motion as pm
        name = f"move_particles #{len(self.particle_motions)}"
        if getattr(self.integrator, "explicit", True):
            raise NotImplementedError(f"{name}: prescribed particle motion is enforced by the "
                                      f"implicit integrators (fm.QuasiStatic, fm.Newmark); "
                                      f"explicitly, use a rigid body (fm.ExplicitContact)")
        if not callable(region) or not callable(displacement):
            raise TypeError(f"{name}: 'region' and 'displacement' must be functions "
                            f"region(x) -> bool and displacement(X, t) -> (n, gdim)")
        if isinstance(penalty, bool) or not (isinstance(penalty, (int, float)) and penalty > 0):
            raise ValueError(f"{name}: 'penalty' must be a number > 0, got {penalty!r}")
        comps = list(range(self.gdim)) if components is None else list(components)
        if not comps or any(c not in range(self.gdim) for c in comps):
            raise ValueError(f"{name}: 'components' must be a non-empty subset of "
                             f"{list(range(self.gdim))}, got {components!r}")
        motion = pm.ParticleMotion(len(self.particle_motions), displacement, comps, penalty)
        if pm.attach(self, motion, region) == 0:
            raise ValueError(f"{name}: 'region' selects no particle")
        self.particle_motions.append(motion)
        return motion.index

    def particle_reaction(self, index=0):
        """The force (a gdim vector, per unit thickness in 2D) that prescribed particle motion
        `index` (move_particles) exerted on the material in the last step, summed over ranks."""
        if not 0 <= index < len(self.particle_motions):
            raise ValueError(f"particle_reaction: no prescribed particle motion {index!r} "
                             f"({len(self.particle_motions)} added with move_particles)")
        r = self.particle_motions[index].reaction
        if r is None:
            raise ValueError("particle_reaction: no step has run yet")
        return r

    def _particle_load_force(self, t, out):
        p = self.particles
        for name, load in self.particle_loads:
            share = getattr(p, name)
            sel = np.flatnonzero(share)
            if len(sel):
                vec = np.ascontiguousarray(np.broadcast_to(load.at(t, self.gdim), (len(sel), self.gdim)))
                kt.p2g_weighted(self.grid.D, self.nodes[sel], self.N[sel], share[sel], vec, out)
        for field, value, name in self.surface_pressures:
            an0 = getattr(p, field)
            loaded = np.flatnonzero(np.any(an0 != 0.0, axis=1))
            if len(loaded):
                pressure_force(self.grid.D, loaded, self.nodes, self.N, p.F, an0,
                               self._pressure_at(value, t, name), out)

    def release(self, where=None, components=None):
        """Remove Dirichlet conditions at nodes where(x) (default: everywhere) on the given
        components (default: all), e.g. to replace a fixed base by an absorbing one."""
        mask = (np.ones((self.grid.n_nodes, self.gdim), dtype=bool) if where is None
                else fixed_dofs(self.grid, where, components))
        self.fixed &= ~mask
        for m in self.motions:
            m.mask &= ~mask
        self.motions = [m for m in self.motions if m.mask.any()]

    def start_stage(self, integrator=None, dt=None, gravity=None, initial_stress=True,
                    reset_displacement=True, gravity_ramp=None):
        """Begin a new stage on this simulation (seed 000 §3.5), e.g. after a static gravity
        stage: `sim.start_stage(fm.Newmark(), dt=5e-3, gravity=(0, 0))` then swap boundaries
        with `release` and `add_boundary`.

        initial_stress: keep the current stress as sigma_ini; from now on the internal force
          comes from sigma_dyn = sigma - sigma_ini while materials see the total stress, so
          removing gravity together with sigma_ini leaves the body in equilibrium. A stage
          that keeps (or sets) gravity, or keeps a traction that is not zero at its start,
          with initial_stress=True on a stressed body loads it a second time (under gravity
          it sinks as under twice its weight): a RuntimeWarning names those loads (rank 0);
          pass gravity=(0, 0), or initial_stress=False to go on under the same loads with
          the total stress. Collective.
        reset_displacement: measure particle displacements (and Robin spring displacements)
          from the start of the stage.
        gravity_ramp: ramp time T of this stage's gravity (see Simulation), None: no ramp."""
        p = self.particles
        if integrator is not None:
            if not all(hasattr(integrator, a) for a in ("explicit", "setup", "step")):
                raise TypeError(f"start_stage: 'integrator' must be an integrator such as "
                                f"fm.Newmark(), got {integrator!r}")
            if self.frictions and not getattr(integrator, "supports_friction", False):
                raise NotImplementedError("start_stage: frictional boundaries need fm.Explicit, "
                                          f"not {type(integrator).__name__}")
            self._check_prescribed(integrator, "start_stage", self.motions)
            self.integrator = integrator
            if integrator.explicit and self.layers:
                self._use_standard_shape(LAYER_EXPLICIT)
            integrator.setup(self)
            self._robin = None                    # recompile for the new integrator
        if dt is not None or integrator is not None:
            self._wave_materials = self._deformable_materials()
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
            stressed = bool(np.any(p.stress != 0.0))
            if self.comm.size > 1:
                from mpi4py import MPI
                stressed = self.comm.allreduce(stressed, op=MPI.LOR)
            loads = ([f"gravity {tuple(float(g) for g in self.gravity)}"]
                     if np.any(self.gravity != 0.0) else [])
            loads += [tr.name for tr in self.tractions
                      if np.any(tr.at(self.t, self.gdim, nonfinite=ValueError) != 0.0)]
            if stressed and loads and self.comm.rank == 0:
                warnings.warn(f"start_stage: {' and '.join(loads)} act in this stage while "
                              f"initial_stress=True balances the current stress with "
                              f"sigma_ini, so the body carries these loads a second time (under "
                              f"gravity it sinks as under twice its weight). Pass gravity=(0, 0) "
                              f"(and tractions that are zero from now on) for a stage on top of "
                              f"the static state (seed 000 3.5), or initial_stress=False to go "
                              f"on under the same loads with the total stress", RuntimeWarning,
                              stacklevel=2)
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
        face re-enters through the other. shape="mpm" only (with shape="auto" the simulation
        switches to it, logged). Returns the PeriodicTie."""
        from .boundaries.periodic import PeriodicTie
        self._use_standard_shape("periodic sides support the standard family only")
        if self.shape != "mpm":
            raise NotImplementedError(f"set_periodic: shape={self.shape!r}; periodic sides "
                                      f"support shape='mpm' only")
        self.grid.periodic = PeriodicTie(self.grid, axis)
        return self.grid.periodic

    def add_friction(self, where, mu, normal=None):
        """A rigid frictional boundary on the grid nodes where(x) with Coulomb coefficient `mu`
        and outward unit normal `normal` (a vector), or, with normal=None, the normals of the
        mesh facets where(x) selects (inclined and curved bases); boundaries.friction, seed 002
        §5.1: unilateral contact decided by the gap between the particles and the base, stick
        or slip. Explicit integrators (fm.Explicit, fm.ExplicitContact) only; do not also
        `fix` the normal component there. Returns the boundary: its `reaction()` (collective)
        is the force the material exerted on it in the last step."""
        if not getattr(self.integrator, "supports_friction", False):
            raise NotImplementedError(f"add_friction: frictional boundaries need fm.Explicit or "
                                      f"fm.ExplicitContact, not {type(self.integrator).__name__}; "
                                      f"in implicit runs fix the base (sim.fix) instead")
        fr = FrictionalBoundary(where, mu, normal).bind(self.grid)
        self.frictions.append(fr)
        return fr

    def enable_splitting(self, alpha=2.0, beta=0.5, gamma=1.0, every=1):
        """Split particles whose voxel stretched beyond alpha, shrank below beta or sheared
        beyond gamma since their creation (seed 002 §3.4.1 eq 3.25; fenicsmpm.splitting).
        The number split so far is `splitting.count`; the last step's is stats["split"]."""
        if self.layers:
            raise ValueError("enable_splitting: particle-layer boundaries cannot be split")
        self.splitting = Splitting(self, alpha, beta, gamma, every)
        return self.splitting

    def add_traction(self, where, value):
        """Traction (force per area) on boundary facets where(x); value: vector or t -> vector.
        Checked now: the locator must select a boundary facet and value(t) at the current
        time must be a finite vector of length gdim (a non-finite value later stops the run
        with a FloatingPointError naming the traction and the time)."""
        tr = Traction(where, value, name=f"add_traction #{len(self.tractions)}")
        facets_on_boundary(self.grid, where, tr.name)
        tr.at(self.t, self.gdim, nonfinite=ValueError)
        self.tractions.append(tr)
        self._traction_forms = None

    def add_boundary(self, boundary):
        """Add a Robin boundary: fm.Viscous, fm.Viscoelastic or a user fm.Robin law on mesh
        facets, or an fm.ParticleLayer (the law on a layer of particles). Its displacement u
        is measured from the time it is added. Mesh forms are compiled once, at the next step."""
        if isinstance(boundary, ParticleLayer):
            if self.axisymmetric:
                raise NotImplementedError("add_boundary: particle-layer boundaries are not "
                                          "implemented on axisymmetric grids; use a mesh boundary")
            if self.integrator.explicit:
                self._use_standard_shape(LAYER_EXPLICIT)
            elif self.shape != "mpm" and self._mass_tolerance_default \
                    and self.mass_tolerance < LAYER_MASS_TOLERANCE:
                self.mass_tolerance = LAYER_MASS_TOLERANCE
                if self.comm.rank == 0:
                    logging.getLogger("fenicsmpm").info(
                        "particle layer with shape=%r: mass_tolerance = %g", self.shape,
                        LAYER_MASS_TOLERANCE)
            if self.fbar and not self.integrator.explicit:
                if not self.fbar_auto or self.step_count:
                    raise NotImplementedError("add_boundary: implicit F-bar (fbar=True) does not "
                                              "support particle layers; use fbar=False")
                self.fbar, self.fbar_reason = False, "implicit F-bar does not support particle layers"
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

    def observe(self, callback, every=1):
        """Call callback(sim) after every `every` steps (energy monitors, custom output)."""
        if not callable(callback):
            raise TypeError(f"observe: 'callback' must be callable, got {type(callback).__name__}")
        if not (isinstance(every, (int, np.integer)) and every >= 1):
            raise ValueError(f"observe: 'every' must be a positive integer, got {every!r}")
        self.observers.append((callback, int(every)))

    def probe(self, point, fields=("velocity",), path=None, every=1):
        """Record `fields` ("velocity", "displacement", "position", "stress", "acceleration")
        of the particle whose initial position is nearest to `point` (which must lie in the
        mesh), every `every` steps; CSV at `path`. Returns the fm.Probe: `str(probe)` names the
        particle it follows (id, initial position); `probe.data()` (collective) the series.
        "acceleration" is (v_new - v_old) / dt of the particle with explicit integrators and
        the Newmark/generalized-alpha particle acceleration with implicit ones."""
        pr = Probe(self, point, fields, path, every)
        self.probes.append(pr)
        return pr

    def probe_reaction(self, where=None, path=None, every=1):
        """Record the reaction force of the fixed or moved nodes at where(x) (default: all
        fixed nodes), sim.reaction(where), every `every` steps; CSV at `path` (columns t,
        reaction_x, reaction_y[, reaction_z]). Returns the probe; `probe.data()` (collective)
        the series. Needs an integrator that reports reactions (fm.Explicit, fm.QuasiStatic)."""
        if not getattr(self.integrator, "reports_reaction", False):
            raise ValueError(f"probe_reaction: {type(self.integrator).__name__} reports no "
                             f"reaction (fm.Explicit and the implicit integrators do)")
        pr = ReactionProbe(self, where, path, every)
        self.probes.append(pr)
        return pr


    def _on_new_mesh(self):
        """After Grid.ensure_vertex_ring rebuilt the mesh (same cells and owners): locate the
        particles again and size the nodal arrays for the new numbering (set-up calls that
        bind nodes come after the constructor)."""
        g, p, d = self.grid, self.particles, self.gdim
        self.comm = g.comm        # the old mesh's communicator dies with the old mesh
        p.cell, p.xi = g.locate(p.x)
        self.fixed = np.zeros((g.n_nodes, d), dtype=bool)
        self.motions = []
        if g.axisymmetric:
            self.fixed[:, 0] = np.abs(g.node_x[:, 0]) <= 1e-9 * g.h
        self.robin_u = np.zeros((g.n_nodes, d))

    def _deformable_materials(self):
        """The materials of particles that deform: those of rigid bodies (fm.ExplicitContact's
        `rigid`; they carry no stress) do not limit the explicit time step (issue 21).
        Collective; all materials when every body is rigid."""
        p = self.particles
        rigid = list(getattr(self.integrator, "rigid", None) or ())
        if not rigid:
            return list(p.materials)
        from .contact.multi_velocity import body_ids
        used = np.zeros(len(p.materials), dtype=np.int64)
        used[np.unique(p.material_id[~np.isin(body_ids(p), rigid)])] = 1
        if self.comm.size > 1:
            used = self.comm.allreduce(used)
        return [m for m, u in zip(p.materials, used) if u] or list(p.materials)

    def _use_standard_shape(self, reason):
        """shape="auto" falls back to the standard family before the first step (logged);
        nothing otherwise (a family asked for by name, or a run under way)."""
        if self.shape == "mpm" or not self.shape_auto or self.step_count:
            return
        self.shape, self.shape_reason, self._wide = "mpm", reason, None
        self._n_alloc = -1
        if self.comm.rank == 0:
            logging.getLogger("fenicsmpm").info("shape='auto': mpm (%s)", reason)

    def _check_options(self, on_leave, max_dt_cuts, shape, stress_feedback, gravity_ramp, force_integration,
                       fbar):
        """Check and store the options of Simulation() (see there)."""
        if on_leave not in LEAVE_POLICIES:
            raise ValueError(f"Simulation: 'on_leave' must be one of {LEAVE_POLICIES}, got {on_leave!r}")
        if not (isinstance(max_dt_cuts, (int, np.integer)) and 0 <= max_dt_cuts <= 20):
            raise ValueError(f"Simulation: 'max_dt_cuts' must be an integer in [0, 20], got {max_dt_cuts!r}")
        self.on_leave, self.max_dt_cuts = on_leave, int(max_dt_cuts)
        if stress_feedback not in (None, "smoothed"):
            raise ValueError(f"Simulation: 'stress_feedback' must be None or 'smoothed', got {stress_feedback!r}")
        if stress_feedback is not None and not self.integrator.explicit:
            raise NotImplementedError("Simulation: stress_feedback='smoothed' needs an explicit integrator")
        self.stress_feedback = stress_feedback
        self.gravity_ramp = _check_ramp(gravity_ramp, "Simulation")
        if force_integration not in FORCE_INTEGRATIONS:
            raise ValueError(f"Simulation: 'force_integration' must be one of {FORCE_INTEGRATIONS}, "
                             f"got {force_integration!r}")
        if force_integration == "mixed" and shape not in ("mpm", "auto"):
            raise NotImplementedError(f"Simulation: force_integration='mixed' needs shape='mpm', got {shape!r}")
        self.force_integration = force_integration
        if self.axisymmetric and (shape not in ("auto", "mpm", "ugimp", "cpgimp")
                                  or force_integration != "particles"):
            raise NotImplementedError(f"Simulation: axisymmetric grids support shape 'mpm', 'ugimp' "
                                      f"and 'cpgimp' with particle integration, got shape={shape!r}, "
                                      f"force_integration={force_integration!r}")
        if shape not in SHAPES:
            raise ValueError(f"Simulation: 'shape' must be one of {SHAPES}, got {shape!r}")
        if fbar not in (True, False, "auto"):
            raise ValueError(f"Simulation: 'fbar' must be True, False or 'auto', got {fbar!r}")
        if fbar is True and getattr(self.integrator, "double_mapping", False):
            raise NotImplementedError("Simulation: fbar=True is not implemented for the "
                                      "double-mapping (DM-GC) integrators")
        self.fbar_auto = fbar == "auto"
        self.fbar, self.fbar_reason = (False, "") if self.fbar_auto else (bool(fbar), "")

    def _resolve_fbar(self):
        """fbar="auto" (issue 21, chosen by data): F-bar on where a deformable particle is
        VonMises (isochoric plastic flow locks: Prandtl's smooth footing, bench bearing-capacity,
        1.80 (2+pi) c_u without F-bar at 5 cells under B/2, 0.994 standard / 1.031 cpGIMP with
        it; the implicit W5 footing at peak strength 1.249 -> 0.929) and the integrator supports
        it (explicit: every grid; implicit: plane and 3D grids, no particle layers, add_boundary);
        off otherwise: with Mohr-Coulomb the granular collapse against Lube et al.'s law
        (problems.granular_collapse, h = min(L0, H0) / 16) ran out +10.9 / +25.3 / +23.2 % at
        a = 1 / 2 / 4 with F-bar against +2.5 / +17.8 / +15.7 % without, its heights -22 / -30 /
        -43 % against -8 / -16 / -34 %. Logged once (rank 0)."""
        if not self.fbar_auto:
            return
        from .materials import VonMises
        if not any(isinstance(m, VonMises) for m in self._wave_materials):
            on, why = False, "no von Mises material"
        elif getattr(self.integrator, "double_mapping", False):
            on, why = False, "not implemented for the DM-GC integrators"
        elif self.force_integration != "particles":
            on, why = False, f"force_integration={self.force_integration!r}"
        elif not self.integrator.explicit and self.axisymmetric:
            on, why = False, "implicit F-bar needs a plane or 3D grid"
        else:
            on, why = True, "von Mises material: isochoric plastic flow locks without it"
        self.fbar, self.fbar_reason = on, why
        if on and self.comm.rank == 0:
            logging.getLogger("fenicsmpm").info("fbar='auto': %s (%s)", on, why)
