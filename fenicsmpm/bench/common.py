"""Shared machinery of the benchmark cases: the JSON record format, machine information, MPI
reductions, timing of simulation steps, sweeps and convergence fits, memory measurement,
table printing and plotting; `finish` writes a case's JSON, figure and table. A case module
holds only its scenes and its metrics.

Result file DIR/CASE.json (a stable format for every case):
    {"case": str,
     "quick": bool,
     "machine": {"cores", "ranks", "cpu", "platform", "versions": {dolfinx, petsc, numba,
                 numpy, python}, "timestamp" (UTC, ISO 8601), "load_average_1min"},
     "runs": [{"name": str,
               "config": {integrator, scheme, shape, h, dt, ppc, cell_type, ...},
               "n_particles": int (global), "n_cells": int (global), "steps": int,
               "wall_s": float, "metrics": {name: number}}, ...],
     ... case-specific extra keys (e.g. "targets", "peers")}
Only rank 0 writes files and prints; all numbers are global (summed over ranks, or the
slowest rank for wall-clock times)."""
import datetime
import gc
import json
import math
import os
import platform
import sys
import time

import numpy as np

from ..collective import gmax, gmin, gsum  # noqa: F401  (the bench cases call common.gmax etc.)

__all__ = ["machine_info", "make_record", "result", "write_result", "print_table",
           "format_number", "machine_title", "new_figure", "stacked_bars", "save_figure",
           "time_steps", "MemoryProbe", "particle_bytes", "say", "world", "gmax", "gmin",
           "gsum", "global_cells", "timed_run", "best_of", "fit_slope", "convergence",
           "pareto_front", "table_title", "figure_title", "finish"]


# ---------------------------------------------------------------------------- machine
def _cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _load_average():
    try:
        return round(os.getloadavg()[0], 2)
    except (OSError, AttributeError):
        return None


def machine_info(comm):
    """Cores, MPI ranks, CPU model, library versions and a UTC timestamp (no hostname), as
    rank 0 sees them (collective: every rank's document then equals the JSON rank 0 writes,
    also when the ranks' clocks or load averages tick between their calls)."""
    import dolfinx
    import numba
    from petsc4py import PETSc
    info = None
    if comm.rank == 0:
        info = {
            "cores": os.cpu_count(),
            "ranks": comm.size,
            "cpu": _cpu_model(),
            "platform": f"{platform.system()} {platform.release()} {platform.machine()}",
            "versions": {
                "dolfinx": dolfinx.__version__,
                "petsc": ".".join(str(v) for v in PETSc.Sys.getVersion()),
                "numba": numba.__version__,
                "numpy": np.__version__,
                "python": platform.python_version(),
            },
            "timestamp": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            # other load on the machine when the case started (timings are wall-clock)
            "load_average_1min": _load_average(),
        }
    return comm.bcast(info, root=0) if comm.size > 1 else info


def machine_title(machine):
    """One-line description for plot titles."""
    v = machine["versions"]
    return (f"{machine['cpu']}, {machine['cores']} cores, {machine['ranks']} rank(s) | "
            f"dolfinx {v['dolfinx']}, PETSc {v['petsc']}, numba {v['numba']}, "
            f"numpy {v['numpy']}, Python {v['python']} | {machine['timestamp']}"
            + (f", load {machine['load_average_1min']:g}"
               if machine.get("load_average_1min") is not None else ""))


