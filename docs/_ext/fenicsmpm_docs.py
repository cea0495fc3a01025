"""Sphinx extension of the fenicsmpm docs: pages generated at build time (into
docs/_generated/, not committed) from the repository itself, so they cannot drift from it.

  _generated/api.rst           one autodoc entry for every name in fenicsmpm.__all__ (grouped by
                               GROUPS; a name no group lists goes under "Other" and is still
                               documented), plus fenicsmpm.partition, fenicsmpm.bench,
                               fenicsmpm.errors and the helper modules in MODULES
  _generated/demos/*.rst       one page per demos/*.py: its docstring as the text, then the file
  _generated/results/*.rst     one page per docs/results/CASE.json (written by
                               `python -m fenicsmpm.bench CASE --quick --out docs/results`): the
                               machine, every run's configuration and metrics as a table, and
                               the case's notes and other keys

Docstrings are plain text laid out for a terminal (aligned columns, formulas), not reST, so
`autodoc-process-docstring` shows each one as a literal block: nothing in them is parsed, and
`-W` cannot fail on their markup."""
import json
import math
import os
import re

HERE = os.path.dirname(os.path.abspath(__file__))
DOCS = os.path.dirname(HERE)
ROOT = os.path.dirname(DOCS)
OUT = os.path.join(DOCS, "_generated")

GROUPS = [
    ("Grid, particles, simulation", ["Grid", "Particles", "Simulation"]),
    ("Materials", ["LinearElastic", "NeoHookean", "Hencky", "BiotElastic", "MohrCoulomb", "VonMises",
                   "Hypoplastic"]),
    ("Integrators", ["Explicit", "ExplicitGeneralizedAlpha", "Newmark", "QuasiStatic",
                     "ImplicitGeneralizedAlpha", "DoubleMappingNewmark",
                     "DoubleMappingQuasiStatic"]),
    ("Boundaries", ["Robin", "Viscous", "Viscoelastic", "ParticleLayer"]),
    ("Earthquakes: base motion", ["InputMotion", "rigid_base", "compliant_base",
                                  "CompliantBase"]),
    ("Contact", ["ExplicitContact", "RigidLoad", "set_body"]),
    ("Output", ["Probe", "Output"]),
    ("Exceptions", ["ParticlesLeftMesh", "CheckpointNotFoundError"]),
]
MODULES = [
    ("fenicsmpm.partition", "Deterministic MPI mesh partitioners"),
    ("fenicsmpm.collective", "Reductions over the ranks"),
    ("fenicsmpm.materials.element_test", "Element tests of materials"),
    ("fenicsmpm.materials.initial_stress", "Initial (K0) stress"),
    ("fenicsmpm.boundaries.friction", "Rough and frictional bases"),
    ("fenicsmpm.problems.slope_stability", "Slope stability by limit equilibrium (Bishop)"),
    ("fenicsmpm.errors", "Exceptions"),
    ("fenicsmpm.io.compiler_log", "Form-compiler output"),
    ("fenicsmpm.io", "Probe, output writers and particle rasters"),
    ("fenicsmpm.bench", "Benchmark suite"),
    ("fenicsmpm.bench.common", "Benchmark JSON format and helpers"),
]


