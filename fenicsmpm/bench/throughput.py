"""Benchmark case `throughput`: particle updates per second and where a step's time goes.

Scene: a 2D plane-strain linear-elastic block (E = 1 MPa, nu = 0.3, rho = 1000 kg/m^3) in a
unit-square structured quadrilateral grid, resting on a fixed base (all displacement
components fixed at y = 0) with MARGIN empty cells on its left, right and top, loaded by
gravity from rest, so it compresses and bulges.

Runs (full size / --quick):
  explicit MUSL, USL, USF: 512^2 cells, 2x2 particles per cell -> 1.04e6 particles, 20 steps
      after 2 warm-up steps, dt = "auto" (cfl 0.5)     / quick: MUSL only, 164^2 cells (1.0e5)
  implicit Newmark: 164^2 cells, 2x2 ppc -> 1.04e5 particles, 3 steps after 1 warm-up step,
      dt = 5 h / c_p (5x the explicit critical step), the defaults (shape="auto": cpGIMP;
      KSP GMRES + block Jacobi/ILU)                     / quick: 74^2 cells (2.0e4), 2 steps
  implicit Newmark, standard family (full size only), with the default KSP and with the
      direct LU (the defaults before issue 15)
  quasi-static (full size only): the same block, gravity ramped over the warm-up and measured
      steps (each step loads), default KSP (GMRES + lagged LU), with shape="auto" (cpGIMP)
      and "mpm"
A spec with dim=3 builds the same block as a box of hexahedra (MARGIN empty cells on its four
sides and top; not among the rows: docs/guide/integrators.md measures 3D quasi-static steps
with it), and lu_times() times PETSc's LU against MUMPS on the quasi-static tangent.
The warm-up absorbs numba compilation and first-call set-up; sim.timers are zeroed after it.
These runs use the process's numba threads (NUMBA_NUM_THREADS; config "threads").

Thread rows (serial runs only; doc["threads"]): the explicit MUSL scene above with the
standard shape functions and with cpGIMP, each in a child process per thread count
(NUMBA_NUM_THREADS = 1 and 2: `threads`), so one process on 1 and on 2 threads can be
compared; speed-up = updates/s on N threads / updates/s on 1 thread, per shape.

Metrics per run: particle_updates_per_s = n_particles * steps / wall_s; cpu_s (CPU time of
the measured steps, all ranks), cpu_utilization = cpu_s / (wall_s * ranks) (< 1: the machine
was busy with other work) and particle_updates_per_cpu_s; t_<stage> (seconds
per step, from sim.timers: locate, shape, p2g, solve, g2p, constitutive; implicit also
assembly and ksp, which are parts of solve) and frac_<stage> (of the wall time per step);
t_other (wall per step minus the stages: untimed work); implicit: assembly_over_ksp,
newton_iterations (mean per step), ksp_iterations_per_step, n_dofs; memory: peak_rss_bytes,
mem_bytes_per_particle (peak RSS during the run minus RSS before building the scene, over
particles: everything the run needs, mesh, grid, matrix and factors included) and
particle_array_bytes_per_particle (per-particle state and work arrays / particles)."""
import argparse
import gc
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from . import common

CASE = "throughput"

E, NU, RHO, GRAVITY = 1.0e6, 0.3, 1000.0, 9.81
LENGTH = 1.0
MARGIN = 2          # empty cells left, right and above the block
MIN_CELLS = 2 * MARGIN + 4

