"""Always-on checks after each step (cheap: one read-only pass over the particles), and the
`on_leave` policy for particles that left the mesh (particles_left).

A run either stays physical or stops with a message naming the step, the time, the field
and the first offending particles (ids and positions), on every rank at once."""
import warnings

import numpy as np
from numba import njit, prange

from .errors import ParticlesLeftMesh
from .kernels.threads import PRANGE, chunk, particle_chunks
from .materials.piola import det3


FIELD_NAMES = ("position", "velocity", "stress", "deformation gradient")
SPEED_CELLS = 2.0   # a particle moving more than this many cells per step stops the run (code 8)


@njit(cache=True)
def _scan_range(x, v, a, stress, F, V, V0, inverted, vol_tol, a_lim2, v_lim2, bad_out,
                material_id, stretch, lo, hi):
    n_bad = 0
    d = x.shape[1]
    for p in range(lo, hi):
        s = 0.0                         # the stretch V / V0 of a particle carrying stress
        for i in range(3):
            for j in range(3):
                s += abs(stress[p, i, j])
        if s > 0.0 and V[p] > stretch[material_id[p]] * V0[p]:
            stretch[material_id[p]] = V[p] / V0[p]
        code = 5 if p < inverted.shape[0] and inverted[p] == 1 else 0
        # 0 * value is 0 for every finite value and NaN otherwise: one test for the common case
        z = 0.0
        for k in range(d):
            z += 0.0 * x[p, k] + 0.0 * v[p, k]
        for i in range(3):
            for j in range(3):
                z += 0.0 * stress[p, i, j] + 0.0 * F[p, i, j]
        if code == 0 and z != 0.0:                  # which field is not finite
            for k in range(d):
                if not np.isfinite(x[p, k]):
                    code = 1
                elif not np.isfinite(v[p, k]):
                    code = 2
            for i in range(3 if code == 0 else 0):
                for j in range(3):
                    if not np.isfinite(stress[p, i, j]):
                        code = 3
                    elif not np.isfinite(F[p, i, j]):
                        code = 4
        if code == 0:
            if not det3(F[p]) > 0.0:
                code = 5
            elif V[p] < vol_tol * V0[p]:
                code = 6
        if code == 0:
            s = 0.0
            for k in range(d):
                s += a[p, k] * a[p, k]
            if s > a_lim2:
                code = 7
            else:
                s = 0.0
                for k in range(d):
                    s += v[p, k] * v[p, k]
                if s > v_lim2:
                    code = 8
        bad_out[p] = code
        if code:
            n_bad += 1
    return n_bad


@njit(parallel=PRANGE, cache=True)
def _scan(x, v, a, stress, F, V, V0, inverted, vol_tol, a_lim2, v_lim2, bad_out, material_id,
          stretch):
    """bad_out[p] = 0 (fine), 1..4 (non-finite field, see FIELD_NAMES), 5 (det F <= 0, or an
    increment the commit refused: `inverted`), 6 (volume below vol_tol V0), 7 (|a|^2 > a_lim2:
    a velocity jump of more than a cell per step in one step, the start of a blow-up), 8
    (|v|^2 > v_lim2: a particle moving more than SPEED_CELLS cells per step, which no stable
    explicit run reaches: a blow-up that grew over several steps). An
    inversion is
    reported first: it is the cause of any non-finite value that follows it. Returns the
    number of bad particles (threaded over particle chunks, kernels.threads). In the same pass
    stretch[k] = max(stretch[k], V_p / V0_p) over the particles of material k that carry
    stress (material_wave_speeds)."""
    n = x.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _scan_range(x, v, a, stress, F, V, V0, inverted, vol_tol, a_lim2, v_lim2, bad_out,
                           material_id, stretch, np.int64(0), n)
    bad = np.zeros(nc, dtype=np.int64)
    part = np.ones((nc, stretch.shape[0]))
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        bad[c] = _scan_range(x, v, a, stress, F, V, V0, inverted, vol_tol, a_lim2, v_lim2,
                             bad_out, material_id, part[c], lo, hi)
    for c in range(nc):
        for k in range(stretch.shape[0]):
            stretch[k] = max(stretch[k], part[c, k])
    return bad.sum()


