"""Benchmark case `mpi-scaling`: the same scenes on 1, 2, ... MPI ranks (issues 4, 16).

    python -m fenicsmpm.bench mpi-scaling [--quick] [--ranks 1,2,4,8,16] [--weak]

--ranks: the rank counts to launch (must include 1; default 1,2). Strong scaling (default):
the same scene on every rank count. --weak: weak scaling, the particles per rank fixed:
on N ranks the scene has about N times the particles.
Each rank runs one numba thread (NUMBA_NUM_THREADS=1 unless set in the environment), so
the rank counts are compared at one core per rank.
--weak grows the grid so that the block has N times the 1-rank block's cells (weak_scenes).

The runner process is serial. For each rank count it launches
    mpirun [--allow-run-as-root] -n N python -m fenicsmpm.bench.mpi_scaling --worker SPEC RESULT
(OMPI_MCA_rmaps_base_oversubscribe=1 in the environment, --allow-run-as-root only when
running as root, OMP/OpenBLAS threads pinned to 1 per rank unless already set); the worker
runs every scene on its N ranks and writes its measurements as JSON to RESULT, a temporary
file that the runner reads. Run under an existing mpirun (MPI size > 1), the case refuses:
it launches its own.

Scenes: the `throughput` block (a plane-strain elastic block on a fixed base under gravity,
structured quadrilateral grid, 2x2 particles per cell, built by throughput.build_scene):
  explicit MUSL, dt = "auto" (cfl 0.5): 320^2 cells -> 401,952 particles, 2 warm-up steps,
      best of 3 repetitions of 20 steps        / quick: 164^2 cells (1.0e5), best of 2 x 10
  implicit Newmark, dt = 5 dt_critical, direct LU by MUMPS on both rank counts (the same
      factorization package on 1 and 2 ranks): 164^2 cells -> 103,680 particles, 1 warm-up
      step, best of 2 repetitions of 3 steps   / quick: 74^2 cells (2.0e4), 1 x 2 steps
The launches alternate between the rank counts (1, 2, 1, 2: `rounds` = 2; quick: 1 round)
so that a burst of other load on a shared machine does not hit one rank count only; each
(scene, ranks) reports its fastest repetition over all rounds, and keeps every repetition
(wall_per_step_repeats_s) and their median (wall_per_step_median_s).

Metrics per run (times per step; stage times are averages over ranks, wall the slowest
rank): wall_per_step_s; with P particles and t seconds per step on N ranks,
efficiency = (P_N / (N t_N)) / (P_1 / t_1) (particle updates per second per rank against
one rank: t_1 / (N t_N) for strong scaling, t_1 / t_N for weak), speedup = N efficiency,
and efficiency_<stage> the same for each stage's time (exclusive, see below; "other"
included; a stage that takes no time on N ranks has none),
t_<stage> and frac_<stage> (of the wall time) for the simulation's stages with two parts
taken out and reported on their own:
  migration: Particles.send_to_owners (called from Simulation.locate_and_shape; taken out
      of "locate"): handing particles to the rank owning their cell, at least one small
      global reduction per step;
  exchange: Grid.accumulate (reverse + forward scatter of nodal sums across ranks; taken
      out of "p2g", or of "solve" when called from the Newton loop). It includes the time
      a rank waits for the other one to arrive, so load imbalance shows up here.
Both are measured by wrapping the methods with timers in the worker (on 1 rank they are a
trivial check and a no-op). When no particle changes rank, migration is that reduction
plus the wait for the slower rank. guards: the particle check at the end of
Simulation.step (its "guards" stage timer); other: the rest of the wall time. Also: imbalance (max over mean of
particles per rank at the end; 1 = balanced), imbalance_start, cpu_utilization (CPU time
of the measured steps over wall x ranks: < 1 means the ranks were starved by other load),
migrated_particles (sent to another rank during the measured steps), and, before each
launch, the 1-minute load average and the fraction of the cores busy during one second
(cpu_busy_before; full runs first wait up to 30 s for at most a quarter of the cores to be
busy), and other_load_cores: the cores used by other processes during the measured steps
(all busy cores from /proc/stat minus the run's own CPU time over its wall time).

Targets (issue 4, reported, not asserted): explicit speed-up >= 1.6 on 2 ranks (strong)."""
import argparse
import collections
import functools
import json
import math
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from . import common

