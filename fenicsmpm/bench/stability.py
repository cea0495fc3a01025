"""Benchmark case `stability`: numerical stability under stress (issue 6, long version).

    python -m fenicsmpm.bench stability [--quick]

The short versions of the same scenarios are the tests in tests/stress/, which call the
scenario functions of this module with small sizes. Every scenario is collective (MPI).

Scenarios (full size / --quick):
  bar-explicit    V1 vibrating bar (fenicsmpm.problems.elastic.vibrating_bar: 20 cells, 2x2 ppc,
                  L = 1, E = 100, rho = 1, v0 = 0.1, period T = 0.4 s), explicit MUSL at
                  dt = "auto" (cfl 0.5), 10^4 steps (125 periods) / 2000 steps.
  bar-newmark     the same bar, implicit Newmark at dt = 5 h / c, 10^3 steps (62.5 periods)
                  / 200 steps.
      Metrics: energy_drift = (mean E over the last period - mean E over the first) / E0,
      E = kinetic + strain (every step); max_energy_error = max |E - E0| / E0;
      energy_max = max E / E0, energy_end = E_end / E0. The explicit scheme conserves a
      shadow energy: the measured E oscillates by about 4 % x dt / dt_critical (the kinetic
      energy is taken at the particles' velocities, half a step off the stresses) without
      drifting; the drift is the figure of merit.
  dt sweep        explicit MUSL bar at dt / dt_critical = 0.5 ... 1.5: accepted (and run,
                  energy bounded) at or below 1, refused with ValueError (the limit in the
                  message) above 1. For each refused factor the run is also *forced*
                  (sim.dt set after construction) to show how much margin the limit h / c_p
                  leaves on this problem (forced_outcome, forced_energy_max).
                  2000 / 500 steps per factor.
  courant sweep   implicit Newmark on the bar at Courant C = dt c / h = 1, 5, 10, 20, 50
                  (stable: energy never above E0 by more than round-off and Newton converges),
                  1000 / 200 steps per Courant number.
  collapse        a neo-Hookean block (1 m high, 0.2 m wide, E = 1e5 Pa, nu = 0.25,
                  rho = 1000) on a fixed base between frictionless side walls (rollers),
                  gravity ramped linearly over 20 wave transits H / c_p to
                  rho g H / E = COLLAPSE_LOAD, then held for 10 transits; explicit MUSL with
                  PIC (flip = 0, damped: a quasi-static collapse), cfl 0.5. Compaction =
                  1 - sum V / sum V0 (the confined block only changes volume). Plus the same
                  pushed to rho g H / E = COLLAPSE_OVERLOAD and COLLAPSE_INVERSION, to find
                  where standard MPM stops (it must stop with a guard's RuntimeError naming
                  the particles, never NaN). 40 / 10 cell rows.
  impact          colliding discs (problems.elastic.colliding_discs, BENCHMARKS L2) at 10x the
                  speed (|v| = 1.41 m/s per disc, closing speed 2.8 m/s, 2.4 c_p), explicit
                  MUSL, USF and USL, to t = 0.6 s (impact at 0.16 s, rebound; later the discs
                  leave the unit square); and the same discs made of neo-Hookean material
                  (MUSL, USL). Metrics: momentum_error = max over steps of
                  |sum m v| / sum m |v|_0 (exact: 0), min det F, energies. Expected outcome:
                  completed, or a guard's RuntimeError (inverted / collapsed particle).
                  40 / 20 cells per side.

Output: stability.json (common schema; extra keys "dt_sweep", "courant_sweep", "collapse",
"impact" with the tables), stability.png (energy histories, sweeps, compaction, impact)
and tables on stdout."""
import math
import os
import time

import numpy as np

from . import common

CASE = "stability"
# The failure modes characterised here (inversion, compaction through the base, the forced
# 2x dt blow-up) are those of the standard family; the default shape="auto" (cpGIMP on these
# lattices) runs the same overloads further (USL impact at 10x does not invert).
SHAPE = "mpm"

