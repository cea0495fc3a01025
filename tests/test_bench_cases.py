"""Tests for the benchmark cases `accuracy` and `mpi-scaling` in tiny modes.

Run serially and under mpirun -n 2. `mpi-scaling` launches its own `mpirun -n 1` and
`mpirun -n 2`, so it runs only serially (under an MPI size > 1 the test checks that it
refuses)."""
import json
import os
import shutil

import pytest
from mpi4py import MPI

from fenicsmpm import bench
from fenicsmpm.bench import accuracy, common, mpi_scaling

comm = MPI.COMM_WORLD

V1_CELLS = (10, 20)
V2_CELLS = (5, 10)


@pytest.fixture(scope="module")
def shared_dir(shared_module_tmp_path):
    return shared_module_tmp_path


def _load(path):
    with open(path) as f:
        return json.load(f)


def _check_schema(data, case):
    assert data["case"] == case
    assert set(data) >= {"case", "quick", "machine", "runs"}
    m = data["machine"]
    assert set(m) >= {"cores", "ranks", "cpu", "versions", "timestamp", "load_average_1min"}
    for r in data["runs"]:
        assert set(r) >= {"name", "config", "n_particles", "n_cells", "steps", "wall_s",
                          "metrics"}
        assert set(r["config"]) >= {"integrator", "scheme", "shape", "h", "dt", "ppc",
                                    "cell_type"}
        assert isinstance(r["n_particles"], int) and r["n_particles"] > 0
        assert isinstance(r["n_cells"], int) and r["n_cells"] > 0
        assert r["steps"] >= 1 and r["wall_s"] > 0
        for k, v in r["metrics"].items():
            assert v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)), k


def _is_png(path):
    with open(path, "rb") as f:
        return os.path.getsize(path) > 0 and f.read(8) == b"\x89PNG\r\n\x1a\n"


# ============================================================================ accuracy
@pytest.fixture(scope="module")
def tiny_accuracy(shared_dir):
    out = os.path.join(shared_dir, "accuracy")
    doc = accuracy.run(quick=True, out=out, v1_cells=V1_CELLS, v2_cells=V2_CELLS, repeats=1,
                       verbose=False)
    return out, doc


def test_accuracy_registered():
    assert bench.get_case("accuracy") is accuracy.run


def test_accuracy_json(tiny_accuracy):
    out, doc = tiny_accuracy
    data = _load(os.path.join(out, "accuracy.json"))
    assert data == doc
    _check_schema(data, "accuracy")
    assert data["machine"]["ranks"] == comm.size
    v1 = [r for r in data["runs"] if r["problem"] == "V1"]
    v2 = [r for r in data["runs"] if r["problem"] == "V2"]
    amps = data["v1_amplitudes"]
    assert len(v1) == 2 * len(amps) * len(V1_CELLS) and len(v2) == len(V2_CELLS)
    for r in v1:
        for k in ("period_error", "rms_velocity_error", "max_energy_error"):
            assert r["metrics"][k] is not None and r["metrics"][k] >= 0, k
        assert r["metrics"]["energy_drift"] is not None
        assert r["config"]["cells_along"] in V1_CELLS
        expl = r["config"]["integrator"] == "Explicit"
        assert r["config"]["scheme"] == ("MUSL" if expl else "Newmark")
        # dt = cfl 0.2 h / c (explicit) or 5 h / c (Newmark), c = 10
        ratio = 0.2 if expl else 5.0
        assert abs(r["config"]["dt"] - ratio * r["config"]["h"] / 10.0) < 1e-12
    for r in v2:
        for k in ("stress_error", "top_settlement_error"):
            assert r["metrics"][k] is not None and r["metrics"][k] >= 0, k
        assert r["config"]["integrator"] == "QuasiStatic" and r["steps"] == accuracy.LOAD_STEPS
    for c in data["convergence"]:
        assert len(c["h"]) == len(c["error"]) == len(c["wall_s"])
        assert c["slope"] is None or isinstance(c["slope"], float)


def test_accuracy_v2_stress_error_decreases(tiny_accuracy):
    _, doc = tiny_accuracy
    v2 = sorted((r for r in doc["runs"] if r["problem"] == "V2"),
                key=lambda r: r["config"]["cells_along"])
    coarse, fine = v2[0]["metrics"]["stress_error"], v2[1]["metrics"]["stress_error"]
    assert fine < coarse, (f"V2 stress error {fine:.4g} on {v2[1]['config']['cells_along']} "
                           f"cells is not below {coarse:.4g} on {v2[0]['config']['cells_along']}")
    c = accuracy._find(doc["convergence"], "V2", "QuasiStatic", "stress_error")
    assert c["slope"] > 0.5


def test_accuracy_v1_explicit_period(tiny_accuracy):
    """V1 explicit MUSL period error below 1 % on the finest mesh (every amplitude)."""
    _, doc = tiny_accuracy
    for a in doc["v1_amplitudes"]:
        runs = [r for r in doc["runs"]
                if r["problem"] == "V1" and r["series"] == f"explicit-MUSL v0={a:g}"]
        finest = max(runs, key=lambda r: r["config"]["cells_along"])
        err = finest["metrics"]["period_error"]
        assert err < 0.01, (f"{finest['name']}: period error {100 * err:.3f} % (tol 1 %)")


def test_accuracy_pngs(tiny_accuracy):
    out, _ = tiny_accuracy
    for name in ("accuracy_convergence.png", "accuracy_pareto.png"):
        assert _is_png(os.path.join(out, name)), name