# name, integrator, scheme, cells per side, particles per cell per direction, steps, warm-up
FULL = [
    dict(name="explicit-MUSL", integrator="Explicit", scheme="MUSL", cells=512, per_cell=2,
         steps=20, warmup=2),
    dict(name="explicit-USL", integrator="Explicit", scheme="USL", cells=512, per_cell=2,
         steps=20, warmup=2),
    dict(name="explicit-USF", integrator="Explicit", scheme="USF", cells=512, per_cell=2,
         steps=20, warmup=2),
    # the defaults: shape="auto" (cpGIMP here) and the iterative KSP (GMRES + block Jacobi)
    dict(name="implicit-Newmark", integrator="Newmark", scheme="Newmark", cells=164,
         per_cell=2, steps=3, warmup=1, dt_factor=5.0, shape="auto"),
    # the standard family with the same KSP, and with the direct LU (the defaults before
    # issue 15: the reference of its "within 2x" target)
    dict(name="implicit-Newmark-mpm", integrator="Newmark", scheme="Newmark", cells=164,
         per_cell=2, steps=3, warmup=1, dt_factor=5.0),
    dict(name="implicit-Newmark-mpm-lu", integrator="Newmark", scheme="Newmark", cells=164,
         per_cell=2, steps=3, warmup=1, dt_factor=5.0,
         petsc_options={"ksp_type": "preonly", "pc_type": "lu"}, prefix="fenicsmpm_bench_lu_"),
    # quasi-static (default KSP: GMRES + lagged LU), gravity ramped over the 4 steps: the
    # default shape (cpGIMP) and the standard family
    dict(name="implicit-QuasiStatic", integrator="QuasiStatic", scheme="QuasiStatic",
         cells=164, per_cell=2, steps=3, warmup=1, shape="auto"),
    dict(name="implicit-QuasiStatic-mpm", integrator="QuasiStatic", scheme="QuasiStatic",
         cells=164, per_cell=2, steps=3, warmup=1),
]
QUICK = [
    dict(name="explicit-MUSL", integrator="Explicit", scheme="MUSL", cells=164, per_cell=2,
         steps=10, warmup=2),
    dict(name="implicit-Newmark", integrator="Newmark", scheme="Newmark", cells=74,
         per_cell=2, steps=2, warmup=1, dt_factor=5.0, shape="auto"),
]

# targets from the issue (reported, not asserted) and peers for context
# issue 16: the default configuration (shape "auto": cpGIMP on this grid) on 1 and 2 threads
TARGETS = {"default_particle_updates_per_s_1_thread": 8.0e6,
           "default_particle_updates_per_s_2_threads": 1.5e7,
           "implicit_assembly_over_ksp_max": 1.0}
PEERS = {"CB-Geo MPM, 1 core (particle updates/s)": 0.50e6}

STAGES = ("locate", "shape", "p2g", "solve", "g2p", "constitutive")
THREADS = (1, 2)                 # thread counts of the thread rows
THREAD_SHAPES = ("mpm", "cpgimp")
DEFAULT_SHAPE = "cpgimp"         # what shape="auto" takes on this axis-aligned grid
SUBSTAGES = ("assembly", "ksp")          # parts of "solve" (implicit)


def scenes(quick=False, scale=1.0):
    """The run specifications; `scale` multiplies the particle counts (cells per side by
    sqrt(scale), at least MIN_CELLS)."""
    if not (scale > 0):
        raise ValueError(f"throughput: 'scale' must be > 0, got {scale!r}")
    out = []
    for s in (QUICK if quick else FULL):
        s = dict(s)
        s["cells"] = max(MIN_CELLS, int(round(s["cells"] * math.sqrt(scale))))
        out.append(s)
    return out


def scene_config(spec):
    """The run's config record (h and dt are filled in by build_scene)."""
    n, dim = spec["cells"], spec.get("dim", 2)
    if dim not in (2, 3):
        raise ValueError(f"{CASE}: 'dim' must be 2 or 3, got {dim!r}")
    family = spec.get("shape")
    # 3D (spec dim=3): the same block as a hexahedral box, the margins on the four sides
    cfg = dict(integrator=spec["integrator"], scheme=spec["scheme"],
               shape=family or f"{'Q1' if dim == 2 else 'Q1 hex'} (standard MPM)",
               shape_family=family, h=LENGTH / n, dt=None, ppc=spec["per_cell"] ** dim,
               per_cell=spec["per_cell"],
               cell_type="quadrilateral" if dim == 2 else "hexahedron", grid_cells=[n] * dim,
               block_cells=[n - 2 * MARGIN] * (dim - 1) + [n - MARGIN],
               margin_cells=MARGIN, length=LENGTH, material="LinearElastic", E=E, nu=NU,
               density=RHO, gravity=[0.0] * (dim - 1) + [-GRAVITY], base="fixed (every component)",
               warmup_steps=spec["warmup"])
    if spec["integrator"] == "Explicit":
        cfg.update(dt_rule="auto", cfl=0.5, flip=1.0)
    elif spec["integrator"] == "QuasiStatic":     # gravity ramped over every step: each loads
        cfg.update(dt_rule="1 (quasi-static)", load_steps=spec["warmup"] + spec["steps"],
                   petsc_options=spec.get("petsc_options"), petsc_prefix=spec.get("prefix"))
    else:
        cfg.update(dt_rule=f"{spec['dt_factor']:g} * dt_critical", dt_factor=spec["dt_factor"],
                   beta=0.25, gamma=0.5, petsc_options=spec.get("petsc_options"),
                   petsc_prefix=spec.get("prefix"))
    return cfg