SIZES = {
    "full": dict(explicit_steps=10_000, implicit_steps=1_000, sweep_steps=2_000,
                 courant_steps=1_000, collapse_rows=40, impact_cells=40),
    "quick": dict(explicit_steps=2_000, implicit_steps=200, sweep_steps=500,
                  courant_steps=200, collapse_rows=10, impact_cells=20),
}
# dt / dt_critical; 1.75 and 2.0 go beyond the issue's 0.5 ... 1.5 to show where the forced
# (refused) runs really become unstable on this problem
SWEEP_FACTORS = (0.5, 0.75, 0.9, 1.0, 1.1, 1.25, 1.5, 1.75, 2.0)
COURANTS = (1.0, 5.0, 10.0, 20.0, 50.0)
NEWMARK_DT_FACTOR = 5.0
# collapse: rho g H / E at the end of the ramp (COLLAPSE_LOAD: standard MPM reaches ~ 80 %
# compaction; COLLAPSE_OVERLOAD: well beyond what it can do)
COLLAPSE = dict(height=1.0, width=0.2, E=1.0e5, nu=0.25, density=1000.0, flip=0.0, cfl=0.5,
                ramp_transits=20.0, hold_transits=10.0)
COLLAPSE_LOAD = 30.0
COLLAPSE_OVERLOAD = 200.0       # the squeezed bottom row blows up: the guard stops it
COLLAPSE_INVERSION = 300.0      # a neo-Hookean particle inverts within ~10 steps
IMPACT_SPEED_FACTOR = 10.0
IMPACT_T_END = 0.6
IMPACT_SCHEMES = ("MUSL", "USF", "USL")


# ---------------------------------------------------------------------------- helpers
def state_finite(sim):
    """True when every particle position, velocity, stress, F and volume is finite on every
    rank (collective)."""
    p = sim.particles
    ok = bool(all(np.all(np.isfinite(a)) for a in (p.x, p.v, p.stress, p.F, p.V)))
    return bool(common.gmin(sim.comm, int(ok)))


def min_det_F(sim):
    """Smallest det F over all particles (collective)."""
    p = sim.particles
    local = float(np.min(np.linalg.det(p.F))) if len(p) else math.inf
    return common.gmin(sim.comm, local)


def total_energy(sim):
    e = sim.energy()
    return e["kinetic"] + e["strain"]


def _outcome(err):
    """'completed' or 'ExceptionType: message' (first line)."""
    if err is None:
        return "completed"
    return f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"


def _config(sim, **extra):
    integ = sim.integrator
    cfg = dict(integrator=type(integ).__name__, scheme=getattr(integ, "scheme", type(integ).__name__),
               shape=SHAPE, h=sim.grid.h, dt=sim.dt, ppc=4,
               cell_type="quadrilateral", dt_critical=sim.dt_critical,
               dt_over_dt_critical=sim.dt / sim.dt_critical)
    cfg.update(extra)
    return cfg


def _destroy(sim):
    system = getattr(sim.integrator, "system", None)
    if system is not None:
        system.destroy()


# ---------------------------------------------------------------------------- bar
def bar_dt_critical(n_cells=20, comm=None):
    """The explicit critical step h / c_p of the V1 bar on n_cells cells (as Simulation
    computes it from the grid)."""
    import fenicsmpm as fm
    from ..problems.elastic import vibrating_bar
    sim, _ = vibrating_bar(fm.Explicit("MUSL"), n_cells=n_cells, cfl=0.5, comm=common.world(comm),
                           shape=SHAPE)
    return sim.dt_critical