CASE = "mpi-scaling"
RANKS = (1, 2)
# the stages whose efficiency is reported (exclusive times, see the module docstring)
EFF_STAGES = ("locate", "migration", "shape", "p2g", "exchange", "solve", "g2p",
              "constitutive", "guards", "other")
TARGETS = {"explicit_speedup_2_ranks": 1.6}

MUMPS = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}

FULL = [
    dict(name="explicit-MUSL", integrator="Explicit", scheme="MUSL", cells=320, per_cell=2,
         steps=20, warmup=2, repeats=3),
    dict(name="implicit-Newmark", integrator="Newmark", scheme="Newmark", cells=164,
         per_cell=2, steps=3, warmup=1, repeats=2, dt_factor=5.0, petsc_options=MUMPS,
         prefix="fenicsmpm_scaling_"),
]
QUICK = [
    dict(name="explicit-MUSL", integrator="Explicit", scheme="MUSL", cells=164, per_cell=2,
         steps=10, warmup=2, repeats=2),
    dict(name="implicit-Newmark", integrator="Newmark", scheme="Newmark", cells=74,
         per_cell=2, steps=2, warmup=1, repeats=1, dt_factor=5.0, petsc_options=MUMPS,
         prefix="fenicsmpm_scaling_"),
]

# the stages of the stacked bars, in drawing order (exclusive times)
BAR_STAGES = ("locate", "migration", "shape", "p2g", "exchange", "solve (residual)",
              "assembly", "ksp", "g2p", "constitutive", "guards", "other")

REFUSAL = (f"benchmark case {CASE!r} launches its own mpirun (1, 2, ... ranks) and must be "
           f"started serially: python -m fenicsmpm.bench {CASE}")


def scenes(quick=False, scale=1.0, steps=None, repeats=None):
    """The scene specifications. scale multiplies the particle counts (cells per side by
    sqrt(scale), at least throughput.MIN_CELLS); steps / repeats override the measured
    steps per repetition and the number of repetitions."""
    from .throughput import MIN_CELLS
    if not (scale > 0):
        raise ValueError(f"{CASE}: 'scale' must be > 0, got {scale!r}")
    for name, v in (("steps", steps), ("repeats", repeats)):
        if v is not None and not (isinstance(v, int) and v >= 1):
            raise ValueError(f"{CASE}: {name!r} must be a positive integer, got {v!r}")
    out = []
    for s in (QUICK if quick else FULL):
        s = dict(s)
        s["cells"] = max(MIN_CELLS, int(round(s["cells"] * math.sqrt(scale))))
        if steps is not None:
            s["steps"] = steps
        if repeats is not None:
            s["repeats"] = repeats
        out.append(s)
    return out


def weak_scenes(specs, n):
    """The scenes of `specs` (1 rank) grown for n ranks at fixed particles per rank: cells
    per side c such that the block, (c - 2 MARGIN) x (c - MARGIN) cells, has about n times
    the 1-rank block's cells."""
    from .throughput import MARGIN
    out = []
    for s in specs:
        c1 = s["cells"]
        block = n * (c1 - 2 * MARGIN) * (c1 - MARGIN)
        # (c - 2M)(c - M) = (c - 1.5 M)^2 - (M / 2)^2
        c = int(round(1.5 * MARGIN + math.sqrt(block + 0.25 * MARGIN ** 2)))
        out.append(dict(s, cells=c))
    return out


# ============================================================================ worker side
def _proc_stat():
    """(all jiffies, idle jiffies) of the whole machine from /proc/stat; None elsewhere."""
    try:
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
        return sum(v[:8]), v[3] + (v[4] if len(v) > 4 else 0)
    except (OSError, ValueError, IndexError):
        return None


def _busy_cores(a, b):
    """Cores busy on average between two _proc_stat() readings (None if unknown)."""
    if a is None or b is None or b[0] <= a[0]:
        return None
    return (1.0 - (b[1] - a[1]) / (b[0] - a[0])) * (os.cpu_count() or 1)


