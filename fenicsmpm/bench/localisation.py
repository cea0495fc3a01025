"""Benchmark case `localisation` (issue 19): softening with and without the nonlocal
regularisation (fenicsmpm.materials.regularisation) on the W5 strip footing pushed to failure
and on the periodic shear layer (fenicsmpm.problems.localisation), per cell size h
(footing: h = 0.125 / 0.0625 / 0.03125 m, quick 0.25 / 0.125; layer: 0.01 / 0.005 m), and
the run-out of a softening Mohr-Coulomb slope (fenicsmpm.problems.softening_slope, explicit
defaults, l = 1.25 m; h = H/8, H/16, H/32, H/64, quick H/8, H/16).

Per run: the pressure-settlement (footing) or tau-u (layer) curve, its peak, the band width,
Newton iterations (mean, max), completion, and the cost of the nonlocal averaging as a
fraction of the step wall time.  Spread: the largest difference between the curves of the
meshes of a series, over the settlements every run of the series reached, relative to the
series' largest peak; slope: the run-out difference of the two finest meshes relative to
the finer one's run-out.  Writes out/localisation.json and out/localisation.png."""
import numpy as np

from . import common
from ..problems import softening_slope
from ..problems.localisation import shear_layer, strip_footing

CASE = "localisation"
FOOTING_L, LAYER_L, SLOPE_L = 0.25, 0.02, 1.25
SIZES = {"quick": dict(footing=(0.25, 0.125), layer=(0.01, 0.005), slope=(8, 16)),
         "full": dict(footing=(0.125, 0.0625, 0.03125), layer=(0.01, 0.005), slope=(8, 16, 32, 64))}
# the footing: its top particle row pushed by penalty (it keeps holding the soil after more
# than a cell of settlement, unlike a node footing), the ghost penalty of poorly filled cells
# (Newton at the footing edge), Newton with line search to rtol 1e-6 (in the softening band
# the full step cycles at |R|/|f| ~ 1e-4); docs/guide/choosing.md "Implicit W5 footing"
FOOTING = dict(footing="particles", ghost=0.01, line_search=6, rtol=1e-6)


def _spread(curves):
    """max_k |y_a(s_k) - y_b(s_k)| / max peak over the common range of abscissae s."""
    if len(curves) < 2:
        return None
    s_end = min(s[-1] for s, _ in curves)
    grid = np.linspace(0.0, s_end, 200)
    ys = [np.interp(grid, s, y) for s, y in curves]
    peak = max(float(np.max(y)) for _, y in curves)
    return float(max(np.max(np.abs(a - b)) for i, a in enumerate(ys) for b in ys[i + 1:]) / peak)


def _record(scene, r, length, steps, x, y):
    newton = r["newton"] or [0]
    m = dict(completed=int(r["completed"]), peak=float(np.max(y)), end_value=float(y[-1]),
             end_abscissa=float(x[-1]), band_width=r["band_width"], eps_max=r["eps_max"],
             newton_mean=float(np.mean(newton)), newton_max=int(np.max(newton)),
             nonlocal_s=r["nonlocal_s"], nonlocal_fraction=r["nonlocal_s"] / max(r["wall_s"], 1e-300))
    # n_cells: the cells holding soil (2 x 2 particles each)
    cfg = dict(integrator="QuasiStatic", scheme="Newton", shape="mpm", h=r["h"], dt=1.0 / steps,
               ppc=4, cell_type="quadrilateral", scene=scene, nonlocal_length=length,
               **(FOOTING if scene == "footing" else {}))
    rec = common.make_record(f"{scene}-{'l' + format(length, 'g') if length else 'local'}-h{r['h']:g}",
                             cfg, r["n_particles"], r["n_particles"] // 4, len(r["newton"]),
                             r["wall_s"], m)
    rec["curve"] = dict(x=np.asarray(x).tolist(), y=np.asarray(y).tolist())
    rec["stopped"] = r["stopped"]
    return rec