def bar_energy(integrator, steps, dt=None, dt_factor=None, n_cells=20, comm=None, force_dt=None):
    """Run the V1 bar for `steps` steps, recording E = kinetic + strain after every step.

    dt: fixed time step (default: vibrating_bar's, cfl 0.5 explicit / 5 h / c implicit);
    dt_factor: dt = dt_factor * dt_critical instead. force_dt: build with the default dt,
    then set sim.dt = force_dt * dt_critical (bypasses the explicit refusal on purpose).
    A guard's exception stops the run and is returned as `error` (the energy series ends
    there). Returns a dict with the series (E relative to E0, t in periods) and metrics."""
    from ..problems.elastic import vibrating_bar
    comm = common.world(comm)
    if dt_factor is not None:
        dt = dt_factor * bar_dt_critical(n_cells, comm)
    sim, exact = vibrating_bar(integrator, n_cells=n_cells, dt=dt, cfl=0.5, comm=comm, shape=SHAPE)
    if force_dt is not None:
        sim.dt = force_dt * sim.dt_critical
    E0 = total_energy(sim)
    E, err = [E0], None
    t0 = time.perf_counter()
    try:
        for _ in range(steps):
            sim.step()
            E.append(total_energy(sim))
    except (RuntimeError, FloatingPointError) as e:     # guards: raised on every rank
        err = e
    wall = common.gmax(comm, time.perf_counter() - t0)
    E = np.asarray(E) / E0
    T = exact["period"]
    t = sim.dt * np.arange(len(E))
    done = len(E) - 1
    if done >= 1 and t[-1] >= 2 * T:
        first = float(np.mean(E[t <= T]))
        last = float(np.mean(E[t >= t[-1] - T]))
        drift = last - first
    else:
        drift = math.nan
    its = getattr(sim.integrator, "iterations", None)
    m = dict(energy_drift=drift, abs_energy_drift=abs(drift),
             max_energy_error=float(np.max(np.abs(E - 1.0))), energy_max=float(np.max(E)),
             energy_min=float(np.min(E)), energy_end=float(E[-1]), periods=t[-1] / T,
             steps_done=done, finite=int(state_finite(sim) and bool(np.all(np.isfinite(E)))),
             E0_over_exact=E0 / exact["energy"], wall_per_step_s=wall / max(done, 1))
    if its:
        m["newton_iterations_mean"] = float(np.mean(its))
        m["newton_iterations_max"] = int(np.max(its))
    out = dict(sim=sim, exact=exact, E=E, t_over_T=t / T, error=err, outcome=_outcome(err),
               wall_s=wall, metrics=m, steps=done)
    return out


def _bar_record(name, r, **extra):
    sim = r["sim"]
    cfg = _config(sim, problem="V1 vibrating bar", cells_along=round(1.0 / r["exact"]["h"]),
                  courant=sim.dt * r["exact"]["wave_speed"] / r["exact"]["h"], **extra)
    rec = common.make_record(name, cfg, sim.particles.n_global(), common.global_cells(sim),
                             max(r["steps"], 1), max(r["wall_s"], 1e-9), r["metrics"])
    rec["outcome"] = r["outcome"]
    return rec


def dt_sweep(factors=SWEEP_FACTORS, steps=500, n_cells=20, comm=None, force=True):
    """Explicit MUSL bar at dt = f dt_critical for each f. Returns rows: factor, accepted,
    refusal message, and for accepted factors the energy metrics of `steps` steps; for
    refused ones (force=True) the outcome of the forced run."""
    import fenicsmpm as fm
    from ..problems.elastic import vibrating_bar
    comm = common.world(comm)
    dt_crit = bar_dt_critical(n_cells, comm)
    rows = []
    for f in factors:
        row = dict(factor=float(f), dt=f * dt_crit, dt_critical=dt_crit)
        try:
            vibrating_bar(fm.Explicit("MUSL"), n_cells=n_cells, dt=f * dt_crit, comm=comm,
                          shape=SHAPE)
            row.update(accepted=True, message="")
        except ValueError as e:
            row.update(accepted=False, message=str(e))
        if row["accepted"]:
            r = bar_energy(fm.Explicit("MUSL"), steps, dt=f * dt_crit, n_cells=n_cells, comm=comm)
        elif force:
            r = bar_energy(fm.Explicit("MUSL"), steps, n_cells=n_cells, comm=comm, force_dt=f)
        else:
            r = None
        if r is not None:
            key = "" if row["accepted"] else "forced_"
            row.update({f"{key}outcome": r["outcome"],
                        f"{key}energy_max": r["metrics"]["energy_max"],
                        f"{key}energy_drift": r["metrics"]["energy_drift"],
                        f"{key}steps_done": r["steps"]})
        rows.append(row)
    return rows