def check_particles(sim, vol_tol=1e-6):
    """Raise FloatingPointError (non-finite state) or RuntimeError (inverted or collapsed
    particles, or a blow-up: a particle of an explicit run whose velocity changed by more than
    h / dt in one step, |a_p| dt > h / dt, a kick that would move it a further cell per step;
    smooth motion, impacts and free fall change a particle's velocity by a fraction of that;
    or a particle faster than SPEED_CELLS h / dt, moving more than two cells per step, where a
    blow-up that grew over many steps has taken it) naming step, time, field and the first
    offending particles; for a blow-up also their speed, velocity jump, stress and volume
    ratio det F, and the likely causes. The same pass keeps the per-material stretch of the
    state for material_wave_speeds."""
    p = sim.particles
    bad = np.empty(len(p), dtype=np.int8)
    a_lim = sim.grid.h / sim.dt ** 2 if sim.integrator.explicit else np.inf
    J = np.ones(len(p.materials))
    v_lim = SPEED_CELLS * a_lim * sim.dt
    n_bad = _scan(p.x, p.v, p.a, p.stress, p.F, p.V, p.V0, sim._inverted, vol_tol, a_lim * a_lim,
                  v_lim * v_lim, bad, p.material_id, J)
    sim._stretch = (_state_key(sim), J)
    sim._inverted[:] = 0
    if sim.comm.size > 1:
        n_bad = sim.comm.allreduce(n_bad)
    if n_bad == 0:
        return
    idx = np.flatnonzero(bad)
    idx = idx[np.argsort(bad[idx] != 5, kind="stable")][:5]       # inversions first
    local = [(int(bad[i] != 5), int(p.id[i]), tuple(np.round(p.x[i], 6)), int(bad[i]),
              float(np.linalg.norm(p.v[i])), float(np.abs(p.stress[i]).max()),
              float(det3(p.F[i])), float(np.linalg.norm(p.a[i]) * sim.dt)) for i in idx]
    everyone = sim.comm.allgather(local) if sim.comm.size > 1 else [local]
    first = [r[1:] for r in sorted(r for part in everyone for r in part)]
    code = first[0][2]
    first = [r for r in first if r[2] == code][:5]
    what = (f"non-finite {FIELD_NAMES[code - 1]}" if code <= 4 else
            "inverted particle (det F <= 0)" if code == 5 else
            f"collapsed particle volume (V < {vol_tol:g} V0)" if code == 6 else
            f"blow-up: particle velocity jumped by more than h / dt = {sim.grid.h / sim.dt:.4g} "
            f"m/s in one step" if code == 7 else
            f"blow-up: particle speed above {SPEED_CELLS:g} h / dt = "
            f"{SPEED_CELLS * sim.grid.h / sim.dt:.4g} m/s (more than {SPEED_CELLS:g} cells per "
            f"step)")
    msg = (f"step {sim.step_count}, t = {sim.t:.6g}: {what} in {n_bad} particle(s); first ids "
           f"{[r[0] for r in first]} at {[r[1] for r in first]}")
    if code >= 7:
        msg += (f"; their velocity jump {[float(f'{r[6]:.4g}') for r in first]} m/s, |v| "
                f"{[float(f'{r[3]:.4g}') for r in first]} m/s, max |stress| "
                f"{[float(f'{r[4]:.4g}') for r in first]} Pa, det F "
                f"{[float(f'{r[5]:.4g}') for r in first]}. Likely causes: a stress spike in a "
                f"particle whose volume grew far (det F >> 1) and is compacted again, loading "
                f"nodes of little mass; a load or gravity that accelerates the material past "
                f"h / dt; a stiffness or density beyond the one dt='auto' was set from; too "
                f"large a dt (lower cfl)")
    raise (FloatingPointError if code <= 4 else RuntimeError)(msg)


def _state_key(sim):
    """What the stretch kept by check_particles belongs to: the step and the particle set."""
    return sim.step_count, sim.particles.version, len(sim.particles)


def _stretch(sim):
    """Per material the largest V_p / V0_p (>= 1) of its particles that carry stress: the one
    check_particles kept for this state, else a fresh scan (local; see _scan)."""
    kept = getattr(sim, "_stretch", None)
    if kept is not None and kept[0] == _state_key(sim):
        return kept[1]
    p = sim.particles
    J = np.ones(len(p.materials))
    _scan(p.x, p.v, p.a, p.stress, p.F, p.V, p.V0, sim._inverted[:0], 0.0, np.inf, np.inf,
          np.empty(len(p), dtype=np.int8), p.material_id, J)
    return J


def material_wave_speeds(sim, stretch=True):
    """Per material (global, collective) the P-wave speed of its current state: a material with
    a stress-dependent stiffness gives its state_p_wave_speed(stress) (Hypoplastic: the bound
    at the largest mean stress when it is above p_max; its stretched, loose particles are at
    low pressure and soft); with `stretch` any other gives p_wave_speed sqrt(J_max), J_max >= 1
    the largest volume ratio V / V0 of its particles that carry stress (c_p = sqrt(M / rho),
    rho = rho_0 / J: a stretched particle is lighter for the same stiffness; particles without
    stress, a cohesionless material pulled apart, add no stiffness), without it 0."""
    p = sim.particles
    mats = p.materials
    J = _stretch(sim) if stretch else None
    c = np.zeros(len(mats))
    for k, m in enumerate(mats):
        f = getattr(m, "state_p_wave_speed", None)
        if f is not None:
            c[k] = f(p.stress[p.material_id == k])
        elif stretch:
            c[k] = m.p_wave_speed * np.sqrt(J[k])
    if sim.comm.size > 1:
        from mpi4py import MPI
        sim.comm.Allreduce(MPI.IN_PLACE, c, op=MPI.MAX)
    return c


