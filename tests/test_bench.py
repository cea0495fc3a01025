"""Tests for the benchmark runner (fenicsmpm.bench): a tiny `throughput` run, the JSON
schema, the case registry and the CLI. Run serially and under mpirun -n 2."""
import json
import math
import os

import pytest
from mpi4py import MPI

from fenicsmpm import bench
from fenicsmpm.bench import common, throughput
from fenicsmpm.bench.__main__ import main

comm = MPI.COMM_WORLD

TINY = 0.02          # of the --quick particle counts (a few thousand particles)


@pytest.fixture(scope="module")
def shared_dir(shared_module_tmp_path):
    return shared_module_tmp_path


@pytest.fixture(scope="module")
def tiny(shared_dir):
    out = os.path.join(shared_dir, "tiny")
    doc = throughput.run(quick=True, out=out, scale=TINY, verbose=False)
    return out, doc


def _load(path):
    with open(path) as f:
        return json.load(f)


def test_json_schema(tiny):
    out, doc = tiny
    path = os.path.join(out, "throughput.json")
    assert os.path.isfile(path)
    data = _load(path)
    assert data == doc
    assert data["case"] == "throughput"
    m = data["machine"]
    for k in ("cores", "ranks", "versions", "timestamp"):
        assert k in m
    assert m["cores"] == os.cpu_count() and m["ranks"] == comm.size
    assert set(m["versions"]) >= {"dolfinx", "petsc", "numba", "numpy", "python"}
    assert "hostname" not in json.dumps(data).lower()
    assert [r["name"] for r in data["runs"]] == ["explicit-MUSL", "implicit-Newmark"]
    for r in data["runs"]:
        assert set(r) >= {"config", "n_particles", "n_cells", "steps", "wall_s", "metrics"}
        assert set(r["config"]) >= {"integrator", "scheme", "shape", "h", "dt", "ppc", "cell_type"}
        assert isinstance(r["n_particles"], int) and isinstance(r["n_cells"], int)
        assert r["steps"] >= 1 and r["wall_s"] > 0
        for k, v in r["metrics"].items():
            assert isinstance(v, (int, float)) and not isinstance(v, bool), k
        for stage in ("locate", "shape", "p2g", "solve", "g2p", "constitutive"):
            assert r["metrics"][f"t_{stage}"] >= 0
            assert f"frac_{stage}" in r["metrics"]
    imp = data["runs"][1]["metrics"]
    for k in ("t_assembly", "t_ksp", "assembly_over_ksp", "newton_iterations"):
        assert imp[k] > 0, k
    assert "t_assembly" not in data["runs"][0]["metrics"]


def test_counts_and_throughput(tiny):
    out, doc = tiny
    data = _load(os.path.join(out, "throughput.json"))
    for r in data["runs"]:
        cfg = r["config"]
        bx, by = cfg["block_cells"]
        assert r["n_particles"] == bx * by * cfg["ppc"]
        assert r["n_cells"] == cfg["grid_cells"][0] * cfg["grid_cells"][1]
        rate = r["metrics"]["particle_updates_per_s"]
        assert rate > 0
        expect = r["n_particles"] * r["steps"] / r["wall_s"]
        assert abs(rate - expect) <= 1e-9 * expect


def test_particle_count_is_global(tiny):
    """n_particles is the global count of the scene (summed over ranks)."""
    _, doc = tiny
    r = doc["runs"][0]
    sim = throughput.build_scene(dict(r["config"]), comm)
    n_local = len(sim.particles)
    assert comm.allreduce(n_local) == r["n_particles"] == sim.particles.n_global()