def courant_sweep(courants=COURANTS, steps=200, n_cells=20, comm=None):
    """Implicit Newmark bar at dt = C h / c. Returns rows with the energy metrics."""
    import fenicsmpm as fm
    comm = common.world(comm)
    rows = []
    for c in courants:
        r = bar_energy(fm.Newmark(), steps, dt_factor=c, n_cells=n_cells, comm=comm)
        m = r["metrics"]
        rows.append(dict(courant=float(c), dt=r["sim"].dt,
                         dt_over_dt_critical=r["sim"].dt / r["sim"].dt_critical,
                         outcome=r["outcome"], steps_done=r["steps"], periods=m["periods"],
                         energy_max=m["energy_max"], energy_end=m["energy_end"],
                         energy_drift=m["energy_drift"], finite=m["finite"],
                         newton_iterations_max=m.get("newton_iterations_max"),
                         E=r["E"], t_over_T=r["t_over_T"]))
        _destroy(r["sim"])
    return rows


# ---------------------------------------------------------------------------- collapse
def collapse(n_rows=10, load=COLLAPSE_LOAD, comm=None, ramp_transits=None, hold_transits=None,
             flip=None, per_cell=2, record_every=1):
    """Neo-Hookean block collapsing under gravity on a fixed base between roller walls.

    Gravity is ramped linearly (updated every 10 steps through sim.start_stage) to
    g = load E / (rho H) over `ramp_transits` P-wave transits and held for `hold_transits`.
    After every step: compaction 1 - sum V / sum V0, min det F and the finiteness of the
    state are recorded (collective). A guard's RuntimeError / FloatingPointError stops the
    run and is returned in `error`. Returns a dict (series, metrics, sim)."""
    import fenicsmpm as fm
    from dolfinx import mesh as dmesh
    comm = common.world(comm)
    P = dict(COLLAPSE)
    if ramp_transits is not None:
        P["ramp_transits"] = ramp_transits
    if hold_transits is not None:
        P["hold_transits"] = hold_transits
    if flip is not None:
        P["flip"] = flip
    H, W = P["height"], P["width"]
    h = H / n_rows
    nx = max(1, int(round(W / h)))
    W = nx * h
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [W, H + h]], [nx, n_rows + 1],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.NeoHookean(E=P["E"], nu=P["nu"], density=P["density"])
    pts = fm.Particles.fill(grid, mat, per_cell=per_cell, region=lambda x: x[:, 1] < H)
    sim = fm.Simulation(grid, pts, fm.Explicit("MUSL", flip=P["flip"]), dt="auto", cfl=P["cfl"],
                        shape=SHAPE)
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], W), [0])
    p = sim.particles
    V0 = float(p.total(p.V0))
    g_end = load * P["E"] / (P["density"] * H)
    transit = H / mat.p_wave_speed
    n_ramp = max(10, int(math.ceil(P["ramp_transits"] * transit / sim.dt)))
    n_hold = int(math.ceil(P["hold_transits"] * transit / sim.dt))
    comp, detF, t, err = [0.0], [1.0], [0.0], None
    finite = True
    t0 = time.perf_counter()
    try:
        for k in range(n_ramp + n_hold):
            if k % 10 == 0:
                g = g_end * min(1.0, (k + 10) / n_ramp)
                sim.start_stage(gravity=(0.0, -g), initial_stress=False, reset_displacement=False)
            sim.step()
            if (k + 1) % record_every == 0 or k + 1 == n_ramp + n_hold:
                comp.append(1.0 - float(p.total(p.V)) / V0)
                detF.append(min_det_F(sim))
                t.append(sim.t)
                finite = finite and state_finite(sim)
    except (RuntimeError, FloatingPointError) as e:
        err = e
    wall = common.gmax(comm, time.perf_counter() - t0)
    finite_end = state_finite(sim)
    comp, detF = np.asarray(comp), np.asarray(detF)
    m = dict(compaction_max=float(np.max(comp)), compaction_end=float(comp[-1]),
             min_det_F=float(np.min(detF)), finite_throughout=int(finite and finite_end),
             finite_at_end=int(finite_end), steps_done=sim.step_count,
             steps_planned=n_ramp + n_hold, load_rho_g_H_over_E=load, gravity=g_end,
             wall_per_step_s=wall / max(sim.step_count, 1))
    return dict(sim=sim, compaction=comp, det_F=detF, t=np.asarray(t), error=err,
                outcome=_outcome(err), metrics=m, wall_s=wall, steps=sim.step_count,
                n_ramp=n_ramp, n_hold=n_hold)


