"""Benchmark case `accuracy`: run time against error on problems with known answers.

    python -m fenicsmpm.bench accuracy [--quick]

Problems (fenicsmpm.verification), all on quadrilaterals with 2x2 particles per cell:
  V1 vibrating bar (L = 1, E = 100, rho = 1; first mode, period T = 4 L / c = 0.4 s),
      explicit MUSL at cfl 0.2 and implicit Newmark at dt = 5 h / c, over PERIODS = 2
      periods, bar cells n = 10, 20, 40, 80, 160 (quick: 10, 20, 40), at two velocity
      amplitudes (see V1_AMPLITUDES): v0 = 0.01, where the free-end particle stays inside
      its cell on every mesh (the discretization error), and v0 = 0.1 (the V1 default),
      where from n = 40 on it crosses into the empty cell beyond the bar (standard MPM's
      cell-crossing error; amplitude_over_quarter_cell > 1 marks those runs). A probe
      follows the particle nearest the free end (initial position X). Metrics:
        period_error        |T_measured / T - 1|, T_measured from a straight-line fit of the
                            (linearly interpolated) zero crossings of the probe's velocity
                            (consecutive crossings are half a period apart; crossings less
                            than T / 4 apart, from a noisy velocity, count as one);
                            period_error_signed keeps the sign; zero_crossings (raw) and
                            zero_crossings_merged: 2 per period for a clean signal
        rms_velocity_error  RMS over the probe samples of v(t) - v0 cos(w t) sin(pi X / 2L),
                            divided by v0
        energy_drift        (E_end - E_0) / E_0, E = kinetic + strain (every step);
                            max_energy_error = max |E - E_0| / E_0
  V2 self-weight column, small strain (H = 10, rho = 2000, g = 10, E = 1e8, nu = 0:
      M = E, strain ~ 2e-3), QuasiStatic with gravity ramped over 5 load steps, column
      cells n = 5, 10, 20, 40, 80 (quick: 5, 10, 20, 40). Metrics (Y_p = x_p - u_p, the
      initial height):
        stress_error        sum_p |sigma_yy,p - sigma_a(Y_p)| V0_p / (rho g H sum_p V0_p),
                            sigma_a(y) = -rho g (H - y)  (AMPLE-style normalized error)
        top_settlement_error  |u_y - u_a(Y)| of the top particles (mean) over rho g H^2 / (2 M),
                            u_a(y) = -rho g (H y - y^2 / 2) / M: the error at the particles'
                            own height; top_settlement_vs_surface compares the same
                            settlement with the surface value rho g H^2 / (2 M) instead
        newton_iterations_max
wall_s is the time spent in Simulation.step only (set-up and the error diagnostics are not
counted; the slowest rank under MPI), the fastest of `repeats` identical runs (3; quick 2;
all kept in wall_s_repeats). An untimed warm-up run of each integrator absorbs numba's
cache loading before the first timed run.

Output: accuracy.json (common schema; extra key "convergence": per series and metric the
cell sizes, errors, wall times and the least-squares slope of log(error) against log(h)),
accuracy_convergence.png (error against cell size, log-log, fitted slope in the legend),
accuracy_pareto.png (error against wall time) and a table."""
import math
import os
import time

import numpy as np

from . import common

CASE = "accuracy"
PERIODS = 2
CFL = 0.2
NEWMARK_DT_FACTOR = 5.0
LOAD_STEPS = 5
PER_CELL = 2
# V1 amplitudes: 0.01 keeps the free-end particle (displacement amplitude v0 / w = 6.4e-4)
# inside its cell on every mesh up to n = 160 (h / 4 = 1.6e-3), so the errors are those of the
# discretization; 0.1 (the default of problems.elastic.vibrating_bar, used by the tests and the
# demo) moves it by 6.4e-3, more than h / 4 from n = 40 on: it then crosses into the empty
# cell beyond the bar (standard MPM's cell-crossing error at a free surface).
V1_AMPLITUDES = (0.01, 0.1)
V2 = dict(height=10.0, density=2000.0, g=10.0, E=1e8, nu=0.0)

V1_CELLS = {"full": (10, 20, 40, 80, 160), "quick": (10, 20, 40)}
V2_CELLS = {"full": (5, 10, 20, 40, 80), "quick": (5, 10, 20, 40)}

