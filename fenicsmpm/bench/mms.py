"""Benchmark case `mms`: run time against error on V3, the axis-aligned manufactured solution
(fenicsmpm.problems.mms; BENCHMARKS.md V3, Kamojjala et al. 2013).

    python -m fenicsmpm.bench mms [--quick]

Unit square, neo-Hookean E = 1e7, nu = 0.3, rho0 = 1000, amplitude A = 0.05 (F11 between
0.69 and 1.31), 2 x 2 particles per quadrilateral cell, run to the displacement peak
t_end = 1 / (2 c). Series (integrator x shape family): explicit MUSL (dt = 0.2 h / c_p)
with every shape family ("mpm", "ugimp", "cpgimp", "cpdi1", "cpdi2"), the same on triangles
(each square split in two) with the default shape="auto" (CPDI2 there) and "mpm", "auto"
with the edge domains of Particles.fill_edges ("triangle edges": 1.5 particles a cell), both
triangle layouts with CPDI2 and the affine FLIP transfer ("MUSL aflip"), and
implicit Newmark (dt = h / c_p) with "mpm" and "cpgimp" (its shape="auto"). Cells per side
n = 8, 16, 32, 64 (quick: 4, 6, 8, 12).

Metrics per run: displacement_error and stress_error, the normalized L2 errors at the
particles (problems.mms.errors). wall_s is the time inside the time loop only; the
one-time JIT/cache loading and form compilation are absorbed by an untimed warm-up run of
each series, whose duration is reported in "jit_s" (per series); set-up (mesh, particles)
is reported as setup_s.

Output: mms.json (common schema; extra keys "convergence" (per series and metric: h, error,
wall_s, least-squares slope over the sweep and the slope of the finest pair), "summary"
(observed orders, the cheapest configuration reaching 1 % and 0.1 %), "jit_s"),
mms_convergence.png (error against h, fitted slopes in the legend), mms_pareto.png (error
against wall time with the Pareto front) and a table.

The plotting and summary helpers here are shared with `self-weight`."""
import os
import time

import numpy as np

from . import common

CASE = "mms"
SHAPES = ("mpm", "ugimp", "cpgimp", "cpdi1", "cpdi2")
CELLS = {"full": (8, 16, 32, 64), "quick": (4, 6, 8, 12)}
TARGETS = (1e-2, 1e-3)
METRICS = (("displacement_error", "displacement"), ("stress_error", "stress"))
PER_CELL = 2
CFL = 0.2
EDGES = "triangle edges"      # the triangle series with Particles.fill_edges' edge domains


def cheapest(runs, metric, target):
    """The run of least wall time whose `metric` is at most `target` (None if none)."""
    ok = [r for r in runs if r["metrics"].get(metric) is not None and r["metrics"][metric] <= target]
    return min(ok, key=lambda r: r["wall_s"]) if ok else None


def summary(runs, conv, metrics, targets=TARGETS):
    """Observed orders per series and metric, and per metric and target the cheapest run."""
    orders = [dict(series=c["series"], metric=c["metric"], slope=c["slope"],
                   slope_finest=c["slope_finest"], finest_error=c["error"][-1])
              for c in conv]
    best = []
    for metric in metrics:
        for tgt in targets:
            r = cheapest(runs, metric, tgt)
            best.append(dict(metric=metric, target=tgt, run=None if r is None else r["name"],
                             wall_s=None if r is None else r["wall_s"],
                             error=None if r is None else r["metrics"][metric]))
    return dict(orders=orders, cheapest=best)


def plot(doc, out, comm, case, metrics, title_extra="", problems=None):
    """case_convergence.png and case_pareto.png: one panel per (problem, metric)."""
    conv = doc["convergence"]
    problems = problems or [(None, [s for s in dict.fromkeys(c["series"] for c in conv)])]
    panels = [(prob, series, m, lbl) for prob, series in problems for m, lbl in metrics]
    paths = []
    for kind in ("convergence", "pareto"):
        fig, axes = common.new_figure(ncols=len(panels), size=(5.2, 4.4))
        for j, (prob, series_list, metric, mlabel) in enumerate(panels):
            ax = axes[0, j]
            allpts = []
            for series in series_list:
                c = next((c for c in conv if c["series"] == series and c["metric"] == metric), None)
                if c is None:
                    continue
                e = [np.nan if v is None else v for v in c["error"]]
                if kind == "convergence":
                    s = c["slope"]
                    ax.loglog(c["h"], e, "o-", ms=4,
                              label=f"{series}: slope {s:.2f}" if s is not None else series)
                else:
                    ax.loglog(c["wall_s"], e, "o-", ms=4, label=series)
                    allpts += list(zip(c["wall_s"], c["error"]))
            if kind == "pareto" and allpts:
                front = common.pareto_front(allpts)
                ax.loglog([allpts[i][0] for i in front], [allpts[i][1] for i in front], "k--",
                          lw=1, label="Pareto front")
            for tgt in TARGETS:
                ax.axhline(tgt, color="0.7", lw=0.6, ls=":")
            ax.set_xlabel("cell size h" if kind == "convergence" else "wall time [s] (no JIT)")
            ax.set_ylabel(f"{mlabel} error (normalized)")
            ax.set_title(f"{prob + ': ' if prob else ''}{mlabel}", fontsize=9)
            ax.grid(True, which="both", lw=0.3)
            ax.legend(fontsize=6, loc="best")
        what = "error against cell size" if kind == "convergence" else \
            "error against run time (Pareto view)"
        paths.append(common.save_figure(fig, os.path.join(out, f"{case}_{kind}.png"), comm,
                                        title=common.figure_title(doc, case, f"{title_extra}: {what}")))
    return paths