def build_scene(cfg, comm=None):
    """The Simulation of a config (collective)."""
    from dolfinx import mesh as dmesh
    import fenicsmpm as fm
    comm = common.world(comm)
    n, dim = cfg["grid_cells"][0], len(cfg["grid_cells"])
    L, h = cfg["length"], cfg["length"] / n
    if dim == 2:
        msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [L, L]], [n, n],
                                     dmesh.CellType.quadrilateral)
    else:
        msh = dmesh.create_box(comm, [[0.0] * 3, [L] * 3], [n] * 3, dmesh.CellType.hexahedron)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=cfg["E"], nu=cfg["nu"], density=cfg["density"])
    x0, x1, top = MARGIN * h, L - MARGIN * h, L - MARGIN * h
    pts = fm.Particles.fill(grid, mat, per_cell=cfg["per_cell"],
                            region=lambda x: np.all((x[:, :dim - 1] > x0) & (x[:, :dim - 1] < x1),
                                                    axis=1) & (x[:, dim - 1] < top))
    if cfg["integrator"] == "Explicit":
        integ, dt = fm.Explicit(cfg["scheme"], flip=cfg["flip"]), "auto"
    else:
        kw = {}
        if cfg.get("petsc_options"):
            # own prefix: LinearSystem leaves its options in PETSc's global database
            kw = dict(petsc_options=cfg["petsc_options"], prefix=cfg["petsc_prefix"])
        if cfg["integrator"] == "QuasiStatic":
            integ, dt = fm.QuasiStatic(load_steps=cfg["load_steps"], **kw), 1.0
        else:
            integ = fm.Newmark(beta=cfg["beta"], gamma=cfg["gamma"], **kw)
            dt = cfg["dt_factor"] * grid.h / mat.p_wave_speed      # = dt_factor * sim.dt_critical
    sim = fm.Simulation(grid, pts, integ, dt=dt, gravity=cfg["gravity"],
                        cfl=cfg.get("cfl", 0.5), shape=cfg.get("shape_family") or "mpm")
    sim.fix(lambda x: np.isclose(x[:, dim - 1], 0.0))
    cfg["h"], cfg["dt"], cfg["dt_critical"] = grid.h, sim.dt, sim.dt_critical
    cfg["shape_family"] = getattr(sim, "shape", cfg.get("shape_family"))    # as resolved
    return sim


def run_scene(spec, comm=None):
    """Build, warm up, time; returns the run record."""
    import numba
    comm = common.world(comm)
    cfg = scene_config(spec)
    cfg["threads"] = numba.get_num_threads()
    mem = common.MemoryProbe(comm).start()
    sim = build_scene(cfg, comm)
    n_part = sim.particles.n_global()
    implicit = not sim.integrator.explicit
    if implicit:
        ksp = sim.integrator.system.ksp
        cfg.update(ksp_type=ksp.getType(), pc_type=ksp.getPC().getType())
        if cfg["pc_type"] in ("lu", "cholesky"):
            cfg["factor_solver"] = ksp.getPC().getFactorSolverType() or "petsc"
    steps = spec["steps"]
    for _ in range(spec["warmup"]):
        sim.step()
    if implicit:        # count the iterations of the measured steps only
        n_iter0, ksp0 = len(sim.integrator.iterations), sim.integrator.ksp_iterations
    timing = common.time_steps(sim, steps)
    wall, timers = timing["wall_s"], timing["timers"]
    peak, increase = mem.peak()
    m = {"particle_updates_per_s": n_part * steps / wall, "wall_per_step_s": wall / steps,
         "cpu_s": timing["cpu_s"], "cpu_utilization": timing["cpu_s"] / (wall * comm.size),
         "particle_updates_per_cpu_s": n_part * steps / timing["cpu_s"]}
    keys = [k for k in timers if implicit or k not in SUBSTAGES]
    for k in keys:
        m[f"t_{k}"] = timers[k] / steps
        m[f"frac_{k}"] = timers[k] / wall
    top = sum(timers[k] for k in timers if k not in SUBSTAGES)
    m["t_other"] = (wall - top) / steps
    m["frac_other"] = (wall - top) / wall
    if implicit:
        its = sim.integrator.iterations[n_iter0:]
        if timers["ksp"] > 0:
            m["assembly_over_ksp"] = timers["assembly"] / timers["ksp"]
        m["newton_iterations"] = float(np.mean(its))
        m["ksp_iterations_per_step"] = (sim.integrator.ksp_iterations - ksp0) / steps
        m["n_dofs"] = sim.integrator.system.A.getSize()[0]
    m["peak_rss_bytes"] = peak
    m["mem_bytes_per_particle"] = increase / n_part
    m["particle_array_bytes_per_particle"] = common.particle_bytes(sim) / n_part
    rec = common.make_record(spec["name"], cfg, n_part, common.global_cells(sim), steps, wall, m)
    if implicit:
        sim.integrator.system.destroy()
    del sim
    gc.collect()
    return rec


