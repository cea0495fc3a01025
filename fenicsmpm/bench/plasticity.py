"""Benchmark case `plasticity`: explicit against implicit on the Mohr-Coulomb collapse and
slope scenes (issue 7; BENCHMARKS.md L3 and L4), with run time, Newton iterations per step and
the final runout of each run.

Scenes (Mohr-Coulomb, psi = 0, plane strain, 3 x 3 particles per cell, quadrilaterals):
  collapse   L3: E = 20 MPa, nu = 0.42, rho = 1000, c = 1 kPa, phi = 42 deg, a column W = 4 m
             by H = 8 m centred on x = 0, K0 = nu / (1 - nu) initial stress, g = 9.8, from rest.
             Full: h = 0.4 m, to t = 2.5 s; quick: h = 0.8 m, to t = 1.0 s.
  slope      L4: E = 40 MPa, nu = 0.42, rho = 2000, phi = 18 deg, c = 5 kPa (unreduced),
             g = 9.81 ramped in over 4 s (gravity_ramp = 8 s, seed 002 eq 4.13) from a
             stress-free state, rollers on the sides and the base. The geometry of
             demos/slope_failure.py: 200 m x 108 m, base layer 40 m, slope 60 m high at 1V:1.5H,
             toe at x = 50 m. Full: 50 x 27 cells, to t = 12 s; quick: 20 x 11 cells, to t = 8 s.
Runs per scene:
  explicit   fm.Explicit("MUSL") with shape="auto" (cpGIMP on this grid for Mohr-Coulomb
             since 2026-12-06; the standard family before), dt = 0.5 h / c_p (collapse:
             the seed's 1 ms at full size, 2 ms quick). The collapse base is frictional: sim.add_friction(mu = 0.6).
  implicit   fm.Newmark() (beta = 1/4, gamma = 1/2, Newton with the consistent Mohr-Coulomb
             tangent, rtol 1e-6, direct LU), dt = DT_FACTOR = 10 x the explicit dt, max_dt_cuts
             = 4 (a step whose Newton fails is retried as halves). Frictional bases are
             explicit-only in fenicsmpm (sim.add_friction raises for implicit integrators),
             so the implicit collapse stands on a fully fixed (rough, no-slip) base: `fix` on
             y = 0. The two collapse runs therefore differ in the base as well as in the
             integrator: the no-slip base holds the bottom row where mu = 0.6 lets it slide.
             The slope's base is the same roller in both.
Metrics per run: wall_s (time stepping only, slowest rank; a few warm-up steps of both
integrators on the coarse column run first, untimed, to absorb numba compilation), steps
(implicit: the converged steps, halves included), s_per_step;
newton_mean / newton_max (Newton iterations per step, implicit only; 0 for explicit),
dt_cuts (implicit steps retried as halves, counted as extra steps), runout (collapse: final
spread (max x - min x - W) / 2 of the particle centres; slope: the largest horizontal
particle displacement |u_x|), crest_u (slope: displacement of the crest particle),
max_plastic_strain (MohrCoulomb state column 0), mean_speed_final (mass-weighted), finite
(1 if every particle position and stress is finite), completed (1 if the run reached t_end).
A run that stops with an error (Newton failure after the cuts, an inverted particle) is
recorded with completed = 0 and its message in "errors"."""
import math
import time

import numpy as np

from . import common
from ..collective import gmax, gmax_of, gmin_of

CASE = "plasticity"
DT_FACTOR = 10.0

COLLAPSE = dict(E=20.0e6, nu=0.42, rho=1000.0, phi=42.0, c=1.0e3, g=9.8, W=4.0, H=8.0,
                span=14.0, mu=0.6)
SLOPE = dict(E=40.0e6, nu=0.42, rho=2000.0, phi=18.0, c=5.0e3, g=9.81, L=200.0, height=108.0,
             base=40.0, slope_h=60.0, run=90.0, toe=50.0, t_ramp=4.0)
SIZES = dict(full=dict(collapse=dict(h=0.4, dt=1e-3, t_end=2.5),
                       slope=dict(cells=(50, 27), t_end=12.0)),
             quick=dict(collapse=dict(h=0.8, dt=2e-3, t_end=1.0),
                        slope=dict(cells=(20, 11), t_end=8.0)))


