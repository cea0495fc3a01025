"""The benchmark case `stability` (python -m fenicsmpm.bench stability) at its --quick size:
registry, CLI, JSON schema, PNG and the figures it reports. Serial and mpirun -n 2."""
import json
import os

import pytest
from mpi4py import MPI

from fenicsmpm import bench
from fenicsmpm.bench import stability
from fenicsmpm.bench.__main__ import main

comm = MPI.COMM_WORLD
# Serially the test runs the real --quick size through the CLI (about 6 s). Under MPI a step
# costs ~10x more on the shared 2-core machine, so the parallel run uses these smaller sizes
# (the same scenarios and assertions; the collapse keeps its 10 rows).
MPI_SIZES = dict(explicit_steps=400, implicit_steps=50, sweep_steps=100, courant_steps=30,
                 impact_cells=20)


@pytest.fixture(scope="module")
def quick(shared_module_tmp_path):
    out = os.path.join(shared_module_tmp_path, "stability")
    if comm.size == 1:
        assert main(["stability", "--quick", "--out", out]) == 0
    else:
        stability.run(quick=True, out=out, verbose=False, **MPI_SIZES)
    with open(os.path.join(out, "stability.json")) as f:
        return out, json.load(f)


def test_registered():
    assert "stability" in bench.case_names()
    assert bench.get_case("stability") is stability.run


def test_sizes():
    full, q = stability.SIZES["full"], stability.SIZES["quick"]
    assert full["explicit_steps"] == 10_000 and full["implicit_steps"] == 1_000
    assert set(full) == set(q)
    assert all(q[k] <= full[k] for k in q)
    assert min(stability.SWEEP_FACTORS) == 0.5 and max(stability.COURANTS) == 50.0
    assert {1.1, 1.25, 1.5} <= set(stability.SWEEP_FACTORS)
    with pytest.raises(TypeError, match="unknown size"):
        stability.run(quick=True, out="unused", verbose=False, no_such_size=3)
    with pytest.raises(ValueError, match="positive integer"):
        stability.run(quick=True, out="unused", verbose=False, explicit_steps=0)


def test_json_schema(quick):
    out, data = quick
    assert data["case"] == "stability" and data["quick"] is True
    assert data["machine"]["ranks"] == comm.size
    assert data["sizes"] == (stability.SIZES["quick"] if comm.size == 1
                             else dict(stability.SIZES["quick"], **MPI_SIZES))
    names = [r["name"] for r in data["runs"]]
    assert names[:2] == ["bar-explicit-MUSL", "bar-newmark"]
    assert {"collapse", "collapse-overload", "collapse-inversion", "impact-MUSL", "impact-USF",
            "impact-USL"} <= set(names)
    for r in data["runs"]:
        assert set(r) >= {"name", "config", "n_particles", "n_cells", "steps", "wall_s",
                          "metrics", "outcome"}
        assert set(r["config"]) >= {"integrator", "scheme", "shape", "h", "dt", "ppc",
                                    "cell_type"}
        assert r["n_particles"] > 0 and r["n_cells"] > 0 and r["steps"] >= 1
        for k, v in r["metrics"].items():
            assert v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)), k
    assert os.path.isfile(os.path.join(out, "stability.png"))
    with open(os.path.join(out, "stability.png"), "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_bar_figures(quick):
    _, data = quick
    runs = {r["name"]: r for r in data["runs"]}
    e, n = runs["bar-explicit-MUSL"], runs["bar-newmark"]
    assert e["steps"] == data["sizes"]["explicit_steps"] and e["outcome"] == "completed"
    assert abs(e["metrics"]["energy_drift"]) < 5e-4          # measured +3.2e-5
    assert n["steps"] == data["sizes"]["implicit_steps"] and n["outcome"] == "completed"
    assert n["metrics"]["energy_max"] <= 1.005                # measured 1.0028
    assert abs(n["config"]["dt_over_dt_critical"] - 5.0) < 1e-9


def test_sweeps(quick):
    _, data = quick
    for row in data["dt_sweep"]:
        if row["factor"] <= 1.0:
            assert row["accepted"] and row["outcome"] == "completed", row
            assert row["energy_max"] < 1.05, row
        else:
            assert not row["accepted"] and "exceeds the explicit critical time step" in row["message"]
            assert "forced_outcome" in row
    forced = {r["factor"]: r for r in data["dt_sweep"] if not r["accepted"]}
    # the forced runs show the real margin: bounded at 1.5, blown up (guard) at 2
    assert forced[1.5]["forced_outcome"] == "completed"
    assert forced[2.0]["forced_outcome"].startswith("RuntimeError: step ")
    assert [r["courant"] for r in data["courant_sweep"]] == list(stability.COURANTS)
    for row in data["courant_sweep"]:
        assert row["outcome"] == "completed" and row["finite"] == 1, row
        assert row["energy_max"] <= 1.01, row


def test_collapse_and_impact_figures(quick):
    _, data = quick
    runs = {r["name"]: r for r in data["runs"]}
    c = runs["collapse"]
    assert c["outcome"] == "completed"
    assert c["metrics"]["compaction_max"] >= 0.78 and c["metrics"]["min_det_F"] > 0
    assert c["metrics"]["finite_throughout"] == 1
    over = runs["collapse-overload"]
    assert over["metrics"]["finite_throughout"] == 1
    assert over["outcome"] == "completed" or over["outcome"].startswith(
        ("RuntimeError: step", "ParticlesLeftMesh: step"))
    # the neo-Hookean inversion bug (tests/stress/test_extreme_deformation.py) is recorded
    assert runs["collapse-inversion"]["outcome"] != "completed"
    for name in ("impact-MUSL", "impact-USF", "impact-USL", "impact-MUSL-neo-Hookean"):
        m = runs[name]["metrics"]
        assert m["momentum_error"] < 1e-12, name
        assert m["finite_throughout"] == 1, name
    assert runs["impact-MUSL"]["outcome"] == "completed"