# ---------------------------------------------------------------------------- impact
def discs(material, integrator, n_cells=20, per_cell=2, speed=0.1, comm=None):
    """The L2 geometry of problems.elastic.colliding_discs (discs of radius 0.2 centred at
    (0.2, 0.2) and (0.8, 0.8), velocities +-(speed, speed), unit square, dt = "auto" at
    cfl 0.5) with another material, built through the public API."""
    import fenicsmpm as fm
    from dolfinx import mesh as dmesh
    comm = common.world(comm)
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [n_cells, n_cells],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    c = np.array([[0.2, 0.2], [0.8, 0.8]])
    v = np.array([speed, speed])
    pts = (fm.Particles.fill(grid, material, per_cell, velocity=v,
                             region=lambda x: np.linalg.norm(x - c[0], axis=1) < 0.2)
           + fm.Particles.fill(grid, material, per_cell, velocity=-v,
                               region=lambda x: np.linalg.norm(x - c[1], axis=1) < 0.2))
    sim = fm.Simulation(grid, pts, integrator, dt="auto", cfl=0.5, shape=SHAPE)
    contact = (np.linalg.norm(c[1] - c[0]) - 0.4) / (2 * speed * np.sqrt(2))
    return sim, dict(contact_time=contact)


def impact(scheme="MUSL", n_cells=20, speed_factor=IMPACT_SPEED_FACTOR, t_end=IMPACT_T_END,
           comm=None, material=None):
    """Colliding discs (BENCHMARKS L2) at speed_factor x the nominal 0.1 m/s per component.

    material: None (the builder's LinearElastic) or another material on the same geometry
    (see `discs`), e.g. fm.NeoHookean(E=1000, nu=0.3, density=1000). After every step: the total momentum
    (|sum m v| / sum m |v|_0), min det F, energies and state finiteness (collective).
    A guard's exception stops the run and is returned in `error`."""
    import fenicsmpm as fm
    from ..problems.elastic import colliding_discs
    comm = common.world(comm)
    speed = 0.1 * speed_factor
    if material is None:
        sim, exact = colliding_discs(fm.Explicit(scheme), n_cells=n_cells, speed=speed, comm=comm,
                                     shape=SHAPE)
    else:
        sim, exact = discs(material, fm.Explicit(scheme), n_cells=n_cells, speed=speed, comm=comm)
    p = sim.particles
    ref = float(p.total(p.mass * np.linalg.norm(p.v, axis=1)))
    steps = int(math.ceil(t_end / sim.dt - 1e-9))
    mom, detF, t, ek, es, err = [0.0], [1.0], [0.0], [], [], None
    e = sim.energy()
    ek.append(e["kinetic"])
    es.append(e["strain"])
    finite = True
    t0 = time.perf_counter()
    try:
        for _ in range(steps):
            sim.step()
            P = p.total(p.mass[:, None] * p.v) if len(p) else p.total(np.zeros((1, 2)))
            mom.append(float(np.linalg.norm(P)) / ref)
            detF.append(min_det_F(sim))
            t.append(sim.t)
            e = sim.energy()
            ek.append(e["kinetic"])
            es.append(e["strain"])
            finite = finite and state_finite(sim)
    except (RuntimeError, FloatingPointError) as e:
        err = e
    wall = common.gmax(comm, time.perf_counter() - t0)
    finite_end = state_finite(sim)
    K0 = ek[0]
    m = dict(momentum_error=float(np.max(mom)), min_det_F=float(np.min(detF)),
             finite_throughout=int(finite and finite_end), finite_at_end=int(finite_end),
             steps_done=sim.step_count, steps_planned=steps,
             kinetic_min_over_K0=float(np.min(ek) / K0),
             energy_max_over_K0=float(np.max(np.add(ek, es)) / K0),
             energy_end_over_K0=float((ek[-1] + es[-1]) / K0),
             contact_time=exact["contact_time"], wall_per_step_s=wall / max(sim.step_count, 1))
    return dict(sim=sim, exact=exact, momentum=np.asarray(mom), det_F=np.asarray(detF),
                t=np.asarray(t), kinetic=np.asarray(ek) / K0, strain=np.asarray(es) / K0,
                error=err, outcome=_outcome(err), metrics=m, wall_s=wall, steps=sim.step_count)