# metrics fitted against h (JSON "convergence") and the ones drawn in the plots
FITTED = {"V1": ("period_error", "rms_velocity_error", "abs_energy_drift", "max_energy_error"),
          "V2": ("stress_error", "top_settlement_error")}
PLOTTED = {"V1": (("period_error", "period"), ("rms_velocity_error", "RMS velocity")),
           "V2": (("stress_error", "stress (normalized L1)"),
                  ("top_settlement_error", "top settlement"))}


def zero_crossings(t, v, merge=0.0):
    """Times of the sign changes of v(t), linearly interpolated. Crossings closer than
    `merge` to the previous one are merged into one (their mean): a noisy signal chattering
    around zero counts as one crossing."""
    t, v = np.asarray(t, dtype=float), np.asarray(v, dtype=float)
    i = np.flatnonzero(np.sign(v[:-1]) * np.sign(v[1:]) < 0)
    tz = t[i] - v[i] * (t[i + 1] - t[i]) / (v[i + 1] - v[i])
    if merge <= 0 or len(tz) < 2:
        return tz
    groups = [[tz[0]]]
    for x in tz[1:]:
        if x - groups[-1][-1] < merge:
            groups[-1].append(x)
        else:
            groups.append([x])
    return np.array([np.mean(g) for g in groups])


def measured_period(t, v, merge=0.0):
    """Period from a straight-line fit of the zero crossings of v(t) (consecutive crossings
    are half a period apart; see zero_crossings for `merge`); nan with fewer than two."""
    tz = zero_crossings(t, v, merge)
    if len(tz) < 2:
        return math.nan
    return 2.0 * np.polyfit(np.arange(len(tz)), tz, 1)[0]


def _integrator(series):
    import fenicsmpm as fm
    if series == "explicit-MUSL":
        return fm.Explicit("MUSL")
    if series == "Newmark":
        return fm.Newmark()
    return fm.QuasiStatic(load_steps=LOAD_STEPS)


def _best_of(repeats, fn, *args):
    """common.best_of, with wall_per_step_s of the fastest repetition."""
    rec = common.best_of(repeats, fn, *args)
    rec["metrics"]["wall_per_step_s"] = rec["wall_s"] / rec["steps"]
    return rec


def run_v1(series, n_cells, comm, periods=PERIODS, v0=V1_AMPLITUDES[0], repeats=1):
    """V1 vibrating bar: the record (wall time: fastest of `repeats` identical runs)."""
    return _best_of(repeats, _run_v1, series, n_cells, comm, periods, v0)


def run_v2(n_cells, comm, repeats=1):
    """V2 self-weight column on quadrilaterals: the record (fastest of `repeats` runs)."""
    return _best_of(repeats, _run_v2, n_cells, comm)