def _cpu_busy(seconds=1.0):
    """Fraction of all cores busy during the next `seconds`: what other work occupies the
    machine just before a launch (None where /proc/stat is missing)."""
    a = _proc_stat()
    time.sleep(seconds)
    busy = _busy_cores(a, _proc_stat())
    return None if busy is None else round(busy / (os.cpu_count() or 1), 3)


def _wait_for_quiet(max_wait, threshold=0.25):
    """Sample the machine every second until at most `threshold` of its cores are busy or
    `max_wait` seconds have passed; (busy fraction of the last second, seconds waited)."""
    t0 = time.perf_counter()
    while True:
        busy = _cpu_busy()
        waited = time.perf_counter() - t0
        if busy is None or busy <= threshold or waited >= max_wait:
            return busy, round(waited, 1)


_PROBE = collections.defaultdict(float)
NEWTON_FRAMES = ("solve_step", "newton_residual")     # integrators.implicit's Newton loop


def _install_probes():
    """Wrap Particles.send_to_owners and Grid.accumulate with timers (worker process only).
    Exchange time is attributed to the stage that called it: "solve" for the Newton loop
    (NEWTON_FRAMES), "p2g" otherwise (the integrators' transfer part and external_force)."""
    import fenicsmpm as fm
    if getattr(fm.Particles.send_to_owners, "_bench_probe", False):
        return
    send, acc = fm.Particles.send_to_owners, fm.Grid.accumulate

    @functools.wraps(send)
    def send_to_owners(self):
        t0 = time.perf_counter()
        try:
            return send(self)
        finally:
            _PROBE["migration"] += time.perf_counter() - t0
            _PROBE["migration_calls"] += 1

    @functools.wraps(acc)
    def accumulate(self, *arrays):
        caller = sys._getframe(1).f_code.co_name
        t0 = time.perf_counter()
        try:
            return acc(self, *arrays)
        finally:
            dt = time.perf_counter() - t0
            _PROBE["exchange_solve" if caller in NEWTON_FRAMES else "exchange_p2g"] += dt
            _PROBE["exchange_calls"] += 1


    send_to_owners._bench_probe = True
    fm.Particles.send_to_owners = send_to_owners
    fm.Grid.accumulate = accumulate


def _reset_probes():
    _PROBE.clear()


