"""Benchmark case `shape-cost`: cost per particle-step of each shape family relative to
standard MPM (issue 16 target: the wide families at most 1.3x).

    python -m fenicsmpm.bench shape-cost [--quick]

Scene: unit square of n x n quadrilateral cells (full n = 160, quick n = 80: at n = 40 the
fixed cost of a step was 35-60 % of the standard family's, 0.24-0.40 us per particle-step
against 0.16 at n = 160), an elastic block over [0.2, 0.8]^2
(E = 1e6, nu = 0.3, rho = 1000) with 2 x 2 particles per cell (36,864 particles full, 9,216
quick), spinning slowly (v = 0.1 (-(y - 1/2), x - 1/2)) under
gravity; explicit MUSL at dt = 0.5 h / c_p. For each family: `warmup` untimed steps (JIT and
cache loading), then `steps` timed steps (common.time_steps), the fastest of `repeats` runs.

Row cpdi2-triangle: CPDI2 on a triangle mesh of about the same cell count (round(n / sqrt 2)
squares per side, split in two); doc["triangle_over_cpgimp"] its cost over cpGIMP's (issue 16
target 1.5).

Metrics: wall_per_particle_step_s, ratio_to_mpm (the same for standard MPM: 1), the
stage timers per particle-step (shape, p2g, g2p, constitutive, ...), nodes_per_particle
(the stencil width). Output: shape-cost.json, shape-cost.png (stacked stage times per family)
and a table."""
import os
import time

import numpy as np

from . import common

CASE = "shape-cost"
SHAPES = ("mpm", "ugimp", "cpgimp", "cpdi1", "cpdi2", "cpdi2-triangle")
TRIANGLE_TARGET = 1.5        # issue 16: CPDI2 on triangles at most 1.5x cpGIMP on quads
SIZES = {"full": dict(n=160, steps=20, repeats=3), "quick": dict(n=80, steps=5, repeats=2)}
TARGET_RATIO = 1.3         # issue 16: the wide families at most 1.3x the standard family per particle-step


def _scene(shape, n, comm):
    """The scene; shape "cpdi2-triangle" is CPDI2 on a triangle mesh of round(n / sqrt 2)
    squares per side, each split in two: about the cell (and particle) count of the quads."""
    import fenicsmpm as fm
    from dolfinx import mesh as dmesh
    from ..grid import vertex_ghost_partitioner
    kw = {} if shape == "mpm" else {"partitioner": vertex_ghost_partitioner()}
    if shape == "cpdi2-triangle":
        shape, n = "cpdi2", max(1, int(round(n / np.sqrt(2.0))))
        msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [n, n],
                                     dmesh.CellType.triangle, **kw)
    else:
        msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [n, n],
                                     dmesh.CellType.quadrilateral, **kw)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    pts = fm.Particles.fill(grid, mat, per_cell=2,
                            region=lambda x: np.all((x > 0.2) & (x < 0.8), axis=1),
                            velocity=lambda x: 0.1 * np.c_[-(x[:, 1] - 0.5), x[:, 0] - 0.5])
    sim = fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt=0.5 * (1.0 / n) / mat.p_wave_speed,
                        gravity=(0.0, -9.81), shape=shape)
    return sim


def run_one(shape, n, steps, warmup, comm):
    t0 = time.perf_counter()
    sim = _scene(shape, n, comm)
    setup = time.perf_counter() - t0
    t = common.time_steps(sim, steps, warmup=warmup)
    npart = sim.particles.n_global()
    width = sim.nodes.shape[1]
    return sim, t, npart, setup, width