def _run_v1(series, n_cells, comm, periods, v0):
    from ..problems.elastic import vibrating_bar
    integ = _integrator(series)
    t0 = time.perf_counter()
    sim, exact = vibrating_bar(integ, n_cells=n_cells, per_cell=PER_CELL, cfl=CFL, v0=v0,
                               comm=comm)
    L, h, T = 1.0, exact["h"], exact["period"]
    probe = sim.probe((L, h / 2), fields=("velocity", "position"))
    setup = common.gmax(comm, time.perf_counter() - t0)

    def energy():
        e = sim.energy()
        return e["kinetic"] + e["strain"]

    E0 = energy()
    steps = int(math.ceil(periods * T / sim.dt - 1e-9))
    wall, E = common.timed_run(sim, steps, energy)
    E = np.array([E0] + E)
    d = probe.data()
    X = d["position_x"][0]
    Tm = measured_period(d["t"], d["velocity_x"], merge=T / 4)
    v_exact = exact["velocity"](X, d["t"])
    rms = float(np.sqrt(np.mean((d["velocity_x"] - v_exact) ** 2)) / v0)
    amplitude = v0 / exact["omega"]
    drift = (E[-1] - E0) / E0
    m = dict(period_error=abs(Tm / T - 1.0), period_error_signed=Tm / T - 1.0,
             period_s=Tm, exact_period_s=T, rms_velocity_error=rms, energy_drift=drift,
             abs_energy_drift=abs(drift), max_energy_error=float(np.max(np.abs(E - E0)) / E0),
             zero_crossings=len(zero_crossings(d["t"], d["velocity_x"])),
             zero_crossings_merged=len(zero_crossings(d["t"], d["velocity_x"], T / 4)),
             probe_X=X, probe_max_displacement=float(np.max(np.abs(d["position_x"] - X))),
             displacement_amplitude=amplitude, amplitude_over_quarter_cell=amplitude / (h / 4),
             setup_s=setup, wall_per_step_s=wall / steps,
             dt_over_dt_critical=sim.dt / sim.dt_critical)
    if not integ.explicit:
        m["newton_iterations_mean"] = float(np.mean(integ.iterations))
    cfg = dict(problem="V1 vibrating bar", integrator=type(integ).__name__,
               scheme=getattr(integ, "scheme", "Newmark"), shape=sim.shape, h=h,
               dt=sim.dt, ppc=PER_CELL ** 2, cell_type="quadrilateral", cells_along=n_cells,
               periods=periods, length=L, E=100.0, density=1.0, v0=v0,
               dt_rule=f"cfl {CFL:g} * h / c" if integ.explicit
               else f"{NEWMARK_DT_FACTOR:g} * h / c")
    rec = common.make_record(f"V1 {series} v0={v0:g} n={n_cells}", cfg,
                             sim.particles.n_global(), common.global_cells(sim), steps, wall, m)
    rec.update(problem="V1", series=f"{series} v0={v0:g}")
    if not integ.explicit:
        integ.system.destroy()
    return rec


def _run_v2(n_cells, comm):
    from mpi4py import MPI
    from ..problems.elastic import self_weight_column
    integ = _integrator("QuasiStatic")
    t0 = time.perf_counter()
    sim, exact = self_weight_column(integ, n_cells=n_cells, per_cell=PER_CELL, comm=comm, **V2)
    setup = common.gmax(comm, time.perf_counter() - t0)
    wall, _ = common.timed_run(sim, LOAD_STEPS)
    p = sim.particles
    H, rho, g = V2["height"], V2["density"], V2["g"]
    Y = (p.x - p.u)[:, 1]
    num = common.gsum(comm, float(np.sum(np.abs(p.stress[:, 1, 1] - exact["stress_yy"](Y)) * p.V0)))
    vol = common.gsum(comm, float(np.sum(p.V0)))
    stress_error = num / (rho * g * H * vol)
    ytop = comm.allreduce(float(Y.max()) if len(Y) else -np.inf, op=MPI.MAX)
    top = np.abs(Y - ytop) < 1e-9 * H
    n_top = common.gsum(comm, int(np.count_nonzero(top)))
    uy = common.gsum(comm, float(p.u[top, 1].sum())) / n_top
    ref = exact["top_settlement"]
    m = dict(stress_error=stress_error,
             top_settlement_error=abs(uy - exact["displacement_y"](ytop)) / ref,
             top_settlement_vs_surface=abs(-uy / ref - 1.0), top_Y=ytop,
             newton_iterations_max=max(integ.iterations), setup_s=setup,
             wall_per_step_s=wall / LOAD_STEPS)
    cfg = dict(problem="V2 self-weight column (small strain)", integrator="QuasiStatic",
               scheme="QuasiStatic", shape=sim.shape, h=exact["h"], dt=sim.dt,
               ppc=PER_CELL ** 2, cell_type="quadrilateral", cells_along=n_cells,
               load_steps=LOAD_STEPS, **V2)
    rec = common.make_record(f"V2 QuasiStatic n={n_cells}", cfg, p.n_global(), common.global_cells(sim),
                             LOAD_STEPS, wall, m)
    rec.update(problem="V2", series="QuasiStatic")
    integ.system.destroy()
    return rec


def _warm_up(comm):
    """Untimed short runs of each integrator: numba's cached kernels are loaded here."""
    from ..problems.elastic import self_weight_column, vibrating_bar
    for series in ("explicit-MUSL", "Newmark"):
        integ = _integrator(series)
        sim, _ = vibrating_bar(integ, n_cells=4, per_cell=PER_CELL, cfl=CFL, comm=comm)
        sim.probe((1.0, 0.125), fields=("velocity", "position"))
        for _ in range(2):
            sim.step()
            sim.energy()
        if not integ.explicit:
            integ.system.destroy()
    integ = _integrator("QuasiStatic")
    sim, _ = self_weight_column(integ, n_cells=4, per_cell=PER_CELL, comm=comm, **V2)
    sim.step()
    integ.system.destroy()


