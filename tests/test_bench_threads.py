"""Benchmark options of issue 16: `mpi-scaling --ranks N,N,... --weak` (the command line,
a tiny weak-scaling run with its per-stage efficiencies) and the `throughput` thread rows
(one child process per NUMBA_NUM_THREADS). Tiny problems; the launching tests run serially
only (they start their own processes)."""
import argparse
import os
import shutil

import pytest
from mpi4py import MPI

from fenicsmpm import bench
from fenicsmpm.bench import mpi_scaling, throughput
from fenicsmpm.bench.__main__ import main
from fenicsmpm.kernels.threads import MIN_CHUNK

comm = MPI.COMM_WORLD
serial_only = pytest.mark.skipif(comm.size > 1, reason="launches its own processes")


def test_rank_list():
    assert mpi_scaling.rank_list("1,2,4,8,16") == (1, 2, 4, 8, 16)
    assert mpi_scaling.rank_list("2,1") == (2, 1)
    for bad in ("2,4", "1,1", "1,x", "", "0,1"):
        with pytest.raises(argparse.ArgumentTypeError):
            mpi_scaling.rank_list(bad)
    with pytest.raises(ValueError, match="including 1"):
        mpi_scaling.run(ranks=(2, 4), verbose=False)


def test_cli_passes_case_options(monkeypatch, tmp_path):
    """python -m fenicsmpm.bench mpi-scaling --ranks 1,2,4 --weak reaches run() by name."""
    got = {}

    def fake(quick=False, out=None, ranks=None, weak=None):
        got.update(quick=quick, out=out, ranks=ranks, weak=weak)

    fake.__module__ = mpi_scaling.__name__          # its options: mpi_scaling.add_arguments
    monkeypatch.setitem(bench.CASES, "mpi-scaling", fake)
    assert main(["mpi-scaling", "--quick", "--ranks", "1,2,4", "--weak", "--out", str(tmp_path)]) == 0
    assert got == dict(quick=True, out=str(tmp_path), ranks=(1, 2, 4), weak=True)
    assert main(["mpi-scaling", "--out", str(tmp_path)]) == 0
    assert got["ranks"] == mpi_scaling.RANKS and got["weak"] is False
    with pytest.raises(SystemExit):                # not an option of throughput
        main(["throughput", "--ranks", "1,2"])


@serial_only
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not on PATH")
def test_weak_scaling_tiny(tmp_path):
    doc = mpi_scaling.run(quick=True, out=str(tmp_path), scale=0.02, steps=2, repeats=1,
                          rounds=1, ranks=(1, 2), weak=True, verbose=False, timeout=300)
    assert doc["mode"] == "weak" and doc["ranks"] == [1, 2]
    assert os.path.isfile(tmp_path / "mpi-scaling.json")
    for scene in ("explicit-MUSL", "implicit-Newmark"):
        by = {r["ranks"]: r for r in doc["runs"] if r["scene"] == scene}
        p1, p2 = by[1]["n_particles"], by[2]["n_particles"]
        assert 1.8 < p2 / p1 < 2.2, (scene, p1, p2)        # twice the particles on 2 ranks
        m1, m2 = by[1]["metrics"], by[2]["metrics"]
        t1, t2 = m1["wall_per_step_s"], m2["wall_per_step_s"]
        eff = (p2 / (2 * t2)) / (p1 / t1)
        assert abs(m2["efficiency"] - eff) <= 1e-9 * eff and abs(m1["efficiency"] - 1) < 1e-12
        assert abs(doc["scaling"][scene]["efficiency_2_ranks"] - eff) <= 1e-9 * eff
        for k in ("locate", "shape", "p2g", "g2p", "constitutive"):
            e = (p2 / (2 * m2[f"t_{k}"])) / (p1 / m1[f"t_{k}"])
            assert abs(m2[f"efficiency_{k}"] - e) <= 1e-9 * e, k
        assert by[2]["config"]["threads_per_rank"] == 1


@serial_only
def test_throughput_thread_rows():
    """One child per thread count runs the explicit scene with each shape family."""
    th = throughput.run_threads(quick=True, scale=0.2, threads=(1, 2), verbose=False)
    rows = {(r["scene"], r["threads"]): r for r in th["runs"]}
    assert set(rows) == {(f"explicit-MUSL-{s}", n) for s in throughput.THREAD_SHAPES for n in (1, 2)}
    for (scene, n), r in rows.items():
        assert r["config"]["threads"] == n
        assert r["config"]["shape_family"] == scene.rsplit("-", 1)[1]
        assert r["n_particles"] >= 2 * MIN_CHUNK            # large enough to be cut into chunks
        m = r["metrics"]
        assert m["particle_updates_per_s"] > 0
        assert abs(m["speedup_over_1_thread"] - th["speedup"][scene][str(n)]) < 1e-12
    assert all(th["speedup"][s]["1"] == 1.0 for s in th["speedup"])