def run(quick=False, out="bench-results", comm=None, n=None, steps=None, repeats=None,
        shapes=SHAPES, verbose=True):
    """Run the case, write out/shape-cost.json and shape-cost.png, print a table; returns the
    result dict."""
    comm = common.world(comm)
    size = dict(SIZES["quick" if quick else "full"])
    for k, v in (("n", n), ("steps", steps), ("repeats", repeats)):
        if v is not None:
            if not (isinstance(v, (int, np.integer)) and v >= 1):
                raise ValueError(f"{CASE}: {k!r} must be a positive integer, got {v!r}")
            size[k] = int(v)
    if "mpm" not in shapes:
        raise ValueError(f"{CASE}: 'shapes' must include 'mpm' (the reference)")
    t_start = time.perf_counter()
    runs, jit = [], {}
    for shape in shapes:
        t0 = time.perf_counter()
        sim = _scene(shape, 8, comm)                    # JIT / cache loading
        for _ in range(2):
            sim.step()
        jit[shape] = time.perf_counter() - t0
        best = None
        for _ in range(size["repeats"]):
            sim, t, npart, setup, width = run_one(shape, size["n"], size["steps"], 2, comm)
            if best is None or t["wall_s"] < best[1]["wall_s"]:
                best = (sim, t, npart, setup, width)
        sim, t, npart, setup, width = best
        ps = npart * size["steps"]
        m = dict(wall_per_particle_step_s=t["wall_s"] / ps, cpu_s=t["cpu_s"], setup_s=setup,
                 nodes_per_particle=width,
                 **{f"t_{k}_per_particle_step_s": v / ps for k, v in t["timers"].items()})
        tri = shape.endswith("triangle")
        cfg = dict(integrator="Explicit", scheme="MUSL", shape=sim.shape, h=sim.grid.h, dt=sim.dt,
                   ppc=4, cell_type="triangle" if tri else "quadrilateral",
                   cells_along=int(round(size["n"] / np.sqrt(2.0))) if tri else size["n"])
        rec = common.make_record(f"{shape}", cfg, npart,
                                 comm.allreduce(sim.grid.n_owned_cells) if comm.size > 1
                                 else sim.grid.n_owned_cells, size["steps"], t["wall_s"], m)
        runs.append(rec)
    ref = next(r for r in runs if r["name"] == "mpm")["metrics"]["wall_per_particle_step_s"]
    for r in runs:
        r["metrics"]["ratio_to_mpm"] = r["metrics"]["wall_per_particle_step_s"] / ref
    ratios = {r["name"]: r["metrics"]["ratio_to_mpm"] for r in runs}
    if "cpgimp" in ratios and "cpdi2-triangle" in ratios:
        ratios_extra = dict(triangle_over_cpgimp=ratios["cpdi2-triangle"] / ratios["cpgimp"],
                            triangle_target=TRIANGLE_TARGET)
    else:
        ratios_extra = {}
    doc = common.result(CASE, runs, comm, quick=quick, jit_s=jit, ratio_to_mpm=ratios,
                        target_ratio=TARGET_RATIO,
                        within_target={k: v <= TARGET_RATIO for k, v in ratios.items()},
                        **ratios_extra,
                        total_wall_s=time.perf_counter() - t_start)
    common.write_result(doc, out, comm)
    _plot(doc, out, comm)
    if verbose:
        common.print_table(runs, [("family", "name"), ("particles", "n_particles"),
                                  ("steps", "steps"), ("wall [s]", "wall_s"),
                                  ("us / particle-step", lambda r: 1e6 * r["metrics"]["wall_per_particle_step_s"]),
                                  ("x mpm", lambda r: r["metrics"]["ratio_to_mpm"]),
                                  ("nodes/particle", lambda r: r["metrics"]["nodes_per_particle"]),
                                  ("shape us/ps", lambda r: 1e6 * r["metrics"]["t_shape_per_particle_step_s"])],
                           comm, title=f"\n== {CASE}{' (quick)' if quick else ''}: cost per particle-step "
                                       f"relative to standard MPM (target <= {TARGET_RATIO:g}x)")
    return doc


def _plot(doc, out, comm):
    fig, axes = common.new_figure(size=(7.0, 4.5))
    runs = doc["runs"]
    stages = [k[2:-len("_per_particle_step_s")] for k in runs[0]["metrics"]
              if k.startswith("t_") and k.endswith("_per_particle_step_s")]
    stacks = {s: [1e6 * r["metrics"][f"t_{s}_per_particle_step_s"] for r in runs] for s in stages}
    common.stacked_bars(axes[0, 0], [r["name"] for r in runs], stacks,
                        annotations=[f"{r['metrics']['ratio_to_mpm']:.2f}x" for r in runs],
                        ylabel="microseconds per particle-step")
    return common.save_figure(fig, os.path.join(out, f"{CASE}.png"), comm,
                              title=common.figure_title(doc, CASE))