def _slope(cells, length, comm):
    """One slope run to rest, as a bench record."""
    r = softening_slope.runout(cells, softening_slope.soil(length), comm=comm)
    m = dict(completed=int(r["finished"]), runout=r["runout"], t_rest=r["t_rest"],
             nonlocal_s=r["nonlocal_s"], nonlocal_fraction=r["nonlocal_s"] / max(r["wall_s"], 1e-300))
    cfg = dict(integrator="Explicit", scheme="default", shape="auto", h=r["h"], dt=r["dt"],
               ppc=4, cell_type="quadrilateral", scene="slope", nonlocal_length=length)
    rec = common.make_record(f"slope-{'l' + format(length, 'g') if length else 'local'}-H/{cells}",
                             cfg, r["particles"], r["particles"] // 4, r["steps"], r["wall_s"], m)
    rec["stopped"] = r["error"]
    return rec


def run(quick=False, out="bench-results", comm=None, verbose=True, steps=50):
    comm = common.world(comm)
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    sizes = SIZES["quick" if quick else "full"]
    runs = []
    for length in (LAYER_L, None):
        for h in sizes["layer"]:
            r = shear_layer(h, length, comm=comm)
            runs.append(_record("layer", r, length, 60, r["u"], r["tau"]))
            say(f"layer h = {h:g}, l = {length}: {runs[-1]['metrics']}")
    for length in (FOOTING_L, None):
        for h in sizes["footing"]:
            r = strip_footing(h, length, comm=comm, steps=steps, **FOOTING)
            runs.append(_record("footing", r, length, steps, r["settlement"], r["pressure"]))
            say(f"footing h = {h:g}, l = {length}: {runs[-1]['metrics']}")
    for length in (SLOPE_L, None):
        for cells in sizes["slope"]:
            runs.append(_slope(cells, length, comm))
            say(f"slope h = H/{cells}, l = {length}: {runs[-1]['metrics']}")
    spread = {}
    for length in ("reg", "local"):
        a, b = [r["metrics"]["runout"] for r in runs if r["config"]["scene"] == "slope"
                and (r["config"]["nonlocal_length"] is None) == (length == "local")][-2:]
        spread[f"slope-{length}"] = abs(a - b) / abs(b)
    for scene in ("layer", "footing"):
        for length in ("reg", "local"):
            sel = [r for r in runs if r["config"]["scene"] == scene
                   and (r["config"]["nonlocal_length"] is None) == (length == "local")]
            spread[f"{scene}-{length}"] = _spread([(np.array(r["curve"]["x"]), np.array(r["curve"]["y"]))
                                                  for r in sel])
    doc = common.result(CASE, runs, comm, quick=quick, spread=spread,
                        notes=["footing: W5 geometry and clay, weightless, smooth rigid footing "
                               f"(its top particle row, ghost 0.01, line search 6, rtol 1e-6) pushed to 0.1 m in {steps} steps, l = {FOOTING_L} m, m = 2; "
                               "layer: periodic simple shear, 0.2 m, l = 0.02 m",
                               "slope: problems.softening_slope, explicit defaults, run to rest, "
                               f"l = {SLOPE_L} m, m = 2; runout [m] from the toe",
                               "spread: max curve difference over the common range / peak"])
    return common.finish(doc, out, comm, plot=_plot, report=_report, verbose=verbose)


def _report(doc, comm):
    common.print_table([dict(name=r["name"], done=r["metrics"]["completed"],
                             peak=r["metrics"]["peak"], end=r["metrics"]["end_abscissa"],
                             w=r["metrics"]["band_width"], nm=r["metrics"]["newton_mean"],
                             nx=r["metrics"]["newton_max"], f=r["metrics"]["nonlocal_fraction"],
                             wall=r["wall_s"]) for r in doc["runs"] if r["config"]["scene"] != "slope"],
                       [("run", "name"), ("completed", "done"), ("peak", "peak"),
                        ("reached", "end"), ("band width m", "w"), ("Newton mean", "nm"),
                        ("Newton max", "nx"), ("nonlocal/step", "f"), ("wall s", "wall")],
                       comm=comm, title=common.table_title(doc))
    common.print_table([dict(name=r["name"], done=r["metrics"]["completed"], n=r["n_particles"],
                             ro=r["metrics"]["runout"], f=r["metrics"]["nonlocal_fraction"],
                             wall=r["wall_s"]) for r in doc["runs"] if r["config"]["scene"] == "slope"],
                       [("run", "name"), ("completed", "done"), ("particles", "n"),
                        ("run-out m", "ro"), ("nonlocal/step", "f"), ("wall s", "wall")],
                       comm=comm, title="softening slope")
    if comm.rank == 0:
        print("spread (max difference / peak):", doc["spread"])


def _plot(doc, path, comm):
    fig, axes = common.new_figure(ncols=4, size=(5.0, 4.5))
    axes = axes[0]
    for ax, scene, xl, yl, sx, sy in ((axes[0], "layer", "top displacement u [mm]", "tau [kPa]", 1e3, 1e-3),
                                      (axes[1], "footing", "settlement [mm]", "pressure [kPa]", 1e3, 1e-3)):
        for r in doc["runs"]:
            if r["config"]["scene"] != scene:
                continue
            reg = r["config"]["nonlocal_length"] is not None
            ax.plot(np.array(r["curve"]["x"]) * sx, np.array(r["curve"]["y"]) * sy,
                    "-" if reg else "--", marker="" if r["metrics"]["completed"] else "x",
                    markevery=[-1], label=f"h = {r['config']['h']:g}, "
                    + (f"l = {r['config']['nonlocal_length']:g}" if reg else "local"))
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        ax.set_title(f"{scene}: spread reg {doc['spread'][scene + '-reg']}, "
                     f"local {doc['spread'][scene + '-local']}", fontsize=8)
    ax = axes[3]
    for length, style in (("reg", "o-"), ("local", "s--")):
        sel = [r for r in doc["runs"] if r["config"]["scene"] == "slope"
               and (r["config"]["nonlocal_length"] is None) == (length == "local")]
        ax.plot([softening_slope.H / r["config"]["h"] for r in sel],
                [r["metrics"]["runout"] for r in sel], style,
                label=(f"l = {SLOPE_L:g} m" if length == "reg" else "local") + ", nonlocal "
                + ", ".join(f"{100 * r['metrics']['nonlocal_fraction']:.0f}" for r in sel) + " % of step")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("H / h")
    ax.set_ylabel("run-out from the toe [m]")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax.set_title(f"softening slope: two finest differ reg {100 * doc['spread']['slope-reg']:.1f} %, "
                 f"local {100 * doc['spread']['slope-local']:.1f} %", fontsize=8)
    ax = axes[2]
    bands = [r for r in doc["runs"] if r["config"]["scene"] != "slope"]
    names = [r["name"] for r in bands]
    ax.barh(names, [r["metrics"]["band_width"] for r in bands], color="tab:blue")
    for k, r in enumerate(bands):
        ax.text(r["metrics"]["band_width"], k, f" nonlocal {100 * r['metrics']['nonlocal_fraction']:.0f} %"
                f" of step", va="center", fontsize=6)
    ax.set_xlabel("band width w [m]")
    ax.tick_params(axis="y", labelsize=6)
    common.save_figure(fig, path, comm, title=common.figure_title(doc, "localisation"))