def _write(path, text):
    """Write only when the content changed (Sphinx then rebuilds only what changed)."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    if os.path.exists(path):
        with open(path, encoding="utf-8") as f:
            if f.read() == text:
                return
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


def _title(text, ch="="):
    return f"{text}\n{ch * len(text)}\n"


def _literal(text, indent="   "):
    lines = text.rstrip().splitlines() or [""]
    return "::\n\n" + "\n".join(indent + line if line.strip() else "" for line in lines) + "\n"


# ---------------------------------------------------------------------------- API
def api_page():
    import inspect
    import fenicsmpm as fm
    listed = [n for _, names in GROUPS for n in names]
    missing = [n for n in listed if n not in fm.__all__]
    if missing:
        raise RuntimeError(f"docs GROUPS list names not in fenicsmpm.__all__: {missing}")
    groups = GROUPS + [("Other", [n for n in fm.__all__ if n not in listed])]
    out = [_title("API reference"),
           "Every name in ``fenicsmpm.__all__`` (``import fenicsmpm as fm``; the page is "
           "generated from it by ``docs/_ext/fenicsmpm_docs.py``), then the modules a script "
           "uses directly. Docstrings are shown as written (plain text).\n"]
    for group, names in groups:
        if not names:
            continue
        out.append(_title(group, "-"))
        for n in names:
            obj = getattr(fm, n)
            if inspect.isclass(obj):
                extra = ("   :members:\n   :inherited-members:\n"
                         if not issubclass(obj, BaseException) else "")
                out.append(f".. autoclass:: fenicsmpm.{n}\n{extra}")
            else:
                out.append(f".. autofunction:: fenicsmpm.{n}\n")
    out.append(_title("Modules", "-"))
    import importlib
    documented = {id(getattr(fm, n)) for n in fm.__all__}
    for mod, what in MODULES:
        m = importlib.import_module(mod)
        names = getattr(m, "__all__", [k for k in vars(m) if not k.startswith("_")])
        again = [k for k in names if id(getattr(m, k, None)) in documented]
        skip = f"   :exclude-members: {', '.join(again)}\n" if again else ""
        out.append(_title(f"{mod}: {what}", "~"))
        out.append(f".. automodule:: {mod}\n   :members:\n{skip}")
    return "\n".join(out)


# ---------------------------------------------------------------------------- demos
def demo_pages():
    import ast
    folder = os.path.join(ROOT, "demos")
    names = sorted(f[:-3] for f in os.listdir(folder) if f.endswith(".py"))
    index = [_title("Demos"),
             "Each demo runs as ``python3 demos/NAME.py [--out DIR] [--quick]`` or under "
             "``mpirun -n 2``; ``--quick`` is what the test suite runs. The text of each page "
             "is the demo's docstring, followed by the whole script.\n",
             ".. toctree::\n   :maxdepth: 1\n"]
    for name in names:
        path = os.path.join(folder, f"{name}.py")
        with open(path, encoding="utf-8") as f:
            doc = ast.get_docstring(ast.parse(f.read())) or ""
        first, _, rest = doc.partition("\n")
        page = [_title(f"{name}.py"), first.strip() + "\n", _literal(rest) if rest.strip() else "",
                _title("The script", "-"),
                f".. literalinclude:: ../../../demos/{name}.py\n   :language: python\n"
                f"   :linenos:\n"]
        _write(os.path.join(OUT, "demos", f"{name}.rst"), "\n".join(page))
        index.append(f"   {name}")
    _write(os.path.join(OUT, "demos", "index.rst"), "\n".join(index) + "\n")


# ---------------------------------------------------------------------------- results
def _fmt(x):
    if x is None:
        return "–"
    if isinstance(x, bool):
        return str(x)
    if isinstance(x, int):
        return f"{x:,}" if abs(x) >= 10000 else str(x)
    if isinstance(x, float):
        if x == 0 or not math.isfinite(x):
            return str(x)
        return f"{x:.4g}"
    return str(x)


def _cell(text):
    """Text for a list-table cell: one line, reST specials escaped."""
    text = re.sub(r"\s+", " ", str(text)).strip() or "–"
    return re.sub(r"([\\`*_|])", r"\\\1", text)


def _table(header, rows, widths=None):
    out = [".. list-table::", "   :header-rows: 1"]
    if widths:
        out.append("   :widths: " + " ".join(map(str, widths)))
    out.append("")
    for row in [header] + rows:
        out.append("   * - " + _cell(row[0]))
        out += ["     - " + _cell(c) for c in row[1:]]
    return "\n".join(out) + "\n"


CONFIG_KEYS = ("integrator", "scheme", "shape", "h", "dt", "ppc")


def result_page(doc, fname):
    case, m = doc["case"], doc["machine"]
    v = m.get("versions", {})
    cmd = f"python -m fenicsmpm.bench {case}{' --quick' if doc.get('quick') else ''} --out docs/results"
    out = [_title(f"{case}{' (quick)' if doc.get('quick') else ''}"),
           f"Generated from ``docs/results/{fname}``, written by::\n\n   {cmd}\n",
           f"Machine: {m.get('cpu')}, {m.get('cores')} cores, {m.get('ranks')} rank(s), "
           f"load {m.get('load_average_1min')} at {m.get('timestamp')}; dolfinx "
           f"{v.get('dolfinx')}, PETSc {v.get('petsc')}, numba {v.get('numba')}, numpy "
           f"{v.get('numpy')}. Wall times are of a shared 2-core machine: allow ±20 %.\n"]
    rows = []
    for r in doc["runs"]:
        cfg = r.get("config", {})
        conf = ", ".join(f"{k}={_fmt(cfg[k])}" for k in CONFIG_KEYS if k in cfg
                         and cfg[k] not in ("none", None))
        metrics = "; ".join(f"{k} = {_fmt(x)}" for k, x in r.get("metrics", {}).items())
        rows.append([r["name"], conf, _fmt(r.get("n_particles")), _fmt(r.get("steps")),
                     _fmt(r.get("wall_s")), metrics])
    out.append(_title("Runs", "-"))
    out.append(_table(["run", "configuration", "particles", "steps", "wall [s]", "metrics"],
                      rows, widths=[14, 18, 8, 6, 6, 48]))
    notes = doc.get("notes")
    if notes:
        out.append(_title("Notes", "-"))
        for n in ([notes] if isinstance(notes, str) else notes):
            out.append(_literal(str(n)))
    extra = {k: x for k, x in doc.items()
             if k not in ("case", "quick", "machine", "runs", "notes")}
    if case == "techniques":
        from fenicsmpm.bench import techniques
        out.append(_title("Recommendation (the README-style block of this run)", "-"))
        out.append(_literal(techniques.readme_block(doc)))
    if extra:
        out.append(_title("Other results of the case", "-"))
        for k, x in extra.items():
            out.append(f"``{k}``\n\n" + _literal(json.dumps(x, indent=1)))
    return "\n".join(out)


def result_pages():
    folder = os.path.join(DOCS, "results")
    files = sorted(f for f in os.listdir(folder) if f.endswith(".json"))
    index = [_title("Measured results (quick benchmark runs)"),
             "These pages are generated at build time from the JSON files in "
             "``docs/results/``, as ``python -m fenicsmpm.bench CASE --quick --out "
             "docs/results`` wrote them (the command is on each page). To refresh a page, "
             "run that command and rebuild (``make docs``). The measured figures of the full "
             "runs, with their commands, are on :doc:`../../measured`.\n",
             ".. toctree::\n   :maxdepth: 1\n"]
    summary = []
    for f in files:
        with open(os.path.join(folder, f), encoding="utf-8") as fh:
            doc = json.load(fh)
        name = f[:-5]
        _write(os.path.join(OUT, "results", f"{name}.rst"), result_page(doc, f))
        index.append(f"   {name}")
        summary.append([doc["case"], len(doc["runs"]),
                        _fmt(sum(r.get("wall_s") or 0.0 for r in doc["runs"])),
                        doc["machine"].get("timestamp", "")[:10]])
    index.append("")
    index.append(_table(["case", "runs", "sum of run wall times [s]", "measured on"], summary))
    _write(os.path.join(OUT, "results", "index.rst"), "\n".join(index) + "\n")


# ---------------------------------------------------------------------------- hooks
def generate(app):
    _write(os.path.join(OUT, "api.rst"), api_page())
    demo_pages()
    result_pages()


def literal_docstring(app, what, name, obj, options, lines):
    """Show a docstring as a literal block (it is plain text, not reST)."""
    if not lines:
        return
    body = list(lines)
    while body and not body[-1].strip():
        body.pop()
    lines[:] = ["::", ""] + ["   " + line if line.strip() else "" for line in body] + [""]


def setup(app):
    app.connect("builder-inited", generate)
    app.connect("autodoc-process-docstring", literal_docstring)
    return dict(version="1", parallel_read_safe=True, parallel_write_safe=True)