def print_summary(doc, comm, case, metrics):
    cols = [("run", "name"), ("particles", "n_particles"), ("cells", "n_cells"),
            ("steps", "steps"), ("h", lambda r: r["config"]["h"]), ("wall [s]", "wall_s")]
    cols += [(lbl + " err", (lambda m: lambda r: r["metrics"].get(m))(m)) for m, lbl in metrics]
    common.print_table(doc["runs"], cols, comm, title=common.table_title(doc))
    common.print_table(doc["summary"]["orders"],
                       [("series", "series"), ("metric", "metric"), ("order (fit)", "slope"),
                        ("order (finest pair)", "slope_finest"), ("error at finest", "finest_error")],
                       comm, title="observed order: slope of log(error) against log(h)")
    common.print_table(doc["summary"]["cheapest"],
                       [("metric", "metric"), ("target", "target"), ("cheapest run", "run"),
                        ("wall [s]", "wall_s"), ("error", "error")],
                       comm, title="cheapest configuration reaching each error target")


# ---------------------------------------------------------------------------- the MMS case
def series_list():
    """(integrator, scheme, shape, cell type): every family on quadrilaterals, and on triangles
    (the right-diagonal split of the same lattice) the default shape="auto" (CPDI2) and the
    standard family; the default CPDI2 also with the affine FLIP transfer (scheme "MUSL
    aflip": fm.Explicit("MUSL", transfer="aflip")), with both particle layouts."""
    quads = [("Explicit", "MUSL", s, "quadrilateral") for s in SHAPES]
    tris = [("Explicit", sc, s, c) for sc, s, c in
            (("MUSL", "auto", "triangle"), ("MUSL", "auto", EDGES), ("MUSL", "mpm", "triangle"),
             ("MUSL aflip", "auto", "triangle"), ("MUSL aflip", "auto", EDGES))]
    return quads + tris + [("Newmark", "Newmark", "mpm", "quadrilateral"),
                           ("Newmark", "Newmark", "cpgimp", "quadrilateral")]


def _integrator(kind, scheme):
    import fenicsmpm as fm
    order, _, transfer = scheme.partition(" ")      # "MUSL aflip": order and transfer
    return fm.Explicit(order, transfer=transfer or None) if kind == "Explicit" else fm.Newmark()


def run_one(kind, scheme, shape, cell, n_cells, comm):
    from dolfinx.mesh import CellType
    from ..problems.mms import axis_aligned, errors
    integ = _integrator(kind, scheme)
    t0 = time.perf_counter()
    fill = "edges" if cell == EDGES else "cells"
    sim, ex = axis_aligned(integ, n_cells=n_cells, per_cell=PER_CELL, shape=shape, cfl=CFL,
                           comm=comm, cell_type=getattr(CellType, cell.split()[0]), fill=fill)
    setup = common.gmax(comm, time.perf_counter() - t0)
    wall, _ = common.timed_run(sim, ex.steps)
    err = errors(sim, ex)
    n = sim.particles.n_global()
    m = dict(displacement_error=err["displacement"], stress_error=err["stress"], setup_s=setup,
             wall_per_particle_step_s=wall / (n * ex.steps))
    if not integ.explicit:
        m["newton_iterations_mean"] = float(np.mean(integ.iterations))
        integ.system.destroy()
    series = f"{kind}-{scheme} {shape}" if kind == "Explicit" else f"Newmark {shape}"
    if cell != "quadrilateral":
        series += f" {cell}"
    cfg = dict(problem="V3 MMS axis-aligned", integrator=kind, scheme=scheme.split()[0],
               transfer=getattr(integ, "transfer", None), shape=sim.shape,
               h=ex.h, dt=ex.dt, ppc=n / common.gsum(comm, sim.grid.n_owned_cells),
               fill=fill, cell_type=cell.split()[0], cells_along=n_cells,
               A=ex.A, E=ex.E, nu=ex.nu, density=ex.rho, t_end=ex.t_end,
               dt_rule=f"{CFL:g} h / c_p" if integ.explicit else "h / c_p")
    rec = common.make_record(f"{series} n={n_cells}", cfg, n, common.gsum(comm, sim.grid.n_owned_cells),
                             ex.steps, wall, m)
    rec["series"] = series
    return rec


def run(quick=False, out="bench-results", comm=None, cells=None, series=None, verbose=True):
    """Run the case, write out/mms.json and the PNGs, print the tables; returns the result
    dict. cells overrides the cell counts per side, series the (integrator, scheme, shape)
    list."""
    comm = common.world(comm)
    cells = common.check_cells(CASE, "cells", CELLS["quick" if quick else "full"] if cells is None else cells)
    series = series_list() if series is None else list(series)
    t_start = time.perf_counter()
    runs, jit = common.sweep(series, lambda s: cells, run_one, comm, verbose and (
        lambda r: f"[{CASE}] {r['name']}: {r['steps']} steps, {r['wall_s']:.3g} s, errors u "
                  f"{r['metrics']['displacement_error']:.3e} sigma {r['metrics']['stress_error']:.3e}"))
    metrics = [m for m, _ in METRICS]
    conv = common.convergence(runs, metrics)
    doc = common.result(CASE, runs, comm, quick=quick, convergence=conv,
                        summary=summary(runs, conv, metrics), jit_s=jit,
                        total_wall_s=common.gmax(comm, time.perf_counter() - t_start))
    return common.finish(doc, out, comm, lambda d, _, c: plot(d, out, c, CASE, METRICS),
                         lambda d, c: print_summary(d, c, CASE, METRICS), verbose)
