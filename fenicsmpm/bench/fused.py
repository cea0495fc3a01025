"""Benchmark case `fused`: the fused particle pass of kernels.fused against the separate
passes it replaces (issue 16).

    python -m fenicsmpm.bench fused [--quick] [--out DIR]

Kernels only (no mesh): n particles (full 1.0e6, quick 1.0e5) in 2D with `nv` nodes each
(4: standard MPM on quads; 9: GIMP), random node lists sorted by particle (the locality of
particles stored in fill order), random weights, gradients, nodal fields and plane-strain
particle states (kernels.fused._elastic_plane).
  elastic:  kernels.fused.elastic_step  against  transfer.incremental_F + the Jaumann
            linear-elastic stress + transfer.commit_step.
(A fused G2P + MUSL remap P2G was measured here too, at 0.86-1.0x of its two passes, and
dropped.)
Each pass: the fastest of `repeats` calls after one warm-up call, on numba's threads
(NUMBA_NUM_THREADS). Metrics: ms per call fused and separate, speed-up = separate / fused,
particle-updates/s of the fused pass. Writes fused.json and fused.png (bars per run)."""
import os

import numpy as np

from . import common

CASE = "fused"
SIZES = {"full": dict(n=1_000_000, repeats=7), "quick": dict(n=100_000, repeats=3)}


def _data(n, nv, rng):
    n_nodes = max(n // 4, 64)
    nodes = np.sort(rng.integers(0, n_nodes, size=(n, nv)).astype(np.int32), axis=0)
    N = rng.uniform(0.0, 0.5, (n, nv))
    dN = rng.standard_normal((n, nv, 2))
    F = np.tile(np.eye(3), (n, 1, 1))
    sigma = rng.standard_normal((n, 3, 3))
    sigma[:, 2, :2] = sigma[:, :2, 2] = 0.0          # plane strain: no out-of-plane shear
    return dict(nodes=nodes, N=N, dN=dN, w=1e-3 * rng.standard_normal((n_nodes, 2)), F=F,
                V=rng.uniform(0.5, 1.5, n), sigma=0.5 * (sigma + sigma.transpose(0, 2, 1)),
                work=np.zeros(n), inverted=np.zeros(n, np.int8))


def _passes(a):
    """{kernel: (fused, separate)} callables on the arrays a."""
    from ..kernels import transfer as kt
    from ..kernels.fused import elastic_step
    from ..materials.linear_elastic import linear_elastic_stress_kernel
    D, n = (0, 0), len(a["nodes"])
    dF, s_new, idx = np.empty((n, 3, 3)), np.empty((n, 3, 3)), np.arange(n)
    lam, mu = 5.8e5, 3.8e5

    def elastic_fused():
        elastic_step(D, a["nodes"], a["dN"], a["w"], 1e-3, lam, mu, a["F"], a["V"], a["sigma"],
                     a["work"], a["inverted"])

    def elastic_separate():
        kt.incremental_F(D, a["nodes"], a["dN"], a["w"], 1e-3, dF)
        linear_elastic_stress_kernel(idx, dF, a["sigma"], s_new, lam, mu)
        kt.commit_step(dF, a["F"], a["V"], a["sigma"], s_new, a["work"], a["inverted"])

    return dict(elastic=(elastic_fused, elastic_separate))


def run(quick=False, out="bench-results", comm=None, verbose=True):
    from numba import get_num_threads
    comm = common.world(comm)
    size = SIZES["quick" if quick else "full"]
    n, repeats = size["n"], size["repeats"]
    rng = np.random.default_rng(0)
    runs = []
    for nv in (4, 9):
        a = _data(n, nv, rng)
        for kernel, (fused, separate) in _passes(a).items():
            t_sep = common.fastest_call(repeats, separate)
            t_fused = common.fastest_call(repeats, fused)
            cfg = dict(integrator="Explicit", scheme="MUSL", shape="mpm" if nv == 4 else "cpgimp",
                       h=float("nan"), dt=float("nan"), ppc=4, cell_type="none (kernels only)",
                       kernel=kernel, nodes_per_particle=nv, threads=get_num_threads())
            m = dict(ms_fused=1e3 * t_fused, ms_separate=1e3 * t_sep, speed_up=t_sep / t_fused,
                     particle_updates_per_s=n / t_fused)
            runs.append(common.make_record(f"{kernel}-nv{nv}", cfg, n, 0, 1, t_fused, m))
    doc = common.result(CASE, runs, comm, quick=quick)
    common.write_result(doc, out, comm)
    if verbose:
        common.print_table([dict(name=r["name"], **r["metrics"]) for r in runs],
                           [("kernel", "name"), ("fused ms", "ms_fused"),
                            ("separate ms", "ms_separate"), ("speed-up", "speed_up"),
                            ("updates/s", "particle_updates_per_s")],
                           comm=comm, title=common.table_title(doc, f"{n:,} particles"))
    fig, axes = common.new_figure(size=(6.0, 4.0))
    ax = axes[0][0]
    if comm.rank == 0:
        names = [r["name"] for r in runs]
        k = np.arange(len(runs))
        ax.bar(k - 0.2, [r["metrics"]["ms_separate"] for r in runs], 0.4, label="separate passes")
        ax.bar(k + 0.2, [r["metrics"]["ms_fused"] for r in runs], 0.4, label="fused")
        ax.set_xticks(k)
        ax.set_xticklabels(names)
        ax.set_ylabel(f"ms per call ({n:,} particles)")
        ax.legend(fontsize=8)
    common.save_figure(fig, os.path.join(out, f"{CASE}.png"), comm,
                       title=common.figure_title(doc, "fused particle passes"))
    return doc