# ---------------------------------------------------------------------------- report
def _strip(rows):
    return [{k: v for k, v in r.items() if k not in ("E", "t_over_T")} for r in rows]


def plot(doc, series, path, comm):
    fig, axes = common.new_figure(ncols=2, nrows=2, size=(6.2, 4.2))
    ax = axes[0, 0]
    for name, (tT, E) in series["bar"].items():
        ax.plot(tT, E, lw=0.6, label=name)
    ax.set_xlabel("t / T (periods)")
    ax.set_ylabel("E / E0")
    ax.set_title("V1 bar: total energy over the long runs", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(True, lw=0.3, alpha=0.5)

    ax = axes[0, 1]
    sw = doc["dt_sweep"]
    acc = [r for r in sw if r["accepted"]]
    ref = [r for r in sw if not r["accepted"]]
    ax.plot([r["factor"] for r in acc], [r["energy_max"] for r in acc], "o-",
            label="explicit MUSL, accepted: max E/E0")
    if ref:
        fy = [r.get("forced_energy_max") for r in ref]
        ax.plot([r["factor"] for r in ref], [math.nan if y is None else min(y, 2.0) for y in fy],
                "x", color="C3", ms=8, label="explicit, refused (ValueError); forced: max E/E0 "
                                            "(clipped at 2)")
    cs = doc["courant_sweep"]
    ax.plot([r["courant"] for r in cs], [r["energy_max"] for r in cs], "s-", color="C2",
            label="Newmark: max E/E0")
    ax.plot([r["courant"] for r in cs], [r["energy_end"] for r in cs], "v--", color="C2",
            label="Newmark: E_end/E0")
    ax.axvline(1.0, color="k", lw=0.6, ls="--")
    ax.set_xscale("log")
    ax.set_xlabel("dt / dt_critical  (= Courant number c dt / h on the bar)")
    ax.set_ylabel("E / E0")
    ax.set_title("V1 bar: time-step sweeps", fontsize=9)
    ax.legend(fontsize=6, loc="lower left")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)

    ax = axes[1, 0]
    for name, (t, comp, detF) in series["collapse"].items():
        ax.plot(t, comp, lw=1.0, label=f"{name}: compaction")
        ax.plot(t, detF, lw=0.8, ls="--", label=f"{name}: min det F")
    ax.axhline(0.8, color="k", lw=0.5, ls=":")
    ax.set_xlabel("t [s]")
    ax.set_title("neo-Hookean block collapse (confined, fixed base)", fontsize=9)
    ax.legend(fontsize=6)
    ax.grid(True, lw=0.3, alpha=0.5)

    ax = axes[1, 1]
    for name, (t, mom, kin, strain) in series["impact"].items():
        ax.plot(t, kin, lw=1.0, label=f"{name}: kinetic / K0")
        ax.plot(t, strain, lw=1.0, ls="--", label=f"{name}: strain / K0")
    ax.set_xlabel("t [s]")
    ax.set_title(f"discs at {IMPACT_SPEED_FACTOR:g}x speed; max |P| / sum m|v0| = "
                 f"{max(r['metrics']['momentum_error'] for r in doc['impact']):.1e}", fontsize=9)
    ax.legend(fontsize=6)
    ax.grid(True, lw=0.3, alpha=0.5)
    return common.save_figure(fig, path, comm, title=common.figure_title(doc, "stability"))


