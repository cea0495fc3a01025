"""Benchmark case `friction`: rough bases and rigid contact that hold a body at rest
(issue 17; fenicsmpm.problems.friction, boundaries.friction, contact.multi_velocity).

Rows:
  rest-SCHEME-cflC   the block on a rough base (mu = 0.5), gravity from rest: largest rise of
                     its centroid above the start (must be < 0.05 mm), mean settlement over
                     the second half against STATIC, mean energy balance error
  incline-BASE-muM   30 deg, geostatic start, 0.5 s: displacement along the incline against
                     a t^2 / 2 (mu = 0.3, 0) or against the frictionless one (mu = 0.7,
                     sticks); BASE: gravity-rotated base, inclined mesh (facet normals),
                     rigid body (multi-velocity) and rigid body (penalty)
Writes out/friction.json and out/friction.png (settlement history per scheme; incline
errors per base)."""
import os
import time

import numpy as np

from . import common
from ..problems.friction import G, STATIC, block_on_base, block_on_rigid_body, incline_answer

CASE = "friction"
SCHEMES = ("USF", "USL", "MUSL", "AVG")


def _rest(scheme, cfl, t_end, h, comm):
    sim, base, hist = block_on_base(scheme, mu=0.5, cfl=cfl, h=h, comm=comm)
    sim.monitor_energy(every=50, tolerance=1.0)
    t0 = time.perf_counter()
    sim.run(t_end=t_end)
    wall = time.perf_counter() - t0
    hh = np.array(hist)
    late = hh[:, 0] > 0.5 * t_end
    err = [e["balance_error"] for e in sim.energy_history if e["t"] > 0.5 * t_end]
    m = dict(max_rise_mm=1e3 * hh[:, 2].max(), settlement_over_static=-hh[late, 2].mean() / STATIC,
             energy_balance_error=float(np.mean(err)))
    cfg = dict(integrator="Explicit", scheme=scheme, shape=sim.shape, h=h, dt=sim.dt, ppc=2,
               cell_type="quadrilateral", cfl=cfl)
    return common.make_record(f"rest-{scheme}-cfl{cfl}", cfg, sim.particles.n_global(),
                              common.global_cells(sim), sim.step_count, wall, m), hh


def _incline(base, mu, h, comm):
    t_end = 0.5
    t0 = time.perf_counter()
    if base.startswith("rigid"):
        sim, hist = block_on_rigid_body(mu, h=h, algorithm=base.split("-", 1)[1], comm=comm)
    else:
        sim, _, hist = block_on_base("MUSL", mu=mu, theta=30.0, geostatic=True, h=h,
                                     inclined_mesh=base == "inclined-mesh", comm=comm)
    sim.run(t_end=t_end)
    wall = time.perf_counter() - t0
    t, along, normal = hist[-1]
    exact = incline_answer(30.0, mu, t)
    free = incline_answer(30.0, 0.0, t)
    m = dict(displacement=along, exact=exact, lift_mm=1e3 * max(r[2] for r in hist),
             sink_mm=-1e3 * min(r[2] for r in hist),
             error=(along - exact) / exact if exact > 0 else abs(along) / free)
    cfg = dict(integrator=type(sim.integrator).__name__, scheme="MUSL", shape=sim.shape, h=h,
               dt=sim.dt, ppc=2, cell_type="quadrilateral", base=base, mu=mu)
    return common.make_record(f"incline-{base}-mu{mu}", cfg, sim.particles.n_global(),
                              common.global_cells(sim), sim.step_count, wall, m)


def run(quick=False, out="bench-results", comm=None, verbose=True):
    comm = common.world(comm)
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    h_rest, t_rest = (0.1, 1.0) if quick else (0.05, 10.0)
    h_inc = 0.1 if quick else 0.05
    runs, series = [], {}
    for scheme in SCHEMES:
        for cfl in ((0.5,) if quick or scheme == "USL" else (0.5, 0.9)):
            rec, hh = _rest(scheme, cfl, t_rest, h_rest, comm)
            runs.append(rec)
            series[rec["name"]] = hh
            say(f"{rec['name']}: rise {rec['metrics']['max_rise_mm']:.4f} mm, settlement "
                f"{rec['metrics']['settlement_over_static']:.3f} STATIC, energy "
                f"{rec['metrics']['energy_balance_error']:+.2%}, {rec['wall_s']:.1f} s")
    bases = ("base", "inclined-mesh", "rigid-multi-velocity", "rigid-penalty")
    for base in bases:
        for mu in (0.7, 0.3, 0.0):
            rec = _incline(base, mu, h_inc, comm)
            runs.append(rec)
            say(f"{rec['name']}: {1e3 * rec['metrics']['displacement']:.2f} mm against "
                f"{1e3 * rec['metrics']['exact']:.2f} mm, error {rec['metrics']['error']:+.2%}")
    doc = common.result(CASE, runs, comm, quick=quick, static_settlement_m=STATIC,
                        targets=dict(max_rise_mm=0.05, settlement=0.10, energy=0.01,
                                     stick=0.005, slide=0.02, frictionless=0.005))
    common.write_result(doc, out, comm)
    common.print_table([dict(name=r["name"], **{k: r["metrics"].get(k) for k in
                                                ("max_rise_mm", "settlement_over_static",
                                                 "energy_balance_error", "error", "sink_mm")},
                             wall=r["wall_s"]) for r in runs],
                       [("run", "name"), ("rise mm", "max_rise_mm"),
                        ("settl./static", "settlement_over_static"),
                        ("energy err", "energy_balance_error"), ("incline err", "error"),
                        ("sink mm", "sink_mm"), ("wall s", "wall")],
                       comm=comm, title=common.table_title(doc))
    fig, axes = common.new_figure(ncols=2, size=(6.5, 4.5))
    a1, a2 = axes[0]
    if comm.rank == 0:
        for name, hh in series.items():
            a1.plot(hh[:, 0], -1e3 * hh[:, 2], lw=0.8, label=name)
        a1.axhline(1e3 * STATIC, color="k", ls="--", label="static (smooth base)")
        a1.set_xlabel("t [s]")
        a1.set_ylabel("centroid settlement [mm]")
        a1.legend(fontsize=7)
        inc = [r for r in runs if r["name"].startswith("incline")]
        for k, base in enumerate(bases):
            rows = [r for r in inc if r["config"]["base"] == base]
            a2.bar(np.arange(3) + 0.2 * k, [abs(r["metrics"]["error"]) * 100 for r in rows], 0.2,
                   label=base)
        a2.set_xticks(np.arange(3) + 0.3)
        a2.set_xticklabels(["mu 0.7 (stick:\n% of free slide)", "mu 0.3 (% error)", "mu 0 (% error)"])
        a2.set_yscale("log")
        a2.axhline(2.0, color="k", ls=":", lw=0.8)
        a2.legend(fontsize=7)
        a2.set_ylabel("|error| [%]")
    common.save_figure(fig, os.path.join(out, f"{CASE}.png"), comm,
                       title=common.figure_title(doc, "rough bases and rigid contact"))
    return doc