def test_accuracy_helpers():
    import numpy as np
    t = np.linspace(0.0, 2.0, 2001)
    assert abs(accuracy.measured_period(t, np.cos(2 * np.pi * t / 0.8)) - 0.8) < 1e-5
    # chatter around one crossing counts once when merged
    v = np.cos(2 * np.pi * t / 0.8)
    v[195:205] = 1e-3 * (-1.0) ** np.arange(10)
    assert len(accuracy.zero_crossings(t, v)) > 5
    assert len(accuracy.zero_crossings(t, v, merge=0.2)) == 5
    assert abs(common.fit_slope([0.1, 0.05, 0.025], [4e-2, 1e-2, 2.5e-3]) - 2.0) < 1e-12
    assert common.fit_slope([0.1, 0.05], [0.0, 1e-3]) is None
    with pytest.raises(ValueError):
        accuracy.run(v1_cells=(0,), out="unused", verbose=False)


# ============================================================================ mpi-scaling
def test_mpi_scaling_registered():
    assert bench.get_case("mpi-scaling") is mpi_scaling.run


def test_mpi_scaling_scenes_full_size():
    """Full-size scenes as specified (without running them): >= 4e5 particles explicit,
    >= 1e5 implicit at dt = 5 dt_critical."""
    from fenicsmpm.bench import throughput
    full = {s["name"]: s for s in mpi_scaling.scenes(quick=False)}
    assert set(full) == {"explicit-MUSL", "implicit-Newmark"}
    for s in full.values():
        cfg = throughput.scene_config(s)
        bx, by = cfg["block_cells"]
        n = bx * by * cfg["ppc"]
        assert n >= (4e5 if s["integrator"] == "Explicit" else 1e5), (s["name"], n)
    assert full["implicit-Newmark"]["dt_factor"] == 5.0
    assert full["explicit-MUSL"]["scheme"] == "MUSL"


def test_mpi_scaling_child_env_and_command():
    env = mpi_scaling._child_env()
    assert env["OMPI_MCA_rmaps_base_oversubscribe"] == "1"
    cmd = mpi_scaling.launch_command(2, "S.json", "R.json", mpirun="mpirun")
    assert cmd[0] == "mpirun" and cmd[cmd.index("-n") + 1] == "2"
    assert cmd[-4:] == ["fenicsmpm.bench.mpi_scaling", "--worker", "S.json", "R.json"]
    assert ("--allow-run-as-root" in cmd) == (os.geteuid() == 0)


@pytest.mark.skipif(comm.size == 1, reason="checks the refusal under MPI size > 1")
def test_mpi_scaling_refuses_under_mpirun(shared_dir):
    with pytest.raises(RuntimeError, match="launches its own mpirun"):
        mpi_scaling.run(quick=True, out=shared_dir, verbose=False)


@pytest.fixture(scope="module")
def tiny_scaling(shared_dir):
    if comm.size > 1:
        pytest.skip("launches its own mpirun")
    if shutil.which("mpirun") is None:
        pytest.skip("mpirun is not on PATH (the case launches mpirun -n 1 and -n 2)")
    out = os.path.join(shared_dir, "scaling")
    doc = mpi_scaling.run(quick=True, out=out, scale=0.02, steps=2, repeats=1, rounds=1,
                          verbose=False, timeout=300)
    return out, doc


def test_mpi_scaling_json(tiny_scaling):
    out, doc = tiny_scaling
    data = _load(os.path.join(out, "mpi-scaling.json"))
    assert data == doc
    _check_schema(data, "mpi-scaling")
    assert {r["ranks"] for r in data["runs"]} == {1, 2}
    assert {r["config"]["ranks"] for r in data["runs"]} == {1, 2}
    scenes = {r["scene"] for r in data["runs"]}
    assert scenes == {"explicit-MUSL", "implicit-Newmark"}
    for scene in scenes:
        by = {r["ranks"]: r for r in data["runs"] if r["scene"] == scene}
        assert by[1]["n_particles"] == by[2]["n_particles"]
        t1 = by[1]["metrics"]["wall_per_step_s"]
        t2 = by[2]["metrics"]["wall_per_step_s"]
        assert abs(t1 - by[1]["wall_s"] / by[1]["steps"]) <= 1e-9 * t1
        assert abs(t2 - by[2]["wall_s"] / by[2]["steps"]) <= 1e-9 * t2
        eff = by[2]["metrics"]["efficiency"]
        assert abs(eff - t1 / (2 * t2)) <= 1e-9 * eff
        assert abs(by[2]["metrics"]["speedup"] - t1 / t2) <= 1e-9 * t1 / t2
        s = data["scaling"][scene]
        assert abs(s["efficiency_2_ranks"] - eff) <= 1e-9 * eff
        for n, r in by.items():
            m = r["metrics"]
            assert m["imbalance"] >= 1.0 and m["imbalance_start"] >= 1.0
            assert 0.0 <= m["frac_migration"] < 1.0 and 0.0 <= m["frac_exchange"] < 1.0
            assert m["t_migration"] >= 0 and m["t_exchange"] >= 0
            assert m["migration_calls_per_step"] >= 1.0
        # exchange is a no-op on one rank; on two it is real work
        assert by[2]["metrics"]["exchange_calls_per_step"] >= 1.0
    assert all(la.get("load_average_1min_before") is not None or os.name != "posix"
               for la in data["launches"])


def test_mpi_scaling_png(tiny_scaling):
    out, _ = tiny_scaling
    assert _is_png(os.path.join(out, "mpi-scaling.png"))