def test_png(tiny):
    out, _ = tiny
    png = os.path.join(out, "throughput.png")
    assert os.path.isfile(png) and os.path.getsize(png) > 0
    with open(png, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_implicit_dt_is_five_critical(tiny):
    _, doc = tiny
    cfg = doc["runs"][1]["config"]
    assert math.isclose(cfg["dt"], 5.0 * cfg["dt_critical"], rel_tol=1e-12)
    assert cfg["shape_family"] == "cpgimp"            # shape="auto" resolved (elastic, lattice)
    assert (cfg["ksp_type"], cfg["pc_type"]) == ("gmres", "bjacobi")      # Newmark's default


def test_scenes_full_size():
    """Full-size problem sizes as specified (without running them)."""
    full = {s["name"]: s for s in throughput.scenes(quick=False)}
    assert set(full) == {"explicit-MUSL", "explicit-USL", "explicit-USF", "implicit-Newmark",
                         "implicit-Newmark-mpm", "implicit-Newmark-mpm-lu",
                         "implicit-QuasiStatic", "implicit-QuasiStatic-mpm"}
    assert full["implicit-Newmark"]["shape"] == "auto"          # the defaults
    for s in full.values():
        cfg = throughput.scene_config(s)
        bx, by = cfg["block_cells"]
        n = bx * by * cfg["ppc"]
        assert n >= (1e6 if s["integrator"] == "Explicit" else 1e5)
        assert s["warmup"] >= 1
    quick = throughput.scenes(quick=True)
    assert [s["name"] for s in quick] == ["explicit-MUSL", "implicit-Newmark"]
    with pytest.raises(ValueError):
        throughput.scenes(scale=0)


def test_registry_and_unknown_case(capsys):
    assert "throughput" in bench.CASES
    assert bench.get_case("throughput") is throughput.run
    with pytest.raises(bench.UnknownCaseError, match="known cases: .*throughput"):
        bench.get_case("no-such-case")
    with pytest.raises(SystemExit):
        main(["no-such-case"])
    err = capsys.readouterr().err
    assert "no-such-case" in err and "throughput" in err


def test_register_custom_case(shared_dir):
    """A case added with register() runs through the CLI and the common record format."""
    def run(quick=False, out="bench-results", comm=comm):
        rec = common.make_record("r", dict(integrator="none", scheme="-", shape="-", h=1.0,
                                           dt=1.0, ppc=1, cell_type="-"),
                                 n_particles=10, n_cells=1, steps=2, wall_s=0.5,
                                 metrics={"x": 1.0, "y": float("nan")})
        doc = common.result("dummy-case", [rec], comm, quick=quick)
        common.write_result(doc, out, comm)
        return doc

    bench.register("dummy-case", run)
    try:
        out = os.path.join(shared_dir, "dummy")
        assert main(["dummy-case", "--quick", "--out", out]) == 0
        data = _load(os.path.join(out, "dummy-case.json"))
        assert data["quick"] is True
        assert data["runs"][0]["metrics"] == {"x": 1.0, "y": None}
    finally:
        bench.CASES.pop("dummy-case", None)
    with pytest.raises(ValueError, match="config lacks"):
        common.make_record("r", {}, 1, 1, 1, 1.0, {})


@pytest.mark.parametrize("shape", ["auto", None])
def test_three_dimensional_quasi_static_block(shape):
    """throughput's block as a 3D box (spec dim=3, hexahedra; the 3D rows of
    docs/guide/integrators.md): gravity in one quasi-static load step; the volume mean of
    sigma_zz is the weight over the base area, -rho g H / 2, to 1 % (measured 0.28 % with
    cpGIMP and the standard family, 8^3 cells)."""
    import numpy as np
    cfg = throughput.scene_config(dict(name="3d", integrator="QuasiStatic", scheme="QuasiStatic",
                                       cells=8, per_cell=2, steps=1, warmup=0, shape=shape,
                                       dim=3))
    assert cfg["cell_type"] == "hexahedron" and cfg["gravity"] == [0.0, 0.0, -throughput.GRAVITY]
    sim = throughput.build_scene(cfg)
    sim.step()
    assert sim.shape == ("cpgimp" if shape else "mpm")
    p = sim.particles
    assert p.n_global() == 4 * 4 * 6 * 8          # block_cells (4, 4, 6), 2 x 2 x 2 a cell
    mean = comm.allreduce(float(np.sum(p.stress[:, 2, 2] * p.V))) / comm.allreduce(float(np.sum(p.V)))
    H = (8 - throughput.MARGIN) * cfg["h"]
    assert mean == pytest.approx(-throughput.RHO * throughput.GRAVITY * H / 2, rel=1e-2)
    with pytest.raises(ValueError, match="'dim'"):
        throughput.scene_config(dict(name="x", integrator="QuasiStatic", scheme="QuasiStatic",
                                     cells=8, per_cell=2, steps=1, warmup=0, dim=4))