def _measure(spec, comm):
    """Build one scene on comm, warm up, time `repeats` x `steps` steps; the run record."""
    from . import throughput
    cfg = throughput.scene_config(spec)
    import numba
    cfg.update(ranks=comm.size, repeats=spec["repeats"], threads_per_rank=numba.get_num_threads(),
               omp_threads=os.environ.get("OMP_NUM_THREADS"), timing="fastest repetition")
    sim = throughput.build_scene(cfg, comm)
    p = sim.particles
    implicit = not sim.integrator.explicit
    if implicit:
        ksp = sim.integrator.system.ksp
        cfg.update(ksp_type=ksp.getType(), pc_type=ksp.getPC().getType(),
                   factor_solver=ksp.getPC().getFactorSolverType())
    n_part = p.n_global()

    def imbalance():
        counts = np.array(comm.allgather(len(p)), dtype=float)
        return float(counts.max() / counts.mean()), counts

    imb0, _ = imbalance()
    for _ in range(spec["warmup"]):
        sim.step()
    steps = spec["steps"]
    reps = []
    for _ in range(spec["repeats"]):
        ids0 = p.id.copy()
        _reset_probes()
        stat0 = _proc_stat() if comm.rank == 0 else None
        timing = common.time_steps(sim, steps)
        # cores used by other processes during the measurement: all busy cores minus ours
        busy = _busy_cores(stat0, _proc_stat()) if comm.rank == 0 else None
        other = None if busy is None else max(busy - timing["cpu_s"] / timing["wall_s"], 0.0)
        timing["other_cores"] = comm.bcast(other, root=0) if comm.size > 1 else other
        probe = dict(_PROBE)
        # particles that left this rank during the measured steps
        gone = int(np.count_nonzero(~np.isin(ids0, p.id)))
        keys = ("migration", "exchange_p2g", "exchange_solve", "migration_calls", "exchange_calls")
        vals = np.array([probe.get(k, 0.0) for k in keys] + [gone], dtype=float)
        if comm.size > 1:
            vals = comm.allreduce(vals)
            vals[:-1] /= comm.size          # means over ranks, like sim.timers
        timing["probe"] = dict(zip(keys, vals[:-1]))
        timing["migrated"] = int(vals[-1])
        reps.append(timing)
    best = min(reps, key=lambda r: r["wall_s"])
    wall, T, pr = best["wall_s"], best["timers"], best["probe"]
    imb, counts = imbalance()
    per = 1.0 / steps
    exch = pr["exchange_p2g"] + pr["exchange_solve"]
    excl = {
        "locate": T["locate"] - pr["migration"],
        "migration": pr["migration"],
        "shape": T["shape"],
        "p2g": T["p2g"] - pr["exchange_p2g"],
        "exchange": exch,
        "solve": T["solve"] - pr["exchange_solve"],
        "g2p": T["g2p"],
        "constitutive": T["constitutive"],
        "guards": T["guards"],
    }
    if implicit:
        excl["assembly"] = T["assembly"]
        excl["ksp"] = T["ksp"]
    excl["other"] = wall - sum(v for k, v in excl.items() if k not in ("assembly", "ksp"))
    m = {"wall_per_step_s": wall * per,
         "wall_per_step_median_s": float(np.median([r["wall_s"] for r in reps])) * per,
         "particle_updates_per_s": n_part * steps / wall,
         "cpu_s": best["cpu_s"], "cpu_utilization": best["cpu_s"] / (wall * comm.size)}
    if best["other_cores"] is not None:
        m["other_load_cores"] = best["other_cores"]
    for k, v in excl.items():
        m[f"t_{k}"] = v * per
        m[f"frac_{k}"] = v / wall
    m.update(imbalance=imb, imbalance_start=imb0, particles_per_rank_min=int(counts.min()),
             particles_per_rank_max=int(counts.max()), migrated_particles=best["migrated"],
             migration_calls_per_step=pr["migration_calls"] * per,
             exchange_calls_per_step=pr["exchange_calls"] * per)
    if implicit:
        m["n_dofs"] = sim.integrator.system.A.getSize()[0]
        m["newton_iterations"] = float(np.mean(sim.integrator.iterations[-steps:]))
    cells = sim.grid.n_owned_cells
    cells = comm.allreduce(cells) if comm.size > 1 else cells
    rec = common.make_record(f"{spec['name']} / {comm.size} rank{'s' if comm.size > 1 else ''}",
                             cfg, n_part, cells, steps, wall, m)
    rec["scene"] = spec["name"]
    rec["ranks"] = comm.size
    rec["wall_per_step_repeats_s"] = [r["wall_s"] * per for r in reps]
    rec["other_load_cores_repeats"] = [r["other_cores"] for r in reps]
    if implicit:
        sim.integrator.system.destroy()
    return rec


def _worker(spec_path, result_path):
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    _install_probes()
    with open(spec_path) as f:
        specs = json.load(f)
    if isinstance(specs, dict):             # weak scaling: the scenes of each rank count
        specs = specs[str(comm.size)]
    runs = []
    for spec in specs:
        common.say(comm, f"  {spec['name']}: {spec['cells']}^2 cells, {comm.size} rank(s), "
                   f"{spec['warmup']} warm-up + {spec['repeats']} x {spec['steps']} steps ...")
        runs.append(_measure(spec, comm))
        m = runs[-1]["metrics"]
        common.say(comm, f"    {runs[-1]['n_particles']:,} particles: {m['wall_per_step_s']:.4g} "
                   f"s/step, imbalance {m['imbalance']:.3f}")
    doc = dict(runs=runs, machine=common.machine_info(comm),
               mpi_library=MPI.Get_library_version().splitlines()[0].strip())
    if comm.rank == 0:
        tmp = result_path + ".tmp"
        with open(tmp, "w") as f:
            json.dump(common._clean(doc), f)
        os.replace(tmp, result_path)
    comm.barrier()