def thread_scenes(quick=False, scale=1.0):
    """The thread rows' scenes: the explicit MUSL scene with each of THREAD_SHAPES."""
    base = next(s for s in scenes(quick, scale) if s["name"] == "explicit-MUSL")
    return [dict(base, name=f"explicit-MUSL-{shape}", shape=shape) for shape in THREAD_SHAPES]


def run_threads(quick=False, scale=1.0, threads=THREADS, verbose=True, timeout=None):
    """The thread rows: for each thread count n a child process with NUMBA_NUM_THREADS=n
    runs thread_scenes. Returns dict(runs=[records], speedup={scene: {n: updates/s on n
    threads over 1 thread}}). Serial only (the children are plain processes)."""
    from .mpi_scaling import _child_env
    specs = thread_scenes(quick, scale)
    timeout = timeout or (600.0 if quick else 3600.0)
    tmp = tempfile.mkdtemp(prefix="fenicsmpm_threads_")
    runs = []
    try:
        spec_path = os.path.join(tmp, "spec.json")
        with open(spec_path, "w") as f:
            json.dump(specs, f)
        for n in threads:
            result = os.path.join(tmp, f"result_{n}.json")
            env = dict(_child_env(), NUMBA_NUM_THREADS=str(n))
            cmd = [sys.executable, "-m", "fenicsmpm.bench.throughput", "--thread-worker",
                   spec_path, result]
            load = common._load_average()
            if verbose:
                print(f"[{CASE}] thread rows on {n} thread(s), load average {load} ...", flush=True)
            r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)
            if r.returncode != 0:
                raise RuntimeError(f"{CASE}: the {n}-thread child exited with status "
                                   f"{r.returncode}:\n{r.stderr[-3000:]}")
            with open(result) as f:
                for rec in json.load(f):
                    rec["load_average_1min_before"] = load
                    runs.append(rec)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    speedup = {}
    for scene in dict.fromkeys(r["scene"] for r in runs):
        by = {r["threads"]: r["metrics"]["particle_updates_per_s"] for r in runs
              if r["scene"] == scene}
        if 1 in by:
            speedup[scene] = {str(n): v / by[1] for n, v in sorted(by.items())}
            for r in runs:
                if r["scene"] == scene:
                    r["metrics"]["speedup_over_1_thread"] = by[r["threads"]] / by[1]
    return dict(runs=runs, speedup=speedup, command=f"NUMBA_NUM_THREADS=N {sys.executable} -m "
                f"fenicsmpm.bench.throughput --thread-worker SPEC RESULT")


def lu_times(cells=(24, 48, 96, 164), shapes=("auto", None), solvers=("petsc", "mumps"),
             repeats=3, comm=None):
    """The direct solvers on the quasi-static block's tangent (linear_system.MUMPS_FROM_DOFS):
    for each grid size and shape family, after one load step, the fastest of `repeats`
    numeric refactorizations plus a solve per LU solver type. Returns rows (cells, shape,
    dofs, {solver: seconds}); serial (MUMPS runs on one rank here)."""
    from petsc4py import PETSc
    rows = []
    for n in cells:
        for shape in shapes:
            sim = build_scene(scene_config(dict(name="lu", integrator="QuasiStatic",
                                                scheme="QuasiStatic", cells=n, per_cell=2,
                                                steps=1, warmup=0, shape=shape)), comm)
            sim.run(steps=1)
            A = sim.integrator.system.A
            times = {}
            for solver in solvers:
                ksp = PETSc.KSP().create(A.getComm())
                ksp.setOperators(A)
                ksp.setType("preonly")
                ksp.getPC().setType("lu")
                ksp.getPC().setFactorSolverType(solver)
                b = A.createVecLeft()
                b.set(1.0)
                x = b.duplicate()
                ksp.setUp()                   # the symbolic factorization, done once a run
                best = np.inf
                for k in range(repeats):
                    A.scale(2.0 if k % 2 else 0.5)    # new values: a numeric refactorization
                    t0 = time.perf_counter()
                    ksp.setUp()
                    ksp.solve(b, x)
                    best = min(best, time.perf_counter() - t0)
                times[solver] = best
                ksp.destroy()
            rows.append((n, sim.shape, A.getSize()[0], times))
    return rows