def print_report(doc, comm):
    bar = [r for r in doc["runs"] if r["name"].startswith("bar-")]
    common.print_table(bar, [("run", "name"), ("steps", "steps"),
                             ("dt/dt_crit", lambda r: r["config"]["dt_over_dt_critical"]),
                             ("periods", lambda r: r["metrics"]["periods"]),
                             ("energy drift", lambda r: r["metrics"]["energy_drift"]),
                             ("max |E-E0|/E0", lambda r: r["metrics"]["max_energy_error"]),
                             ("E_end/E0", lambda r: r["metrics"]["energy_end"]),
                             ("wall [s]", "wall_s")], comm,
                       title=common.table_title(doc) + "\nV1 bar, long runs "
                             f"(drift: mean E over the last period - over the first, / E0)")
    common.print_table(doc["dt_sweep"], [
        ("dt/dt_crit", "factor"), ("accepted", lambda r: "yes" if r["accepted"] else "REFUSED"),
        ("outcome", lambda r: (r.get("outcome") or r.get("forced_outcome") or "")[:60]),
        ("max E/E0", "energy_max"), ("drift", "energy_drift"),
        ("forced max E/E0", "forced_energy_max"), ("forced steps", "forced_steps_done")], comm,
        title="explicit dt sweep (refused runs forced with sim.dt to show the real margin)")
    common.print_table(doc["courant_sweep"], [
        ("Courant", "courant"), ("outcome", lambda r: r["outcome"][:40]),
        ("periods", "periods"), ("max E/E0", "energy_max"), ("E_end/E0", "energy_end"),
        ("newton max", "newton_iterations_max")], comm, title="implicit Newmark Courant sweep")
    common.print_table(doc["collapse"], [
        ("run", "name"), ("rho g H/E", lambda r: r["metrics"]["load_rho_g_H_over_E"]),
        ("max compaction", lambda r: r["metrics"]["compaction_max"]),
        ("min det F", lambda r: r["metrics"]["min_det_F"]),
        ("steps", lambda r: r["metrics"]["steps_done"]),
        ("finite", lambda r: r["metrics"]["finite_throughout"]),
        ("outcome", lambda r: r["outcome"][:70])], comm, title="collapse")
    common.print_table(doc["impact"], [
        ("run", "name"), ("momentum err", lambda r: r["metrics"]["momentum_error"]),
        ("min det F", lambda r: r["metrics"]["min_det_F"]),
        ("min K/K0", lambda r: r["metrics"]["kinetic_min_over_K0"]),
        ("steps", lambda r: r["metrics"]["steps_done"]),
        ("finite", lambda r: r["metrics"]["finite_throughout"]),
        ("outcome", lambda r: r["outcome"][:70])], comm, title="impact")


