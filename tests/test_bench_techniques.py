"""Tests for the benchmark case `techniques` (issue 10) at its quick size.

Serial only: the case is run once per module at --quick size (under an MPI size > 1 the
module is skipped, like the other bench tests that run a whole case). Checks the JSON
schema, the PNG, that the half-step AVG order's end-of-run energy error on the colliding
discs is below USL's, that the mixed integration ran everywhere and beats the baseline's
stress error on L1, and the README block rewrite on a temporary copy of README.md."""
import json
import os
import shutil

import pytest
from mpi4py import MPI

from fenicsmpm import bench
from fenicsmpm.bench import techniques

comm = MPI.COMM_WORLD
pytestmark = pytest.mark.skipif(comm.size > 1, reason="runs the quick case serially")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("techniques"))
    doc = techniques.run(quick=True, out=out, comm=MPI.COMM_SELF, verbose=False)
    return out, doc


def _load(path):
    with open(path) as f:
        return json.load(f)


def test_registered():
    assert bench.get_case("techniques") is techniques.run


def test_json_schema(quick):
    out, doc = quick
    data = _load(os.path.join(out, "techniques.json"))
    assert data == doc
    assert data["case"] == "techniques" and data["quick"] is True
    assert set(data) >= {"machine", "runs", "problems", "sizes", "families", "baseline",
                         "not_applicable", "jit_s", "recommendation", "error_measures"}
    assert data["problems"] == list(techniques.PROBLEMS)
    cfgs = techniques.configurations(quick=True)
    names = {c["name"] for c in cfgs}
    na = {(n["problem"], n["technique"]) for n in data["not_applicable"]}
    ran = {(r["problem"], r["technique"]) for r in data["runs"]}
    # every (problem, configuration) is either run or declared not applicable, never both
    assert ran | na == {(p, n) for p in data["problems"] for n in names}
    assert not (ran & na)
    assert all(n["reason"] for n in data["not_applicable"])
    for r in data["runs"]:
        assert set(r) >= {"name", "config", "n_particles", "n_cells", "steps", "wall_s",
                          "metrics", "problem", "technique"}
        assert set(r["config"]) >= {"integrator", "scheme", "shape", "h", "dt", "ppc",
                                    "cell_type", "family", "error_measure"}
        m = r["metrics"]
        assert r["wall_s"] > 0 and r["steps"] >= 1 and r["n_particles"] > 0
        if m.get("failed"):
            assert "error" not in m and r["config"]["failure"]
        else:
            assert m["error"] >= 0
            assert m["error_x_time"] == pytest.approx(m["error"] * r["wall_s"], rel=1e-12)
        assert isinstance(m["splits"], int) and m["splits"] >= 0
    # JIT is timed separately, one warm-up per run
    assert set(data["jit_s"]) == {r["name"] for r in data["runs"]}
    # the baselines ran everywhere they apply and did not fail
    for r in data["runs"]:
        if r["technique"] == techniques.BASELINE:
            assert not r["metrics"].get("failed"), r["name"]
    rec = data["recommendation"]
    assert set(rec["ranking"]) == set(data["problems"])
    assert {d["family"] for d in rec["defaults"]} == set(techniques.FAMILIES)
    for d in rec["defaults"]:
        assert d["recommended"] in d["options"]


def test_splitting_reported(quick):
    """Splitting triggers on V2 (the base is compressed to a stretch ~0.3 < beta) and the
    count is reported; runs without splitting report 0."""
    _, doc = quick
    by = {(r["problem"], r["technique"]): r for r in doc["runs"]}
    assert by[("V2", "MUSL mpm + split")]["metrics"]["splits"] > 0
    assert all(r["metrics"]["splits"] == 0 for r in doc["runs"] if not r["config"]["splitting"])


def test_png(quick):
    out, _ = quick
    path = os.path.join(out, "techniques.png")
    with open(path, "rb") as f:
        assert os.path.getsize(path) > 0 and f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_avg_energy_below_usl_on_discs(quick):
    _, doc = quick
    by = {r["technique"]: r["metrics"] for r in doc["runs"] if r["problem"] == "discs"}
    avg, usl = by["AVG"]["error"], by["USL"]["error"]
    assert avg < usl, f"AVG energy error {avg:.3e} is not below USL's {usl:.3e}"


def test_mixed_integration_rows(quick):
    """The mixed MPM-Gauss-point integration runs on every problem (shape "mpm") and, on the
    soft column L1, has a smaller stress error than the baseline (less cell-crossing noise)."""
    _, doc = quick
    by = {(r["problem"], r["technique"]): r for r in doc["runs"]}
    for prob in doc["problems"]:
        r = by[(prob, "MUSL mpm + mixed")]
        assert r["config"]["force_integration"] == "mixed" and not r["metrics"].get("failed")
    assert (by[("L1", "MUSL mpm + mixed")]["metrics"]["error"]
            < by[("L1", techniques.BASELINE)]["metrics"]["error"])


def test_readme_rewrite(quick, tmp_path):
    out, doc = quick
    src = techniques.default_readme()
    with open(src, encoding="utf-8") as f:
        real = f.read()
    readme = tmp_path / "README.md"
    shutil.copyfile(src, readme)
    before = readme.read_text(encoding="utf-8")
    assert before.count(techniques.START) == 1 and before.count(techniques.END) == 1
    assert techniques.main(["--readme", "--out", out, "--readme-path", str(readme)]) == 0
    after = readme.read_text(encoding="utf-8")
    i, j = before.index(techniques.START), before.index(techniques.END)
    k, m = after.index(techniques.START), after.index(techniques.END)
    # only the block between the markers changed
    assert after[:k] == before[:i] and after[m:] == before[j:]
    block = after[k + len(techniques.START):m]
    assert block.strip() == techniques.readme_block(doc).strip()
    for prob in doc["problems"]:
        assert f"| {prob} |" in block
    assert "Recommended defaults" in block and "| family | recommended |" in block
    # regenerating is idempotent
    techniques.update_readme(doc, str(readme))
    assert readme.read_text(encoding="utf-8") == after
    # the real README was not touched
    with open(src, encoding="utf-8") as f:
        assert f.read() == real


def test_readme_markers_required(quick, tmp_path):
    _, doc = quick
    bad = tmp_path / "README.md"
    bad.write_text("no markers here\n", encoding="utf-8")
    with pytest.raises(ValueError, match="techniques-table"):
        techniques.update_readme(doc, str(bad))
    assert bad.read_text(encoding="utf-8") == "no markers here\n"