def _thread_worker(spec_path, result_path):
    """One thread-row child: run the scenes of SPEC on this process's numba threads."""
    import numba
    with open(spec_path) as f:
        specs = json.load(f)
    out = []
    for spec in specs:
        rec = run_scene(spec)
        n = numba.get_num_threads()
        rec.update(scene=spec["name"], threads=n,
                   name=f"{spec['name']} / {n} thread{'s' if n > 1 else ''}")
        out.append(rec)
    with open(result_path, "w") as f:
        json.dump(common._clean(out), f)


def _stacks(runs):
    """Exclusive per-stage seconds per step, for the stacked bars (assembly and ksp are taken
    out of solve; stages added to sim.timers later are drawn before "other")."""
    extra = sorted({k[2:] for r in runs for k in r["metrics"] if k.startswith("t_")}
                   - set(STAGES) - set(SUBSTAGES) - {"other"})
    names = (list(STAGES[:3]) + ["solve (residual)", "assembly", "ksp"] + list(STAGES[4:])
             + extra + ["other"])
    stacks = {}
    for k in names:
        vals = []
        for r in runs:
            m = r["metrics"]
            if k == "solve (residual)":
                vals.append(m.get("t_solve", 0.0) - m.get("t_assembly", 0.0) - m.get("t_ksp", 0.0))
            else:
                vals.append(m.get(f"t_{k}", 0.0))
        stacks[k] = vals
    return stacks


def plot(doc, path, comm):
    runs = doc["runs"]
    fig, axes = common.new_figure(ncols=2, size=(6.8, 4.8))
    labels = [f"{r['name']}\n{r['n_particles']:,} p" for r in runs]
    stacks = _stacks(runs)
    ann = [f"{r['metrics']['particle_updates_per_s'] / 1e6:.3g} M upd/s" for r in runs]
    common.stacked_bars(axes[0, 0], labels, stacks, ann, ylabel="time per step [s]",
                        legend=None)
    axes[0, 0].set_title("time per step by stage", fontsize=9)
    per = {k: [1e9 * v / r["n_particles"] for v, r in zip(vals, runs)]
           for k, vals in stacks.items()}
    common.stacked_bars(axes[0, 1], labels, per, ylabel="time per particle update [ns]")
    tgt = 1e9 / TARGETS["default_particle_updates_per_s_1_thread"]
    axes[0, 1].axhline(tgt, color="k", ls="--", lw=0.8)
    axes[0, 1].text(-0.45, tgt, f"issue 16, default on one core: {tgt:.0f} ns", fontsize=7,
                    ha="left", va="bottom")
    axes[0, 1].set_title("per particle (comparable across sizes)", fontsize=9)
    return common.save_figure(fig, path, comm, title=common.figure_title(doc, "throughput"))