def run(quick=False, out="bench-results", comm=None, verbose=True, **sizes):
    """Run the case, write out/stability.json and out/stability.png, print the tables.
    `sizes` override SIZES[quick or full] (explicit_steps, implicit_steps, sweep_steps,
    courant_steps, collapse_rows, impact_cells). Returns the result dict (every rank)."""
    import fenicsmpm as fm
    comm = common.world(comm)
    S = dict(SIZES["quick" if quick else "full"])
    unknown = set(sizes) - set(S)
    if unknown:
        raise TypeError(f"{CASE}: unknown size parameter(s) {sorted(unknown)}; known: {sorted(S)}")
    for k, v in sizes.items():
        if not (isinstance(v, (int, np.integer)) and v >= 1):
            raise ValueError(f"{CASE}: {k!r} must be a positive integer, got {v!r}")
        S[k] = int(v)
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    runs, series = [], dict(bar={}, collapse={}, impact={})

    for name, integ, steps in (("bar-explicit-MUSL", fm.Explicit("MUSL"), S["explicit_steps"]),
                               ("bar-newmark", fm.Newmark(), S["implicit_steps"])):
        say(f"{name}: {steps} steps ...")
        r = bar_energy(integ, steps, comm=comm)
        runs.append(_bar_record(name, r))
        series["bar"][name] = (r["t_over_T"], r["E"])
        _destroy(r["sim"])
        say(f"    drift {r['metrics']['energy_drift']:+.3e}, max |E-E0|/E0 "
            f"{r['metrics']['max_energy_error']:.3e}, {r['outcome']}")

    say(f"dt sweep {SWEEP_FACTORS} x dt_critical, {S['sweep_steps']} steps each ...")
    sweep = dt_sweep(SWEEP_FACTORS, S["sweep_steps"], comm=comm)
    say(f"Courant sweep {COURANTS}, {S['courant_steps']} steps each ...")
    csweep = courant_sweep(COURANTS, S["courant_steps"], comm=comm)

    coll = []
    for name, load in (("collapse", COLLAPSE_LOAD), ("collapse-overload", COLLAPSE_OVERLOAD),
                       ("collapse-inversion", COLLAPSE_INVERSION)):
        say(f"{name}: rho g H / E = {load:g}, {S['collapse_rows']} rows ...")
        r = collapse(S["collapse_rows"], load, comm=comm)
        cfg = _config(r["sim"], problem="neo-Hookean block collapse", rows=S["collapse_rows"],
                      **{k: v for k, v in COLLAPSE.items()})
        rec = common.make_record(name, cfg, r["sim"].particles.n_global(),
                                 common.global_cells(r["sim"]), max(r["steps"], 1),
                                 max(r["wall_s"], 1e-9), r["metrics"])
        rec["outcome"] = r["outcome"]
        runs.append(rec)
        coll.append(rec)
        series["collapse"][name] = (r["t"], r["compaction"], r["det_F"])
        say(f"    max compaction {r['metrics']['compaction_max']:.4f}, min det F "
            f"{r['metrics']['min_det_F']:.3g}, {r['outcome'][:90]}")

    imp = []
    cases = [(f"impact-{s}", s, None) for s in IMPACT_SCHEMES]
    for scheme in ("MUSL", "USL"):
        cases.append((f"impact-{scheme}-neo-Hookean", scheme,
                      fm.NeoHookean(E=1000.0, nu=0.3, density=1000.0)))
    for name, scheme, mat in cases:
        say(f"{name}: {S['impact_cells']}^2 cells, {IMPACT_SPEED_FACTOR:g}x speed ...")
        r = impact(scheme, S["impact_cells"], comm=comm, material=mat)
        cfg = _config(r["sim"], problem="L2 colliding discs", speed_factor=IMPACT_SPEED_FACTOR,
                      material=type(mat).__name__ if mat is not None else "LinearElastic",
                      t_end=IMPACT_T_END, cells_per_side=S["impact_cells"])
        rec = common.make_record(name, cfg, r["sim"].particles.n_global(),
                                 common.global_cells(r["sim"]), max(r["steps"], 1),
                                 max(r["wall_s"], 1e-9), r["metrics"])
        rec["outcome"] = r["outcome"]
        runs.append(rec)
        imp.append(rec)
        series["impact"][name] = (r["t"], r["momentum"], r["kinetic"][: len(r["t"])],
                                  r["strain"][: len(r["t"])])
        say(f"    momentum error {r['metrics']['momentum_error']:.2e}, min det F "
            f"{r['metrics']['min_det_F']:.3g}, {r['outcome'][:90]}")

    doc = common.result(CASE, runs, comm, quick=quick, sizes=S, dt_sweep=_strip(sweep),
                        courant_sweep=_strip(csweep), collapse=coll, impact=imp)
    common.write_result(doc, out, comm)
    series["bar"].update({f"newmark C={r['courant']:g}": (r["t_over_T"], r["E"])
                          for r in csweep if r["courant"] >= 20})
    plot(doc, series, os.path.join(out, f"{CASE}.png"), comm)
    if verbose:
        print_report(doc, comm)
    return doc