def build_collapse(comm, integrator, h, dt):
    """L3 column; frictional base for explicit integrators, fixed base otherwise."""
    from dolfinx import mesh as dmesh
    import fenicsmpm as fm
    from fenicsmpm.materials.initial_stress import k0_stress
    c = COLLAPSE
    nx, ny = int(round(2 * c["span"] / h)), int(round((c["H"] + 2 * h) / h))
    msh = dmesh.create_rectangle(comm, [[-c["span"], 0.0], [c["span"], ny * h]], [nx, ny],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    soil = fm.MohrCoulomb(E=c["E"], nu=c["nu"], density=c["rho"], phi=c["phi"], c=c["c"])
    pts = fm.Particles.fill(grid, soil, per_cell=3,
                            region=lambda x: (np.abs(x[:, 0]) < c["W"] / 2) & (x[:, 1] < c["H"]))
    k0_stress(pts, gravity=c["g"], surface=lambda x: np.full(len(x), c["H"]))
    sim = fm.Simulation(grid, pts, integrator, dt=dt, gravity=(0.0, -c["g"]), max_dt_cuts=4)
    base = lambda x: np.abs(x[:, 1]) < 1e-9 * h
    if integrator.explicit:
        sim.add_friction(base, mu=c["mu"], normal=(0.0, -1.0))
    else:
        sim.fix(base)
    return sim, grid


def build_slope(comm, integrator, cells, dt):
    """L4 slope at phi = 18 deg, c = 5 kPa, gravity ramped in."""
    from dolfinx import mesh as dmesh
    import fenicsmpm as fm
    s = SLOPE
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [s["L"], s["height"]]], list(cells),
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    soil = fm.MohrCoulomb(E=s["E"], nu=s["nu"], density=s["rho"], phi=s["phi"], c=s["c"])
    surf = lambda x: s["base"] + s["slope_h"] * np.clip((x - s["toe"]) / s["run"], 0.0, 1.0)
    pts = fm.Particles.fill(grid, soil, per_cell=3, region=lambda x: x[:, 1] < surf(x[:, 0]))
    sim = fm.Simulation(grid, pts, integrator, dt=dt, gravity=(0.0, -s["g"]),
                        gravity_ramp=2.0 * s["t_ramp"], max_dt_cuts=4)
    tol = 1e-6 * s["L"]
    sim.fix(lambda x: (np.abs(x[:, 0]) < tol) | (np.abs(x[:, 0] - s["L"]) < tol), [0])
    sim.fix(lambda x: np.abs(x[:, 1]) < tol, [1])
    return sim, grid


def _explicit_dt(h, E, nu, rho):
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    return 0.5 * h / math.sqrt(M / rho)


def run_scene(scene, kind, size, comm, t_end=None):
    """One run; returns (record, error message or None)."""
    import fenicsmpm as fm
    explicit = kind == "explicit"
    integ = fm.Explicit("MUSL") if explicit else fm.Newmark(rtol=1e-6)
    if scene == "collapse":
        h, dt0 = size["h"], size["dt"]
        dt = dt0 if explicit else DT_FACTOR * dt0
        sim, grid = build_collapse(comm, integ, h, dt)
    else:
        cells = size["cells"]
        h = SLOPE["L"] / cells[0]
        dt0 = _explicit_dt(h, SLOPE["E"], SLOPE["nu"], SLOPE["rho"])
        dt = dt0 if explicit else DT_FACTOR * dt0
        sim, grid = build_slope(comm, integ, cells, dt)
    t_end = size["t_end"] if t_end is None else t_end
    p = sim.particles
    crest = None
    if scene == "slope":
        crest = sim.probe((SLOPE["toe"] + SLOPE["run"], SLOPE["base"] + SLOPE["slope_h"]),
                          ["displacement"])
    error = None
    t0 = time.perf_counter()
    try:
        sim.run(t_end=t_end, progress=False)
    except (RuntimeError, FloatingPointError) as err:
        error = f"{scene}/{kind}: {err}"
    wall = gmax(comm, time.perf_counter() - t0)
    finite = comm.allreduce(bool(np.all(np.isfinite(p.x)) and np.all(np.isfinite(p.stress))))
    finite = finite == comm.size
    if scene == "collapse":
        lo = gmin_of(comm, p.x[:, 0])
        hi = gmax_of(comm, p.x[:, 0])
        runout = 0.5 * (hi - lo - COLLAPSE["W"])
        crest_u = None
    else:
        runout = gmax(comm, float(np.abs(p.u[:, 0]).max()) if len(p) else 0.0)
        d = crest.data()
        crest_u = float(np.hypot(d["displacement_x"][-1], d["displacement_y"][-1]))
    iters = list(getattr(integ, "iterations", []))
    steps = len(iters) if iters else sim.step_count
    metrics = dict(s_per_step=wall / max(steps, 1),
                   newton_mean=float(np.mean(iters)) if iters else 0.0,
                   newton_max=int(np.max(iters)) if iters else 0,
                   dt_cuts=steps - sim.step_count if iters else 0,
                   runout=runout, t_reached=float(sim.t),
                   completed=int(error is None and sim.t >= t_end - 1e-9),
                   max_plastic_strain=gmax(comm, float(p.state[:, 0].max()) if len(p) else 0.0),
                   mean_speed_final=sim.particles.mean_speed(), finite=int(finite))
    if crest_u is not None:
        metrics["crest_u"] = crest_u
    config = dict(integrator="Explicit" if explicit else "Newmark",
                  scheme="MUSL" if explicit else "Newmark", shape=sim.shape, h=h, dt=dt, ppc=3,
                  cell_type="quadrilateral", scene=scene, t_end=t_end,
                  base=("frictional mu=0.6" if explicit else "fixed (no slip)")
                  if scene == "collapse" else "rollers")
    rec = common.make_record(f"{scene}-{kind}", config, p.n_global(),
                             grid.mesh.topology.index_map(2).size_global, steps, wall, metrics)
    return rec, error


