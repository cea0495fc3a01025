"""Benchmark case `granular-collapse`: a dry granular column collapsing on a rough base against
Lube et al.'s (2005) run-out and height laws (issue 21; fenicsmpm.problems.granular_collapse).

    python -m fenicsmpm.bench granular-collapse [--quick] [--out DIR]

Rows: aspect ratios a = H0 / L0 = 0.5, 1, 2, 4 with the library's defaults (fm.Explicit(),
dt='auto', shape='auto': cpGIMP for Mohr-Coulomb on this grid since 2026-12-06, 2 x 2
particles per cell, no separation gap); the same with the soil's
fm.MohrCoulomb(separation=True) (rows a<a>-gap, the default before 2026-12-05); with the
standard family (rows a<a>-mpm, shape="mpm", the default before 2026-12-06); and with the
gap and 3 x 3 particles per cell (rows a<a>-cpgimp-ppc3), h = min(L0, H0) / 16 (quick:
a = 0.5 and 2 with the defaults, a = 2 in the other series, h = min / 8).
Metrics per row: the run-out (L_inf - L0) / L0 and final height H_inf / L0, their relative errors against
Lube's laws, the time to rest t_rest / T (T = sqrt(H0 / g); nan: still moving at 8 T), whether
the run finished, and the particle-updates per second. Writes out/granular-collapse.json and
out/granular-collapse.png (the mean speed against t / T per row, and run-out / height against
Lube's laws)."""
import os
import time

import numpy as np

from . import common

CASE = "granular-collapse"
ALL = (0.5, 1.0, 2.0, 4.0)
# series name, scene options, aspect ratios (full, quick)
SERIES = (("defaults", {}, ALL, (0.5, 2.0)),
          ("gap", dict(separation=True), ALL, (2.0,)),
          ("mpm", dict(shape="mpm"), ALL, (2.0,)),
          ("cpgimp-ppc3", dict(shape="cpgimp", per_cell=3, separation=True), ALL, (2.0,)))


def _row(a, cells, comm, series="defaults", **scene):
    """One collapse (problems.granular_collapse.collapse(a, cells, **scene)) as a bench record
    named a<a> (defaults) or a<a>-<series>."""
    from ..problems.granular_collapse import collapse
    t0 = time.perf_counter()
    r = collapse(a, cells=cells, comm=comm, **scene)
    wall = common.gmax(comm, time.perf_counter() - t0)
    m = dict(runout=r["runout"], runout_error=r["runout_error"], height=r["height"],
             height_error=r["height_error"], t_rest=r["t_rest"], t_end=r["t_end"],
             finished=float(r["finished"]),
             updates_per_s=r["particles"] * r["steps"] / max(wall, 1e-12))
    cfg = dict(integrator="Explicit", scheme="MUSL", shape=r["shape"], h=None, dt=r["dt"],
               ppc=scene.get("per_cell", 2) ** 2, cell_type="quadrilateral", aspect_ratio=a,
               cells_across=cells)
    name = f"a{a:g}" if series == "defaults" else f"a{a:g}-{series}"
    rec = common.make_record(name, cfg, r["particles"], 0, r["steps"], wall, m)
    rec["mean_speed"] = r["mean_speed"]
    rec["series"] = series
    if r["error"]:
        rec["error"] = r["error"]
    return rec


def run(quick=False, out="bench-results", comm=None, verbose=True):
    from ..problems.granular_collapse import lube_height, lube_runout
    comm = common.world(comm)
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    runs = []
    rows = [(a, series, scene) for series, scene, full, fast in SERIES
            for a in (fast if quick else full)]
    for a, series, scene in rows:
        r = _row(a, 8 if quick else 16, comm, series, **scene)
        runs.append(r)
        m = r["metrics"]
        say(f"{r['name']}: run-out {m['runout']:.3f} ({m['runout_error']:+.1%}), height "
            f"{m['height']:.3f} ({m['height_error']:+.1%}), rest at {m['t_rest']:.2f} T, "
            f"{r['wall_s']:.1f} s" + (f"; STOPPED: {r['error']}" if "error" in r else ""))
    doc = common.result(CASE, runs, comm, quick=quick,
                        targets=dict(runout_error=0.2, height_error=0.1, finished=1.0))
    common.write_result(doc, out, comm)
    common.print_table([dict(name=r["name"], particles=r["n_particles"], wall=r["wall_s"],
                             **r["metrics"]) for r in runs],
                       [("run", "name"), ("particles", "particles"), ("run-out", "runout"),
                        ("error", "runout_error"), ("height", "height"),
                        ("error ", "height_error"), ("rest / T", "t_rest"),
                        ("finished", "finished"), ("wall s", "wall")],
                       comm=comm, title=common.table_title(doc))
    fig, axes = common.new_figure(ncols=2, size=(10.0, 4.2))
    ax1, ax2 = axes[0]
    if comm.rank == 0:
        for r in runs:
            ax1.plot(r["mean_speed"]["t"], r["mean_speed"]["v"], "-", label=r["name"])
        ax1.set_xlabel("t / sqrt(H0 / g)")
        ax1.set_ylabel("mean speed [m/s]")
        ax1.legend(fontsize=7)
        aa = np.linspace(0.3, 4.5, 100)
        ax2.plot(aa, [lube_runout(x) for x in aa], "k-", lw=0.8, label="Lube: run-out")
        ax2.plot(aa, [lube_height(x) for x in aa], "k--", lw=0.8, label="Lube: height")
        for (series, *_), marks in zip(SERIES, ("os", "^v", "D<", "x+")):
            rs = [r for r in runs if r["series"] == series]
            ar = [r["config"]["aspect_ratio"] for r in rs]
            ax2.plot(ar, [r["metrics"]["runout"] for r in rs], marks[0],
                     label=f"(L_inf - L0) / L0, {series}")
            ax2.plot(ar, [r["metrics"]["height"] for r in rs], marks[1],
                     label=f"H_inf / L0, {series}")
        ax2.set_xlabel("aspect ratio a = H0 / L0")
        ax2.legend(fontsize=7)
    common.save_figure(fig, os.path.join(out, f"{CASE}.png"), comm,
                       title=common.figure_title(doc, "Granular column collapse"))
    return doc