# ============================================================================ runner side
def _child_env():
    """Environment of the launched mpirun: oversubscription allowed, one thread per rank
    (unless the caller set it), and no variables of an enclosing MPI launch."""
    env = dict(os.environ)
    if "OMPI_COMM_WORLD_SIZE" in env or "PMIX_RANK" in env:
        # started by an mpirun of its own (with one rank): a nested mpirun must not see
        # the outer launch's variables
        for k in list(env):
            if k.startswith(("OMPI_", "PMIX_", "ORTE_")) and not k.startswith("OMPI_MCA_"):
                del env[k]
            elif k.startswith(("OMPI_MCA_orte_", "OMPI_MCA_ess", "OMPI_MCA_pmix",
                               "OMPI_MCA_initial_wdir")):
                del env[k]
    # the workers import the same fenicsmpm as this process, installed or not
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in env.get("PYTHONPATH", "").split(
        os.pathsep) if p and p != root])
    env["OMPI_MCA_rmaps_base_oversubscribe"] = "1"
    env.setdefault("OMPI_MCA_btl_vader_single_copy_mechanism", "none")
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        env.setdefault(k, "1")
    return env


def launch_command(n, spec_path, result_path, mpirun=None):
    """The command line of one worker launch on n ranks."""
    mpirun = mpirun or shutil.which("mpirun")
    cmd = [mpirun]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    cmd += ["-n", str(n), sys.executable, "-m", "fenicsmpm.bench.mpi_scaling", "--worker",
            spec_path, result_path]
    return cmd