# ---------------------------------------------------------------------------- records
def _clean(obj):
    """JSON-safe copy: numpy scalars/arrays to Python, non-finite floats to None."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if obj is None or isinstance(obj, str):
        return obj
    return str(obj)


REQUIRED_CONFIG = ("integrator", "scheme", "shape", "h", "dt", "ppc", "cell_type")


def make_record(name, config, n_particles, n_cells, steps, wall_s, metrics):
    """One run: its configuration and measured numbers (metrics: name -> number)."""
    missing = [k for k in REQUIRED_CONFIG if k not in config]
    if missing:
        raise ValueError(f"bench record {name!r}: config lacks {missing}")
    bad = {k: v for k, v in metrics.items()
           if not isinstance(v, (int, float, np.integer, np.floating)) or isinstance(v, bool)}
    if bad:
        raise TypeError(f"bench record {name!r}: metrics must be numbers, got {bad}")
    return _clean(dict(name=name, config=dict(config), n_particles=int(n_particles),
                       n_cells=int(n_cells), steps=int(steps), wall_s=float(wall_s),
                       metrics=dict(metrics)))


def result(case, runs, comm, quick=False, **extra):
    """The result dict of a case (the JSON document)."""
    doc = dict(case=case, quick=bool(quick), machine=machine_info(comm), runs=list(runs))
    doc.update(extra)
    return _clean(doc)


def write_result(doc, out, comm):
    """Write out/CASE.json on rank 0; returns its path (on every rank)."""
    path = os.path.join(out, f"{doc['case']}.json")
    if comm.rank == 0:
        os.makedirs(out, exist_ok=True)
        tmp = path + ".tmp"
        with open(tmp, "w") as f:
            json.dump(doc, f, indent=1, allow_nan=False)
            f.write("\n")
        os.replace(tmp, path)
    if comm.size > 1:
        comm.barrier()
    return path


def finish(doc, out, comm, plot=None, report=None, verbose=True):
    """Write out/CASE.json, then plot(doc, out/CASE.png, comm) and, when verbose,
    report(doc, comm); returns doc."""
    write_result(doc, out, comm)
    if plot is not None:
        plot(doc, os.path.join(out, f"{doc['case']}.png"), comm)
    if verbose and report is not None:
        report(doc, comm)
    return doc


# ---------------------------------------------------------------------------- MPI
def world(comm):
    """comm, or MPI.COMM_WORLD for None."""
    from mpi4py import MPI
    return MPI.COMM_WORLD if comm is None else comm


def global_cells(sim):
    """Number of cells of the mesh (owned cells summed over ranks)."""
    return gsum(sim.comm, sim.grid.n_owned_cells)


# ---------------------------------------------------------------------------- sweeps and fits
def check_cells(case, name, cells, minimum=2, count=2):
    """cells as a tuple; ValueError unless at least `count` integers >= `minimum`."""
    cells = tuple(cells)
    if len(cells) < count or any(not (isinstance(n, (int, np.integer)) and n >= minimum) for n in cells):
        raise ValueError(f"{case}: {name!r} must be at least {count} integers >= {minimum}, got {cells!r}")
    return cells


def sweep(series, cells, run_one, comm, describe=None):
    """Refinement sweep: per series (a tuple of run_one's leading arguments) an untimed
    warm-up run_one(*series, n0, comm) with n0 the smallest of cells(series) (JIT / cache
    loading; its time in jit["a b c"]; at 2 cells implicit cpGIMP's Newton fails on V3), then
    run_one(*series, n, comm) for n in cells(series). describe(record): a progress line.
    Returns (runs, jit)."""
    runs, jit = [], {}
    for s in series:
        t0 = time.perf_counter()
        run_one(*s, min(cells(s)), comm)
        jit[" ".join(s)] = gmax(comm, time.perf_counter() - t0)
        for n in cells(s):
            runs.append(run_one(*s, n, comm))
            if describe:
                say(comm, describe(runs[-1]))
    return runs, jit


def best_of(repeats, fn, *args):
    """Run fn(*args) (a deterministic run returning its record) `repeats` times; the first
    record with wall_s the fastest repetition (all kept in wall_s_repeats)."""
    recs = [fn(*args) for _ in range(repeats)]
    walls = [r["wall_s"] for r in recs]
    rec = recs[0]
    rec["wall_s"] = min(walls)
    rec["wall_s_repeats"] = walls
    return rec


def fastest_call(repeats, fn):
    """Seconds of the fastest of `repeats` calls fn() after one untimed warm-up call (kernel
    timings: bench fused, gimp-factors)."""
    fn()
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def fit_slope(h, err):
    """Least-squares slope of log(err) against log(h) over the positive finite errors
    (None with fewer than two)."""
    h = np.asarray(h, dtype=float)
    e = np.array([np.nan if v is None else v for v in err], dtype=float)
    ok = np.isfinite(e) & (e > 0)
    if np.count_nonzero(ok) < 2:
        return None
    return float(np.polyfit(np.log(h[ok]), np.log(e[ok]), 1)[0])


def convergence(runs, metrics, finest=True, **tags):
    """Per (series, metric): h (coarse to fine), errors, wall times, the slope fitted over the
    sweep and (finest) the slope of the two finest runs. tags (e.g. problem="V1") select
    the runs with those keys and are copied into each entry."""
    runs = [r for r in runs if all(r.get(k) == v for k, v in tags.items())]
    out = []
    for series in dict.fromkeys(r["series"] for r in runs):
        rs = sorted((r for r in runs if r["series"] == series), key=lambda r: -r["config"]["h"])
        h = [r["config"]["h"] for r in rs]
        for metric in metrics:
            err = [r["metrics"].get(metric) for r in rs]
            c = dict(tags, series=series, metric=metric, h=h, error=err,
                     wall_s=[r["wall_s"] for r in rs], slope=fit_slope(h, err))
            if finest:
                c["slope_finest"] = fit_slope(h[-2:], err[-2:]) if len(h) > 1 else None
            out.append(c)
    return out


def pareto_front(points):
    """Indices of the points (wall, error) not dominated by another (less time and error)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] is not None and points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


# ---------------------------------------------------------------------------- printing
def table_title(doc, what=None):
    """Heading of a case's table: "== CASE (quick): N rank(s)" (what replaces the ranks)."""
    quick = " (quick)" if doc.get("quick") else ""
    return f"\n== {doc['case']}{quick}: " + (what or f"{doc['machine']['ranks']} rank(s)")


def figure_title(doc, what, tail=""):
    """Title of a case's figure: "fenicsmpm WHAT (quick)TAIL" over the machine line."""
    quick = " (quick)" if doc.get("quick") else ""
    return f"fenicsmpm {what}{quick}{tail}\n{machine_title(doc['machine'])}"


def say(comm, *args, **kw):
    """print on rank 0 (flushed)."""
    if comm.rank == 0:
        print(*args, **kw, flush=True)


def format_number(x, digits=3):
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    if isinstance(x, (int, np.integer)) and not isinstance(x, bool):
        return f"{int(x):,}"
    x = float(x)
    if not math.isfinite(x):
        return "-"
    if x != 0 and (abs(x) >= 1e5 or abs(x) < 1e-3):
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


def print_table(rows, columns, comm=None, file=None, title=None):
    """Fixed-width table. rows: list of dicts; columns: list of (header, key or callable)."""
    if comm is not None and comm.rank != 0:
        return
    file = sys.stdout if file is None else file
    cells = []
    for r in rows:
        line = []
        for _, key in columns:
            v = key(r) if callable(key) else r.get(key)
            line.append(format_number(v))
        cells.append(line)
    heads = [h for h, _ in columns]
    widths = [max([len(h)] + [len(c[j]) for c in cells]) for j, h in enumerate(heads)]
    fmt = "  ".join("{:<%d}" % w if j == 0 else "{:>%d}" % w for j, w in enumerate(widths))
    if title:
        print(title, file=file)
    print(fmt.format(*heads), file=file)
    print("  ".join("-" * w for w in widths), file=file)
    for c in cells:
        print(fmt.format(*c), file=file)
    file.flush()


# ---------------------------------------------------------------------------- plotting
def new_figure(ncols=1, nrows=1, size=(7.0, 4.5)):
    """A matplotlib figure (Agg backend, no display needed)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(nrows, ncols, figsize=(size[0] * ncols, size[1] * nrows),
                             squeeze=False)
    return fig, axes


def stacked_bars(ax, labels, stacks, annotations=None, ylabel=None, colors=None,
                 legend="outside"):
    """Stacked bar chart: one bar per label, stacks = {segment name: [value per bar]}.
    Negative values are drawn as zero; all-zero segments are left out (colours stay tied to
    the segment's position in `stacks`). annotations: text above each bar.
    legend: "outside" (right of the axes), "inside" or None."""
    import matplotlib
    x = np.arange(len(labels))
    bottom = np.zeros(len(labels))
    cmap = matplotlib.colormaps["tab10"]
    for k, (name, vals) in enumerate(stacks.items()):
        v = np.clip(np.asarray(vals, dtype=float), 0.0, None)
        if not np.any(v > 0):
            continue
        c = colors.get(name) if colors else None
        ax.bar(x, v, 0.6, bottom=bottom, label=name, color=c if c else cmap(k % 10))
        bottom += v
    if annotations:
        top = bottom.max() if len(bottom) else 1.0
        for xi, b, text in zip(x, bottom, annotations):
            ax.text(xi, b + 0.01 * top, text, ha="center", va="bottom", fontsize=8)
        ax.set_ylim(0, 1.15 * top if top > 0 else 1.0)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, rotation=15, ha="right", fontsize=8)
    if ylabel:
        ax.set_ylabel(ylabel)
    if legend == "outside":
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    elif legend:
        ax.legend(fontsize=7, loc="best")
    return bottom


def error_figure(doc, curves, ylabel, path, comm, titles=()):
    """Two log-log panels, error against cell size h and against wall time, one line per
    curve (label, style, color, runs, metric); titles: of the panels. Saved to path."""
    fig, ax = new_figure(2, 1)
    for label, style, color, runs, metric in curves:
        e = [r["metrics"][metric] for r in runs]
        ax[0, 0].loglog([r["config"]["h"] for r in runs], e, style, color=color, label=label)
        ax[0, 1].loglog([r["wall_s"] for r in runs], e, style, color=color, label=label)
    ax[0, 0].set_xlabel("cell size h [m]")
    ax[0, 1].set_xlabel("wall time [s]")
    for a in ax[0]:
        a.set_ylabel(ylabel)
        a.legend(fontsize=7)
    for a, t in zip(ax[0], titles):
        a.set_title(t, fontsize=9)
    return save_figure(fig, path, comm, title=machine_title(doc["machine"]))


def save_figure(fig, path, comm, title=None):
    """Save on rank 0 and close; returns path."""
    import matplotlib.pyplot as plt
    if comm.rank == 0:
        os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
        if title:
            fig.suptitle(title, fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=120)
    plt.close(fig)
    if comm.size > 1:
        comm.barrier()
    return path


# ---------------------------------------------------------------------------- timing
def timed_run(sim, steps, every=None):
    """Advance `steps` steps; returns the wall time inside sim.step (slowest rank) and, when
    `every` is a callable, its value after each step (called outside the timing)."""
    wall, samples = 0.0, []
    for _ in range(steps):
        t0 = time.perf_counter()
        sim.step()
        wall += time.perf_counter() - t0
        if every is not None:
            samples.append(every())
    return gmax(sim.comm, wall), samples


def time_steps(sim, steps, warmup=0):
    """Run `warmup` steps (absorbing JIT compilation), reset sim.timers, then time `steps`
    steps with time.perf_counter between barriers.

    Returns a dict: wall_s (slowest rank), cpu_s (process CPU time, summed over ranks; on a
    busy machine cpu_s / (wall_s * ranks) < 1 shows how much the run was starved) and
    timers (seconds per stage summed over the measured steps, averaged over ranks)."""
    comm = sim.comm
    for _ in range(warmup):
        sim.step()
    for k in sim.timers:
        sim.timers[k] = 0.0
    if comm.size > 1:
        comm.barrier()
    c0 = time.process_time()
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    if comm.size > 1:
        from mpi4py import MPI
        wall = comm.allreduce(wall, op=MPI.MAX)
        cpu = comm.allreduce(cpu)
        timers = {k: comm.allreduce(v) / comm.size for k, v in sim.timers.items()}
    else:
        timers = dict(sim.timers)
    return dict(wall_s=wall, cpu_s=cpu, timers=timers)


# ---------------------------------------------------------------------------- memory
def _status_kb(field):
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def _malloc_trim():
    try:
        import ctypes
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


class MemoryProbe:
    """Peak memory of a stretch of code, in bytes summed over ranks.

    On Linux the kernel's peak-RSS mark is reset at start() (/proc/self/clear_refs), so
    peak() is the peak of this stretch; `increase` is that peak minus the resident size at
    start() (what the stretch added). Elsewhere the process-lifetime ru_maxrss is used
    (an upper bound) and `exact_peak` is False."""

    def __init__(self, comm):
        self.comm = comm
        self.exact_peak = False
        self.rss0 = 0

    def start(self):
        gc.collect()
        _malloc_trim()      # hand freed heap back to the OS, so the baseline is what is live
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
            self.exact_peak = _status_kb("VmHWM") is not None
        except OSError:
            self.exact_peak = False
        self.rss0 = (_status_kb("VmRSS") or 0) * 1024
        return self

    def _sum(self, v):
        return self.comm.allreduce(v) if self.comm.size > 1 else v

    def peak(self):
        """(peak bytes, increase over start in bytes), summed over ranks."""
        if self.exact_peak:
            pk = (_status_kb("VmHWM") or 0) * 1024
        else:
            import resource
            pk = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        return self._sum(pk), self._sum(max(pk - self.rss0, 0))


def particle_bytes(sim):
    """Bytes of per-particle arrays (the particle state plus the simulation's per-particle
    work arrays), summed over ranks."""
    p = sim.particles
    arrays = [getattr(p, name) for name in p.field_names()]
    arrays += [getattr(sim, a) for a in ("nodes", "N", "dN")
               if isinstance(getattr(sim, a, None), np.ndarray)]
    arrays += list(sim._scratch.values())
    b = int(sum(a.nbytes for a in arrays))
    return sim.comm.allreduce(b) if sim.comm.size > 1 else b