def print_report(doc, comm):
    cols = [("run", "name"), ("particles", "n_particles"), ("steps", "steps"),
            ("wall [s]", "wall_s"),
            ("updates/s", lambda r: r["metrics"]["particle_updates_per_s"]),
            ("s/step", lambda r: r["metrics"]["wall_per_step_s"]),
            ("cpu/wall", lambda r: r["metrics"]["cpu_utilization"]),
            ("assembly/ksp", lambda r: r["metrics"].get("assembly_over_ksp")),
            ("newton its", lambda r: r["metrics"].get("newton_iterations")),
            ("B/particle", lambda r: r["metrics"]["mem_bytes_per_particle"])]
    common.print_table(doc["runs"], cols, comm, title=common.table_title(doc))
    stage_cols = [("run", "name")] + [
        (k, (lambda k: lambda r: r["metrics"].get(f"frac_{k}"))(k))
        for k in list(STAGES) + list(SUBSTAGES) + ["other"]]
    common.print_table(doc["runs"], stage_cols, comm, title="fraction of the wall time per stage "
                       "(assembly and ksp are parts of solve)")
    for r in doc["runs"]:
        m = r["metrics"]
        if r["config"]["integrator"] == "Explicit":
            continue                  # the standard family: judged in the thread rows below
        elif "assembly_over_ksp" in m and m["assembly_over_ksp"] is not None:
            common.say(comm, f"  {r['name']}: assembly/KSP = {m['assembly_over_ksp']:.3g} vs "
                       f"target <= 1: {'met' if m['assembly_over_ksp'] <= 1 else 'NOT met'}")
    th = doc.get("threads")
    if th and th.get("runs"):
        cols = [("run", "name"), ("particles", "n_particles"), ("threads", "threads"),
                ("updates/s", lambda r: r["metrics"]["particle_updates_per_s"]),
                ("speed-up", lambda r: r["metrics"].get("speedup_over_1_thread")),
                ("cpu/wall", lambda r: r["metrics"]["cpu_utilization"]),
                ("shape", lambda r: r["metrics"].get("frac_shape")),
                ("p2g", lambda r: r["metrics"].get("frac_p2g")),
                ("g2p", lambda r: r["metrics"].get("frac_g2p")),
                ("constitutive", lambda r: r["metrics"].get("frac_constitutive")),
                ("load before", "load_average_1min_before")]
        common.print_table(th["runs"], cols, comm, title="one process on 1 and 2 numba threads "
                           "(NUMBA_NUM_THREADS; cpu/wall: CPU seconds per wall second; shape..."
                           "constitutive: fractions of the step)")
        for r in th["runs"]:              # the default family against issue 16's targets
            nt = r["config"].get("threads", 1)
            key = f"default_particle_updates_per_s_{nt}_thread{'s' if nt > 1 else ''}"
            if r["config"].get("shape_family") != DEFAULT_SHAPE or key not in TARGETS:
                continue
            u, t = r["metrics"]["particle_updates_per_s"], TARGETS[key]
            common.say(comm, f"  {r['name']} (the default shape here): {u / 1e6:.2f} M "
                       f"updates/s vs target {t / 1e6:.0f} M: {'met' if u >= t else 'NOT met'}")
    for k, v in PEERS.items():
        common.say(comm, f"  peer: {k} = {v / 1e6:.2f} M")


def run(quick=False, out="bench-results", comm=None, scale=1.0, verbose=True, threads=THREADS):
    """Run the case, write out/throughput.json and out/throughput.png, print the table.
    Returns the result dict (on every rank). threads: the thread counts of the thread rows
    (run_threads; () for none; skipped under MPI)."""
    comm = common.world(comm)
    runs = []
    for spec in scenes(quick, scale):
        if verbose:
            common.say(comm, f"[{CASE}] {spec['name']}: {spec['cells']}^2 cells, "
                       f"{spec['per_cell']}x{spec['per_cell']} ppc, {spec['warmup']} warm-up + "
                       f"{spec['steps']} steps ...")
        runs.append(run_scene(spec, comm))
        if verbose:
            r = runs[-1]
            common.say(comm, f"    {r['n_particles']:,} particles, {r['wall_s']:.3g} s, "
                       f"{r['metrics']['particle_updates_per_s']:.3g} updates/s")
    extra = {}
    if threads and comm.size == 1:
        extra["threads"] = run_threads(quick, scale, tuple(threads), verbose)
    doc = common.result(CASE, runs, comm, quick=quick, scale=scale, targets=TARGETS, peers=PEERS,
                        **extra)
    common.write_result(doc, out, comm)
    plot(doc, os.path.join(out, f"{CASE}.png"), comm)
    if verbose:
        print_report(doc, comm)
    return doc


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m fenicsmpm.bench.throughput",
                                 description=f"benchmark case {CASE} (or, with --thread-worker, "
                                             f"one thread-row child)")
    ap.add_argument("--thread-worker", nargs=2, metavar=("SPEC", "RESULT"),
                    help="internal: run the scenes of SPEC on this process's threads")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default="bench-results")
    args = ap.parse_args(argv)
    if args.thread_worker:
        _thread_worker(*args.thread_worker)
    else:
        run(quick=args.quick, out=args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