def _launch(cmd, env, timeout, verbose, label):
    """Run cmd, echoing its output (prefixed) when verbose; RuntimeError with the tail of
    the output if it fails or runs past `timeout` seconds."""
    tail = collections.deque(maxlen=60)
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)
    expired = []

    def kill():
        expired.append(True)
        try:
            os.killpg(proc.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass

    timer = threading.Timer(timeout, kill)
    timer.start()
    try:
        for line in proc.stdout:
            tail.append(line.rstrip("\n"))
            if verbose:
                print(f"[{CASE} {label}] {line}", end="", flush=True)
        rc = proc.wait()
    finally:
        timer.cancel()
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    if expired or rc != 0:
        why = f"ran past {timeout:g} s" if expired else f"exited with status {rc}"
        raise RuntimeError(f"{CASE}: the {label} worker {why}:\n  {shlex.join(cmd)}\n"
                           + "\n".join(tail))


def _efficiency(p1, t1, pn, tn, n):
    """(P_N / (N t_N)) / (P_1 / t_1): updates per second per rank against one rank."""
    return (pn / (n * tn)) / (p1 / t1) if t1 > 0 and tn > 0 else None


def _scaling(runs):
    """scene -> t1, tN, speed-up and efficiency (from wall_per_step_s), and the efficiency
    of each stage; also stored in each run's metrics."""
    out = {}
    for scene in dict.fromkeys(r["scene"] for r in runs):
        by = {r["ranks"]: r for r in runs if r["scene"] == scene}
        if 1 not in by:
            continue
        m1, p1 = by[1]["metrics"], by[1]["n_particles"]
        t1 = m1["wall_per_step_s"]
        entry = {"t_1_rank_s_per_step": t1, "particles_1_rank": p1}
        for n, r in sorted(by.items()):
            m, pn = r["metrics"], r["n_particles"]
            tn = m["wall_per_step_s"]
            eff = _efficiency(p1, t1, pn, tn, n)
            m["efficiency"], m["speedup"] = eff, n * eff
            for k in EFF_STAGES:
                e = _efficiency(p1, m1.get(f"t_{k}", 0.0), pn, m.get(f"t_{k}", 0.0), n)
                if e is not None:
                    m[f"efficiency_{k}"] = e
            if n > 1:
                entry.update({f"t_{n}_ranks_s_per_step": tn, f"particles_{n}_ranks": pn,
                              f"speedup_{n}_ranks": n * eff, f"efficiency_{n}_ranks": eff})
                entry.update({f"efficiency_{k}_{n}_ranks": m[f"efficiency_{k}"]
                              for k in EFF_STAGES if f"efficiency_{k}" in m})
        out[scene] = entry
    return out


def _bar_stacks(runs):
    stacks = {}
    for k in BAR_STAGES:
        key = "solve" if k == "solve (residual)" else k
        vals = []
        for r in runs:
            m = r["metrics"]
            v = m.get(f"t_{key}", 0.0)
            if k == "solve (residual)":
                v -= m.get("t_assembly", 0.0) + m.get("t_ksp", 0.0)
            vals.append(v)
        stacks[k] = vals
    return stacks


def plot(doc, path, comm):
    scenes_ = list(dict.fromkeys(r["scene"] for r in doc["runs"]))
    fig, axes = common.new_figure(ncols=len(scenes_), size=(5.2, 4.6))
    for j, scene in enumerate(scenes_):
        runs = sorted((r for r in doc["runs"] if r["scene"] == scene), key=lambda r: r["ranks"])
        ax = axes[0, j]
        labels = [f"{r['ranks']} rank{'s' if r['ranks'] > 1 else ''}" for r in runs]
        ann = []
        for r in runs:
            m = r["metrics"]
            text = f"{m['wall_per_step_s']:.3g} s/step"
            if r["ranks"] > 1:
                text += (f"\n{r['n_particles']:,} p\nspeed-up {m['speedup']:.2f}x"
                         f"\nefficiency {100 * m['efficiency']:.0f} %"
                         f"\nimbalance {m['imbalance']:.3f}")
            if m.get("other_load_cores") is not None:
                text += f"\nothers' load {m['other_load_cores']:.2f} cores"
            ann.append(text)
        top = common.stacked_bars(ax, labels, _bar_stacks(runs), ann,
                                  ylabel="time per step [s]",
                                  colors={"other": "lightgray", "guards": "darkslategray"},
                                  legend="outside" if j == len(scenes_) - 1 else None)
        ax.set_ylim(0, 1.5 * max(float(np.max(top)), 1e-12))      # room for 5 lines of text
        r0 = runs[0]
        ax.set_title(f"{scene}: {r0['n_particles']:,} particles", fontsize=9)
        if scene.startswith("explicit"):
            tgt = TARGETS["explicit_speedup_2_ranks"]
            ax.text(0.02, 0.98, f"target: speed-up >= {tgt:g} on 2 ranks", fontsize=7,
                    transform=ax.transAxes, va="top")
    return common.save_figure(fig, path, comm, title=common.figure_title(
        doc, f"MPI scaling ({doc.get('mode', 'strong')})", " (launched by a serial runner)"))


def print_report(doc, comm):
    cols = [("run", "name"), ("particles", "n_particles"), ("steps", "steps"),
            ("s/step", lambda r: r["metrics"]["wall_per_step_s"]),
            ("speed-up", lambda r: r["metrics"].get("speedup")),
            ("efficiency", lambda r: r["metrics"].get("efficiency")),
            ("migration", lambda r: r["metrics"]["frac_migration"]),
            ("exchange", lambda r: r["metrics"]["frac_exchange"]),
            ("imbalance", lambda r: r["metrics"]["imbalance"]),
            ("cpu/wall", lambda r: r["metrics"]["cpu_utilization"]),
            ("load before", lambda r: r.get("load_average_1min_before")),
            ("busy before", lambda r: r.get("cpu_busy_before")),
            ("others' cores", lambda r: r["metrics"].get("other_load_cores"))]
    common.print_table(doc["runs"], cols, comm, title=f"\n== {CASE}"
                       f"{' (quick)' if doc['quick'] else ''} (migration, exchange: fraction "
                       f"of the step time; load: 1-minute load average, busy: fraction of the cores busy in the "
                       f"second before the launch; others' cores: cores used by other processes "
                       f"during the measured steps)")
    stage_cols = [("run", "name")] + [
        (k, (lambda k: lambda r: r["metrics"].get(f"frac_{k}"))(k))
        for k in ("locate", "migration", "shape", "p2g", "exchange", "solve", "assembly", "ksp",
                  "g2p", "constitutive", "guards", "other")]
    common.print_table(doc["runs"], stage_cols, comm, title="fraction of the step time per stage "
                       "(exclusive; assembly and ksp are parts of solve)")
    eff_cols = [("run", "name"), ("particles", "n_particles"),
                ("total", lambda r: r["metrics"].get("efficiency"))] + [
        (k, (lambda k: lambda r: r["metrics"].get(f"efficiency_{k}"))(k)) for k in EFF_STAGES]
    common.print_table(doc["runs"], eff_cols, comm, title=f"{doc.get('mode', 'strong')}-scaling "
                       f"efficiency per stage: (P_N / (N t_N)) / (P_1 / t_1), 1 = ideal")
    starved = [r["name"] for r in doc["runs"] if r["metrics"]["cpu_utilization"] < 0.9]
    if starved:
        common.say(comm, f"  cpu/wall < 0.9 (the ranks did not get a full core each: other load "
                   f"on the machine, or ranks waiting for each other): {', '.join(starved)}")
    s = doc["scaling"].get("explicit-MUSL")
    if s and "speedup_2_ranks" in s and doc.get("mode", "strong") == "strong":
        t = TARGETS["explicit_speedup_2_ranks"]
        common.say(comm, f"  explicit-MUSL: speed-up {s['speedup_2_ranks']:.2f}x on 2 ranks vs "
                   f"target {t:g}x: {'met' if s['speedup_2_ranks'] >= t else 'NOT met'} "
                   f"({doc['machine']['cores']} cores; 1-minute load average before the "
                   f"launches: {[x['load_average_1min_before'] for x in doc['launches']]})")


def _combine(records):
    """One record per (scene, ranks) from several rounds: the round with the fastest
    repetition, with every round's repetitions and load averages kept."""
    best = dict(min(records, key=lambda r: r["metrics"]["wall_per_step_s"]))
    reps = [t for r in records for t in r["wall_per_step_repeats_s"]]
    best["wall_per_step_repeats_s"] = reps
    best["other_load_cores_repeats"] = [x for r in records for x in r["other_load_cores_repeats"]]
    best["metrics"] = dict(best["metrics"], wall_per_step_median_s=float(np.median(reps)),
                           rounds=len(records))
    best["load_average_1min_before_rounds"] = [r["load_average_1min_before"] for r in records]
    best["cpu_busy_before_rounds"] = [r["cpu_busy_before"] for r in records]
    return best


def run(quick=False, out="bench-results", comm=None, scale=1.0, steps=None, repeats=None,
        rounds=None, ranks=RANKS, weak=False, max_wait=None, verbose=True, timeout=None):
    """Launch the workers, write out/mpi-scaling.json and out/mpi-scaling.png, print the
    table; returns the result dict.

    ranks: the rank counts (positive integers, 1 among them). weak: weak scaling (the scene
    on N ranks has N times the particles of the 1-rank scene) instead of strong scaling.

    The launches alternate between the rank counts, `rounds` times (default 2, quick 1), so
    that a burst of other load on the machine does not hit only one rank count; each
    (scene, ranks) reports its fastest repetition over all rounds.
    Before each launch it waits (at most `max_wait` seconds: default 30, quick 0) until at
    most a quarter of the cores are busy with other work.
    Must run serially (RuntimeError under an MPI size > 1) with `mpirun` on PATH."""
    ranks = tuple(ranks)
    if (1 not in ranks or len(set(ranks)) != len(ranks)
            or any(not (isinstance(n, int) and n >= 1) for n in ranks)):
        raise ValueError(f"{CASE}: 'ranks' must be distinct positive integers including 1, "
                         f"got {ranks!r}")
    comm = common.world(comm)
    if comm.size > 1:
        raise RuntimeError(REFUSAL)
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        raise RuntimeError(f"{CASE}: 'mpirun' is not on PATH (the case launches "
                           f"mpirun -n N for each rank count)")
    rounds = (1 if quick else 2) if rounds is None else rounds
    if not (isinstance(rounds, int) and rounds >= 1):
        raise ValueError(f"{CASE}: 'rounds' must be a positive integer, got {rounds!r}")
    max_wait = (0.0 if quick else 30.0) if max_wait is None else float(max_wait)
    specs = scenes(quick, scale, steps, repeats)
    by_ranks = {n: weak_scenes(specs, n) if weak else specs for n in ranks}
    if timeout is None:
        timeout = 600.0 if quick else 3600.0
    env = _child_env()
    got, launches = collections.defaultdict(list), []
    libs = set()
    tmpdir = tempfile.mkdtemp(prefix="fenicsmpm_scaling_")
    try:
        spec_path = os.path.join(tmpdir, "spec.json")
        with open(spec_path, "w") as f:
            json.dump({str(n): v for n, v in by_ranks.items()}, f)
        for k in range(rounds):
            for n in ranks:
                result_path = os.path.join(tmpdir, f"result_{k}_{n}.json")
                cmd = launch_command(n, spec_path, result_path, mpirun)
                busy, waited = _wait_for_quiet(max_wait)
                load = common._load_average()
                if verbose:
                    common.say(comm, f"[{CASE}] round {k + 1}/{rounds}, {n} rank(s), load "
                               f"average {load}, cores busy before {busy}: {shlex.join(cmd)}")
                t0 = time.perf_counter()
                _launch(cmd, env, timeout, verbose, f"{n} rank{'s' if n > 1 else ''}")
                with open(result_path) as f:
                    res = json.load(f)
                for r in res["runs"]:
                    r["load_average_1min_before"] = load
                    r["cpu_busy_before"] = busy
                    got[(r["scene"], n)].append(r)
                libs.add(res["mpi_library"])
                launches.append(dict(round=k + 1, ranks=n, launch_wall_s=time.perf_counter() - t0,
                                     load_average_1min_before=load, cpu_busy_before=busy,
                                     waited_for_quiet_s=waited,
                                     load_average_1min_after=res["machine"]["load_average_1min"]))
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    runs = [_combine(got[(s["name"], n)]) for s in specs for n in ranks]
    scaling = _scaling(runs)
    cmd = shlex.join(launch_command(2, "SPEC", "RESULT", mpirun))
    doc = common.result(CASE, runs, comm, quick=quick, scale=scale, rounds=rounds,
                        mode="weak" if weak else "strong", ranks=list(ranks),
                        max_wait_for_quiet_s=max_wait,
                        targets=TARGETS, scaling=scaling, launches=launches,
                        launch=dict(command=cmd, mpi_library=sorted(libs)),
                        environment={k: env[k] for k in sorted(env) if k.startswith(
                            ("OMPI_MCA_", "OMP_NUM", "OPENBLAS_NUM", "MKL_NUM"))})
    common.write_result(doc, out, comm)
    plot(doc, os.path.join(out, f"{CASE}.png"), comm)
    if verbose:
        print_report(doc, comm)
    return doc


def rank_list(text):
    """'1,2,4' -> (1, 2, 4) (argparse type of --ranks)."""
    try:
        ranks = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected rank counts like 1,2,4, got {text!r}")
    if not ranks or 1 not in ranks or any(n < 1 for n in ranks) or len(set(ranks)) != len(ranks):
        raise argparse.ArgumentTypeError(f"rank counts must be distinct, positive and include "
                                         f"1, got {text!r}")
    return ranks


def add_arguments(parser):
    """The case's command-line options (also offered by python -m fenicsmpm.bench)."""
    parser.add_argument("--ranks", type=rank_list, default=RANKS, metavar="N,N,...",
                        help="MPI rank counts to launch, 1 among them (default: "
                             f"{','.join(map(str, RANKS))})")
    parser.add_argument("--weak", action="store_true",
                        help="weak scaling: particles per rank fixed (default: strong scaling)")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m fenicsmpm.bench.mpi_scaling",
                                 description=f"benchmark case {CASE} (or, with --worker, one "
                                             f"launch of it under mpirun)")
    ap.add_argument("--worker", nargs=2, metavar=("SPEC", "RESULT"),
                    help="internal: run the scenes of SPEC on this MPI launch, write RESULT")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default="bench-results")
    add_arguments(ap)
    args = ap.parse_args(argv)
    if args.worker:
        _worker(*args.worker)
    else:
        run(quick=args.quick, out=args.out, ranks=args.ranks, weak=args.weak)
    return 0


if __name__ == "__main__":
    sys.exit(main())