def _warmup(comm):
    """A few steps of each integrator on the coarse column, so that numba compilation and
    first-call set-up are not timed in the first run."""
    import fenicsmpm as fm
    for integ, dt in ((fm.Explicit("MUSL"), 2e-3), (fm.Newmark(rtol=1e-6), 2e-2)):
        sim, _ = build_collapse(comm, integ, 0.8, dt)
        sim.run(steps=2, progress=False)


def plot(doc, path, comm):
    fig, axes = common.new_figure(ncols=3, size=(4.6, 4.0))
    runs = doc["runs"]
    labels = [r["name"] for r in runs]
    colors = ["C0" if r["config"]["integrator"] == "Explicit" else "C1" for r in runs]
    ax = axes[0, 0]
    ax.bar(labels, [r["wall_s"] for r in runs], color=colors)
    ax.set_ylabel("wall time [s]")
    for k, r in enumerate(runs):
        ax.annotate(f"{r['steps']} steps", (k, r["wall_s"]), ha="center", va="bottom", fontsize=7)
    ax = axes[0, 1]
    ax.bar(labels, [r["metrics"]["newton_mean"] for r in runs], color=colors)
    ax.set_ylabel("Newton iterations per step (mean)")
    ax = axes[0, 2]
    ax.bar(labels, [r["metrics"]["runout"] or 0.0 for r in runs], color=colors)
    ax.set_ylabel("final runout [m]")
    for ax in axes[0]:
        ax.tick_params(axis="x", labelrotation=30, labelsize=7)
        ax.grid(alpha=0.3, axis="y")
    return common.save_figure(fig, path, comm, title=common.machine_title(doc["machine"]))


def run(quick=False, out="bench-results", comm=None, scenes=("collapse", "slope"),
        t_end=None, verbose=True):
    """Run the case, write out/plasticity.json and out/plasticity.png, print the table.
    t_end overrides every scene's end time (a tiny run for tests)."""
    import os
    comm = common.world(comm)
    size = SIZES["quick" if quick else "full"]
    runs, errors = [], []
    _warmup(comm)
    for scene in scenes:
        for kind in ("explicit", "implicit"):
            rec, err = run_scene(scene, kind, size[scene], comm, t_end=t_end)
            runs.append(rec)
            if err:
                errors.append(err)
    doc = common.result(CASE, runs, comm, quick=quick, errors=errors, dt_factor=DT_FACTOR)
    json_path = common.write_result(doc, out, comm)
    png = plot(doc, os.path.join(out, f"{CASE}.png"), comm)
    if verbose:
        common.print_table(runs, [("run", "name"), ("particles", "n_particles"),
                                  ("dt [s]", lambda r: r["config"]["dt"]),
                                  ("steps", "steps"), ("wall [s]", "wall_s"),
                                  ("s/step", lambda r: r["metrics"]["s_per_step"]),
                                  ("Newton/step", lambda r: r["metrics"]["newton_mean"]),
                                  ("max", lambda r: r["metrics"]["newton_max"]),
                                  ("runout [m]", lambda r: r["metrics"]["runout"]),
                                  ("t reached", lambda r: r["metrics"]["t_reached"]),
                                  ("done", lambda r: r["metrics"]["completed"])],
                           comm=comm, title=f"plasticity ({'quick' if quick else 'full'}), "
                                            f"{comm.size} rank(s); implicit dt = {DT_FACTOR:g} x explicit; "
                                            f"implicit collapse on a fixed base (friction is explicit-only)")
        for e in errors:
            common.say(comm, f"  stopped: {e}")
        common.say(comm, f"wrote {json_path}\n      {png}")
    return doc