def state_wave_speed(sim):
    """The largest P-wave speed of the deformable materials (Simulation._deformable_materials)
    in their current state (material_wave_speeds); collective."""
    c = material_wave_speeds(sim)
    mats = sim.particles.materials
    return float(max(c[k] for k, m in enumerate(mats)
                     if any(m is w for w in sim._wave_materials)))


def check_wave_speed(sim):
    """Warn once (rank 0) when a material whose stiffness grows with its state (a
    `state_p_wave_speed(stress)` method, e.g. Hypoplastic above p_max) now has a P-wave speed
    for which the explicit dt exceeds the critical step stability_factor h / c_p. A fixed dt
    only: dt="auto" follows the state (Simulation.follow_state_dt). Collective."""
    if (not sim.integrator.explicit or getattr(sim, "_wave_warned", False)
            or getattr(sim, "_dt_auto", False)):
        return
    p = sim.particles
    if not any(hasattr(m, "state_p_wave_speed") for m in p.materials):
        return
    c_all = material_wave_speeds(sim, stretch=False)
    k = int(np.argmax(c_all))
    c = float(c_all[k])
    crit = getattr(sim.integrator, "stability_factor", 1.0) * sim.grid.h / c
    if sim.dt > crit:
        sim._wave_warned = True
        if sim.comm.rank == 0:
            mat = p.materials[k]
            warnings.warn(f"step {sim.step_count}, t = {sim.t:.6g}: {type(mat).__name__} "
                          f"(material {k}) now has c_p = {c:.4g} m/s, so dt = {sim.dt:.4g} s "
                          f"exceeds the critical step {crit:.4g} s (dt was set from c_p = "
                          f"{mat.p_wave_speed:.4g} m/s); raise the material's p_max or lower "
                          f"dt / cfl", RuntimeWarning, stacklevel=4)


def _leaving_cause(sim):
    """What the particles that left (cell -1) say about why (collective): their largest
    speed, stress and det F against the fastest deformable material's P-wave speed c_p of
    the current state (state_wave_speed). A particle faster than c_p was thrown out by a
    blow-up that began earlier (issue 21: stress spikes in particles stretched far and
    squeezed again reached about 60x lithostatic before particles left at 274 m/s); a slower
    one flowed out of a mesh too small for the motion."""
    from mpi4py import MPI
    p = sim.particles
    gone = np.flatnonzero(p.cell < 0)
    v = float(np.linalg.norm(p.v[gone], axis=1).max()) if len(gone) else 0.0
    s = float(np.abs(p.stress[gone]).max()) if len(gone) else 0.0
    jmax = float(np.linalg.det(p.F[gone]).max()) if len(gone) else 0.0
    if sim.comm.size > 1:
        v, s, jmax = (sim.comm.allreduce(q, op=MPI.MAX) for q in (v, s, jmax))
    c = state_wave_speed(sim) if sim._wave_materials else 0.0
    msg = (f"; their largest speed {v:.4g} m/s, |stress| {s:.4g} Pa, det F {jmax:.4g} "
           f"(P-wave speed of the material's state c_p = {c:.4g} m/s)")
    if c > 0.0 and v > c:
        return msg + (". Faster than c_p: unless the material was launched that fast, a "
                      "blow-up threw them out. Likely causes: a stress spike in particles whose "
                      "volume grew far (det F >> 1) and was compacted again; a load or contact "
                      "that outgrew dt; too large a dt (lower cfl)")
    return msg + (". The material flowed out of the mesh: extend the mesh, or pass "
                  "on_leave='remove' to drop such particles")


def particles_left(sim, ids, xs):
    """Apply sim.on_leave (Simulation) to the particles in no cell of the mesh (cell == -1; `ids`
    and `xs` list them globally, the same on every rank)."""
    if sim.on_leave == "periodic":             # re-enter through the opposite face
        from .boundaries.periodic import wrap
        if sim.grid.periodic is None:
            raise ValueError("Simulation: on_leave='periodic' needs periodic sides "
                             "(sim.set_periodic(axis))")
        wrap(sim, sim.grid.periodic)
        ids, xs = sim.particles.send_to_owners()
        if len(ids) == 0:
            return
    where = (f"step {sim.step_count}, t = {sim.t:.6g}: {len(ids)} particle(s) left the mesh, "
             f"ids {ids[:5].tolist()} at {np.round(xs[:5], 6).tolist()}")
    if sim.on_leave in ("periodic", "error"):
        raise ParticlesLeftMesh(where + _leaving_cause(sim))
    p = sim.particles
    gone = p.cell < 0
    mass = p.mass[gone].sum()
    if sim.comm.size > 1:
        mass = sim.comm.allreduce(mass)
    keep = np.flatnonzero(~gone)
    for name in p.field_names():
        setattr(p, name, np.ascontiguousarray(getattr(p, name)[keep]))
    p.version += 1
    sim.removed_mass += mass
    sim.removed_count += len(ids)
    if sim.comm.rank == 0:
        warnings.warn(f"{where}: removed (mass {mass:.6g}; {sim.removed_count} particles, "
                      f"mass {sim.removed_mass:.6g} removed so far)", stacklevel=3)