def convergence(runs):
    """Per (problem, series, metric): cell sizes, errors, wall times, fitted slope."""
    return [c for problem, metrics in FITTED.items()
            for c in common.convergence(runs, metrics, finest=False, problem=problem)]


def _find(conv, problem, series, metric):
    for c in conv:
        if (c["problem"], c["series"], c["metric"]) == (problem, series, metric):
            return c
    return None


def _panels(doc):
    """(title, problem, [series]) per plot panel: one per V1 amplitude, one for V2."""
    conv = doc["convergence"]
    out = []
    for a in doc["v1_amplitudes"]:
        series = [x for x in dict.fromkeys(c["series"] for c in conv if c["problem"] == "V1")
                  if x.endswith(f" v0={a:g}")]
        out.append((f"V1 vibrating bar, v0 = {a:g} ({doc['periods']:g} periods)", "V1", series))
    out.append((f"V2 self-weight column (quads, {LOAD_STEPS} load steps)", "V2",
                ["QuasiStatic"]))
    return out


def plot(doc, out, comm):
    conv = doc["convergence"]
    panels = _panels(doc)
    paths = []
    for kind in ("convergence", "pareto"):
        fig, axes = common.new_figure(ncols=len(panels), size=(5.0, 4.4))
        for j, (ptitle, problem, series_list) in enumerate(panels):
            ax = axes[0, j]
            k = 0
            for series in series_list:
                for metric, mlabel in PLOTTED[problem]:
                    c = _find(conv, problem, series, metric)
                    k += 1
                    if c is None:
                        continue
                    x = np.array(c["h"] if kind == "convergence" else c["wall_s"], dtype=float)
                    y = np.array([np.nan if e is None else e for e in c["error"]], dtype=float)
                    ok = np.isfinite(y) & (y > 0) & (x > 0)
                    if not np.any(ok):
                        continue
                    name = series.split(" v0=")[0]
                    lbl = f"{name}: {mlabel}" if problem == "V1" else mlabel
                    if kind == "convergence" and c["slope"] is not None:
                        lbl += f" (slope {c['slope']:.2f})"
                    ax.loglog(x[ok], y[ok], "os^v"[(k - 1) % 4] + "-", ms=4, lw=1.2, label=lbl,
                              color=f"C{k - 1}")
            ax.set_xlabel("cell size h [m]" if kind == "convergence"
                          else "wall time in Simulation.step [s]")
            ax.set_ylabel("relative error")
            ax.set_title(ptitle, fontsize=9)
            ax.grid(True, which="both", lw=0.3, alpha=0.5)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7, loc="best")
        name = f"{CASE}_{kind}.png"
        what = "error against cell size" if kind == "convergence" else \
            "error against run time (Pareto view)"
        paths.append(common.save_figure(fig, os.path.join(out, name), comm,
                                        title=common.figure_title(doc, "accuracy", f": {what}")))
    return paths


