"""Documentation (issue 20): every public name has a docstring and an API entry, the demos
and the benchmark JSON files become pages, README.md is a front door under 12 KB. (`make docs`
builds the whole site with warnings as errors; `make test` runs it after the tests.)"""
import importlib.util
import inspect
import json
from pathlib import Path

import pytest

import fenicsmpm as fm

ROOT = Path(__file__).resolve().parents[1]


def docs_extension():
    spec = importlib.util.spec_from_file_location("fenicsmpm_docs",
                                                  ROOT / "docs" / "_ext" / "fenicsmpm_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


PROTOCOL = ("setup", "step", "solve_step")     # integrator methods Simulation calls


def test_every_public_name_has_a_docstring():
    """Every name in fm.__all__ and every public method of its classes, except the integrator
    protocol (setup, step: called by Simulation, described in the integrators' guide)."""
    missing = []
    for name in fm.__all__:
        obj = getattr(fm, name)
        if not inspect.getdoc(obj):
            missing.append(name)
        if inspect.isclass(obj):
            for k, v in inspect.getmembers(obj):
                if not k.startswith("_") and k not in PROTOCOL \
                        and (callable(v) or isinstance(v, property)) \
                        and not issubclass(obj, BaseException) and not inspect.getdoc(v):
                    missing.append(f"{name}.{k}")
    assert not missing, missing


def test_api_page_lists_every_public_name():
    page = docs_extension().api_page()
    for name in fm.__all__:
        kind = "autoclass" if inspect.isclass(getattr(fm, name)) else "autofunction"
        assert f".. {kind}:: fenicsmpm.{name}\n" in page, name
    for mod in ("fenicsmpm.partition", "fenicsmpm.bench", "fenicsmpm.errors",
                "fenicsmpm.materials.element_test"):
        assert f".. automodule:: {mod}\n" in page, mod


def test_result_pages_come_from_the_json(tmp_path):
    """Each committed docs/results/CASE.json renders to a page holding its command, every
    run's name and wall time, and its metrics."""
    ext = docs_extension()
    files = sorted((ROOT / "docs" / "results").glob("*.json"))
    assert len(files) >= 10
    for f in files:
        doc = json.loads(f.read_text())
        page = ext.result_page(doc, f.name)
        assert f"python -m fenicsmpm.bench {doc['case']} --quick --out docs/results" in page
        for r in doc["runs"]:
            assert ext._cell(r["name"]) in page
            assert ext._fmt(r["wall_s"]) in page
            for k in r["metrics"]:
                assert f"{ext._cell(k)} = " in page, (f.name, k)


def test_demo_pages_cover_every_demo():
    from mpi4py import MPI
    ext = docs_extension()
    if MPI.COMM_WORLD.rank == 0:                # one writer; the others read after it
        ext.demo_pages()
    MPI.COMM_WORLD.barrier()
    demos = sorted(p.stem for p in (ROOT / "demos").glob("*.py"))
    out = ROOT / "docs" / "_generated" / "demos"
    for name in demos:
        page = (out / f"{name}.rst").read_text()
        assert f".. literalinclude:: ../../../demos/{name}.py" in page
    assert "slope_gmsh" in demos


def test_readme_is_a_front_door():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.encode("utf-8")) < 12 * 1024
    for heading in ("## Two commands", "## A complete example", "## Demos",
                    "## Documentation"):
        assert heading in text
    for demo in sorted(p.name for p in (ROOT / "demos").glob("*.py")):
        assert f"`demos/{demo}`" in text, demo


@pytest.mark.parametrize("page", ["measured.md", "guide/choosing.md"])
def test_moved_measurements_keep_their_commands(page):
    """The measured tables moved out of README.md keep their reproducing commands."""
    text = (ROOT / "docs" / page).read_text(encoding="utf-8")
    if page == "measured.md":
        for cmd in ("demos/vibrating_bar.py", "demos/self_weight_column.py",
                    "demos/column_pulse.py", "-m fenicsmpm.bench throughput",
                    "-m fenicsmpm.bench hypoplastic", "-m fenicsmpm.bench stability"):
            assert cmd in text, cmd
    else:
        assert "<!-- techniques-table:start -->" in text
        assert "python -m fenicsmpm.bench.techniques --readme" in text