def print_report(doc, comm):
    v1 = [r for r in doc["runs"] if r["problem"] == "V1"]
    v2 = [r for r in doc["runs"] if r["problem"] == "V2"]
    cols = [("run", "name"), ("particles", "n_particles"), ("cells", "n_cells"),
            ("steps", "steps"), ("h", lambda r: r["config"]["h"]),
            ("dt", lambda r: r["config"]["dt"]), ("wall [s]", "wall_s"),
            ("period err", lambda r: r["metrics"]["period_error_signed"]),
            ("RMS v err", lambda r: r["metrics"]["rms_velocity_error"]),
            ("energy drift", lambda r: r["metrics"]["energy_drift"]),
            ("max |dE|/E0", lambda r: r["metrics"]["max_energy_error"]),
            ("ampl/(h/4)", lambda r: r["metrics"]["amplitude_over_quarter_cell"])]
    common.print_table(v1, cols, comm, title=common.table_title(doc) + f"\nV1 vibrating bar, {PERIODS} periods "
                       f"(errors relative: period to T, RMS velocity to v0, energy to E0;\n"
                       f"ampl/(h/4) > 1: the free-end particle crosses into the empty cell beyond "
                       f"the bar)")
    cols = [("run", "name"), ("particles", "n_particles"), ("cells", "n_cells"),
            ("steps", "steps"), ("h", lambda r: r["config"]["h"]), ("wall [s]", "wall_s"),
            ("stress err", lambda r: r["metrics"]["stress_error"]),
            ("settlement err", lambda r: r["metrics"]["top_settlement_error"]),
            ("vs surface", lambda r: r["metrics"]["top_settlement_vs_surface"]),
            ("newton max", lambda r: r["metrics"]["newton_iterations_max"])]
    common.print_table(v2, cols, comm, title="V2 self-weight column (stress: sum |s - s_a| V0 / "
                       "(rho g H V); settlement: over rho g H^2 / 2M)")
    rows = [dict(c, slope=c["slope"]) for c in doc["convergence"]]
    common.print_table(rows, [("problem", "problem"), ("series", "series"), ("metric", "metric"),
                              ("finest h", lambda c: c["h"][-1]),
                              ("error at finest", lambda c: c["error"][-1]),
                              ("slope vs h", "slope")], comm,
                       title="convergence: least-squares slope of log(error) against log(h)")


def run(quick=False, out="bench-results", comm=None, v1_cells=None, v2_cells=None,
        periods=PERIODS, v1_amplitudes=V1_AMPLITUDES, repeats=None, verbose=True):
    """Run the case, write out/accuracy.json and the two PNGs, print the tables; returns the
    result dict (on every rank). v1_cells / v2_cells override the cell counts (a tiny run:
    v1_cells=(10, 20), v2_cells=(5, 10)), v1_amplitudes the V1 velocity amplitudes v0."""
    comm = common.world(comm)
    mode = "quick" if quick else "full"
    v1_cells = tuple(V1_CELLS[mode] if v1_cells is None else v1_cells)
    v2_cells = tuple(V2_CELLS[mode] if v2_cells is None else v2_cells)
    for name, cells in (("v1_cells", v1_cells), ("v2_cells", v2_cells)):
        if not cells or any(not (isinstance(n, (int, np.integer)) and n >= 1) for n in cells):
            raise ValueError(f"{CASE}: {name!r} must be positive integers, got {cells!r}")
    repeats = (2 if quick else 3) if repeats is None else repeats
    if not (isinstance(repeats, int) and repeats >= 1):
        raise ValueError(f"{CASE}: 'repeats' must be a positive integer, got {repeats!r}")
    v1_amplitudes = tuple(float(a) for a in v1_amplitudes)
    if not v1_amplitudes or not all(a > 0 for a in v1_amplitudes):
        raise ValueError(f"{CASE}: 'v1_amplitudes' must be positive, got {v1_amplitudes!r}")
    if not (isinstance(periods, (int, float)) and periods >= 1):
        raise ValueError(f"{CASE}: 'periods' must be >= 1, got {periods!r}")
    t_start = time.perf_counter()
    load_start = common._load_average()
    _warm_up(comm)
    runs = []
    for v0 in v1_amplitudes:
        for series in ("explicit-MUSL", "Newmark"):
            for n in v1_cells:
                runs.append(run_v1(series, n, comm, periods, v0, repeats))
                if verbose:
                    r = runs[-1]
                    common.say(comm, f"[{CASE}] V1 {series} v0={v0:g} n={n}: {r['steps']} "
                               f"steps, {r['wall_s']:.3g} s, period error "
                               f"{r['metrics']['period_error_signed']:+.3e}")
    for n in v2_cells:
        runs.append(run_v2(n, comm, repeats))
        if verbose:
            r = runs[-1]
            common.say(comm, f"[{CASE}] V2 n={n}: {r['wall_s']:.3g} s, stress error "
                       f"{r['metrics']['stress_error']:.3e}")
    doc = common.result(CASE, runs, comm, quick=quick, periods=periods,
                        v1_amplitudes=v1_amplitudes, repeats=repeats,
                        convergence=convergence(runs),
                        total_wall_s=common.gmax(comm, time.perf_counter() - t_start),
                        load_average_1min_start=load_start)
    return common.finish(doc, out, comm, lambda d, _, c: plot(d, out, c), print_report, verbose)
