"""Benchmark case `techniques` (issue 10): each numerical technique against the baselines
(standard MPM, cpGIMP, CPDI2, all explicit MUSL) on four problems with known answers.

    python -m fenicsmpm.bench techniques [--quick] [--out DIR]
    python -m fenicsmpm.bench.techniques [--quick] [--out DIR]      (the same run)
    python -m fenicsmpm.bench.techniques --readme [--out DIR] [--readme-path FILE]
        (no run: rewrites the block between <!-- techniques-table:start --> and
         <!-- techniques-table:end --> of FILE, by default docs/guide/choosing.md, the docs
         page "Choosing a method", from DIR/techniques.json)

Configurations (one technique changed at a time against the baseline "MUSL mpm"; family in
brackets):
  MUSL mpm (baseline), USF, USL, AVG (seed 002 §4.4 half-step order)       [update order]
  GA rho_b=1, 0.8, 0.5 (fm.ExplicitGeneralizedAlpha; quick: 0.8 only)    [update order]
  MUSL cpgimp, MUSL cpdi2 (baselines GIMP and CPDI; full: also ugimp, cpdi1, gauss) [shape]
  MUSL mpm apic, MUSL cpgimp apic (fm.Explicit(transfer="apic"), Jiang et al. 2015),
  MUSL cpgimp aflip (transfer="aflip", Fei et al. 2021)                     [transfer]
  MUSL mpm + split (sim.enable_splitting(2, 0.5, 1), seed 002 §3.4)        [splitting]
  MUSL mpm + smoothed (stress_feedback="smoothed", seed 002 eqs 4.18-4.19)   [stress feedback]
  MUSL mpm + mixed (force_integration="mixed": Gauss points in full cells, particles at
                    the material boundary; seed 003 after Jassim 2013)     [force integration]

Problems and error measures (the `error` metric of each run):
  V2      the AMPLE large-deformation Hencky column (fenicsmpm.problems.column) relaxed
          by damped explicit dynamics (DampedExplicit, damping 2 w1, sine gravity ramp over
          T, run to T/2 + 16/w1; generalized-alpha gets the same velocity damping in
          _DampedGeneralizedAlpha). error: the AMPLE stress norm
          sum_p |sigma_yy,p - sigma_a| V0_p / (rho0 g l0 sum V0_p), with sigma_a evaluated at
          the reference height Y obtained from the particle's CURRENT height through the
          exact motion y(Y) = Y + u_a(Y) (split children inherit their parent's u, so x - u
          is not their reference position; this measure treats every configuration alike).
          AMPLE's own norm (Y = x - u) is kept as metric stress_error_ample.
          n_y = 32 cells (quick 6).
  discs   the colliding discs (BENCHMARKS L2, fenicsmpm.problems.elastic.colliding_discs,
          cfl 0.2, to t = 3.5 s, through the impact at 1.59 s). error: |E(3.5) / E(0) - 1| of
          the total energy E = kinetic + strain; max_energy_error the largest over samples
          every 10 steps. 20 x 20 cells (quick 10 x 10).
  W1      the 100 m column on a viscous (Lysmer) base (fenicsmpm.problems.absorbing_column), dt =
          "auto" at cfl 0.5 (0.5 x the integrator's critical step: Courant 0.5 for Explicit,
          scaled by Omega_s(rho_b) / 2 for generalized-alpha), to 1.4 s. error: the reflection ratio at 50 m depth. dx = 0.5 m (quick 1 m).
  L1      the soft column (E = 5 MPa, rho = 6000, nu = 0, H = 10 m, LinearElastic), damped
          explicit as bench/self_weight.py (sine ramp T = 20 s, run to 20 s). error: the
          AMPLE stress norm with the exact sigma_yy = -rho g (H - Y), Y = x - u. No
          particle splits there (strains ~12 %), so Y = x - u is exact for every run.
          n = 20 cells (quick 5).
Not applicable (recorded in "not_applicable", no number invented): wide shapes on W1 (not
run: the column is one cell wide and 1D).
On V2, W1 and L1 the smoothed feedback and the mixed integration are switched on by setting
sim.stress_feedback / sim.force_integration after the builder made the Simulation (the
attributes the constructor arguments set); on the discs the Simulation is rebuilt on the
builder's grid and particles with shape / stress_feedback / force_integration.

wall_s: the time inside sim.step over the whole run (full size: the fastest of 2 repeats,
metric wall_s_repeats), JIT compilation and cache loading excluded: every configuration first runs a few steps of a tiny copy of its problem, whose
time is reported in "jit_s". metrics: error, error_x_time (error * wall_s), splits, and
problem-specific extras. A run that raises is recorded with metric failed = 1 and the error
message in config["failure"] (no error number).

Choosing rule (`recommend`, the README table): per problem the configurations are ranked by
error x time. For each family, every option is scored by the geometric mean over the problems
where all options of the family ran of (its error x time) / (baseline MUSL mpm error x time);
the option with the smallest score is the recommended default (a failed run scores infinity).
Output: techniques.json, techniques.png, a printed table."""
import argparse
import math
import os
import sys
import time

import numpy as np

from . import common

CASE = "techniques"
START = "<!-- techniques-table:start -->"
END = "<!-- techniques-table:end -->"
PROBLEMS = ("V2", "discs", "W1", "L1")
ERROR_NAMES = {
    "V2": "stress error (AMPLE norm)",
    "discs": "|E_end/E_0 - 1| (total energy)",
    "W1": "reflection ratio (viscous base)",
    "L1": "stress error (AMPLE norm)",
}
SIZES = {
    "full": dict(V2=32, discs=20, W1=0.5, L1=20),
    "quick": dict(V2=6, discs=10, W1=1.0, L1=5),
}
WARM = dict(V2=2, discs=4, W1=10.0, L1=2)       # tiny copies for the JIT warm-up
WARM_STEPS = 3
DISCS_T = 3.5
DISCS_CFL = 0.2
W1_T = 1.4
L1 = dict(height=10.0, E=5e6, nu=0.0, density=6000.0, g=10.0)
L1_RAMP = 20.0
BASELINE = "MUSL mpm"
FAMILIES = ("update order", "shape", "transfer", "splitting", "stress feedback",
            "force integration")


def _cfg(name, family, scheme="MUSL", rho_b=None, shape="mpm", split=False, smoothed=False,
         mixed=False, transfer="flip"):
    return dict(name=name, family=family, scheme=scheme, rho_b=rho_b, shape=shape, split=split,
                smoothed=smoothed, mixed=mixed, transfer=transfer)


def configurations(quick=False):
    """The configuration list (dicts: name, family, scheme, rho_b, shape, split, smoothed,
    mixed)."""
    c = [_cfg(BASELINE, "baseline")]
    c += [_cfg(s, "update order", scheme=s) for s in ("USF", "USL", "AVG")]
    c += [_cfg(f"GA rho_b={r:g}", "update order", scheme="GA", rho_b=r)
          for r in ((0.8,) if quick else (1.0, 0.8, 0.5))]
    c += [_cfg(f"MUSL {s}", "shape", shape=s)
          for s in (("cpgimp", "cpdi2") if quick else ("ugimp", "cpgimp", "cpdi1", "cpdi2", "gauss"))]
    c += [_cfg(f"MUSL {s} apic", "transfer", shape=s, transfer="apic") for s in ("mpm", "cpgimp")]
    c += [_cfg("MUSL cpgimp aflip", "transfer", shape="cpgimp", transfer="aflip")]
    c += [_cfg("MUSL mpm + split", "splitting", split=True)]
    c += [_cfg("MUSL mpm + smoothed", "stress feedback", smoothed=True)]
    c += [_cfg("MUSL mpm + mixed", "force integration", mixed=True)]
    return c


def family_options(cfgs):
    """family -> list of configuration names (the baseline is an option of every family)."""
    out = {}
    for f in FAMILIES:
        out[f] = [BASELINE] + [c["name"] for c in cfgs if c["family"] == f]
    return out


def applicable(problem, cfg):
    """None when the configuration runs on the problem, else the reason it does not."""
    if problem == "W1" and cfg["shape"] != "mpm":
        return ("wide shapes were not run on W1 (a one-cell-wide 1D column; the reflection "
                "is the boundary's)")
    return None


# ---------------------------------------------------------------------------- builders
def _damped_ga(rho_b):
    """Explicit generalized-alpha with the DampedExplicit velocity damping (set by
    large_deformation_column to 2 w1)."""
    import fenicsmpm as fm

    class _DampedGeneralizedAlpha(fm.ExplicitGeneralizedAlpha):
        def __init__(self, rho_b):
            super().__init__(rho_b)
            self.damping = None

        def step(self, sim, dt):
            super().step(sim, dt)
            if self.damping:
                sim.particles.v *= math.exp(-self.damping * dt)

    return _DampedGeneralizedAlpha(rho_b)


def _integrator(cfg, damped):
    import fenicsmpm as fm
    from ..problems.column import DampedExplicit
    if cfg["scheme"] == "GA":
        if damped:     # damping set in build (large_deformation_column sets DampedExplicit's)
            return _damped_ga(cfg["rho_b"])
        return fm.ExplicitGeneralizedAlpha(cfg["rho_b"])
    kw = dict(transfer=cfg.get("transfer", "flip"))
    return DampedExplicit(cfg["scheme"], **kw) if damped else fm.Explicit(cfg["scheme"], **kw)


def build(problem, cfg, size, comm):
    """(sim, exact, steps) of one problem for one configuration."""
    import fenicsmpm as fm
    from ..problems.column import explicit_time, large_deformation_column
    damped = problem in ("V2", "L1")
    integ = _integrator(cfg, damped)
    if problem in ("V2", "L1"):
        kw = {} if problem == "V2" else dict(
            material=fm.LinearElastic(E=L1["E"], nu=L1["nu"], density=L1["density"]),
            ramp=L1_RAMP, run_time=L1_RAMP, **L1)
        sim, ex = large_deformation_column(integ, n_cells=int(size), shape=cfg["shape"],
                                           cfl=0.5, comm=comm, **kw)
        if getattr(integ, "damping", 0) is None:        # the generalized-alpha wrapper
            l0 = kw.get("height", 50.0)
            E, rho = kw.get("E", 1e4), kw.get("density", 80.0)
            integ.damping = explicit_time(height=l0, E=E, density=rho)[2]
            ex.damping = integ.damping
        steps = ex.steps
    elif problem == "discs":
        from ..grid import vertex_ghost_partitioner
        from ..problems.elastic import colliding_discs
        part = vertex_ghost_partitioner() if cfg["shape"] != "mpm" else None
        sim0, ex = colliding_discs(integ, n_cells=int(size), cfl=DISCS_CFL, comm=comm,
                                   partitioner=part, shape=cfg["shape"])
        sim = fm.Simulation(sim0.grid, sim0.particles, integ, dt=sim0.dt, shape=cfg["shape"],
                            stress_feedback="smoothed" if cfg["smoothed"] else None,
                            force_integration="mixed" if cfg["mixed"] else "particles")
        ex["h"] = sim.grid.h
        steps = int(math.ceil(DISCS_T / sim.dt - 1e-9))
    elif problem == "W1":
        from ..problems.absorbing_column import absorbing_column
        sim, ex = absorbing_column(integ, base="viscous", dx=float(size), cfl=0.5, comm=comm,
                                   depths=(50.0, 100.0), shape=cfg["shape"])
        ex["h"] = float(size)
        steps = int(math.ceil(W1_T / sim.dt - 1e-9))
    else:
        raise ValueError(f"{CASE}: unknown problem {problem!r}")
    if cfg["smoothed"] and problem != "discs":
        sim.stress_feedback = "smoothed"
    if cfg["mixed"] and problem != "discs":
        sim.force_integration = "mixed"
    if cfg["split"]:
        sim.enable_splitting(alpha=2.0, beta=0.5, gamma=1.0)
    return sim, ex, steps


def _total_energy(sim):
    e = sim.energy()
    return e["kinetic"] + e["strain"]


def v2_current_stress_error(sim, ex):
    """AMPLE's stress norm with sigma_a at the reference height Y(y_p) of the exact motion
    (module docstring), global (collective)."""
    from mpi4py import MPI
    p = sim.particles
    Yg = np.linspace(0.0, ex.l0, 4001)
    yg = Yg + ex.displacement_y(Yg)
    Y = np.interp(p.x[:, 1], yg, Yg)
    loc = np.array([np.sum(np.abs(p.stress[:, 1, 1] - ex.stress_yy(Y)) * p.V0), np.sum(p.V0)])
    tot = sim.comm.allreduce(loc, op=MPI.SUM) if sim.comm.size > 1 else loc
    return float(tot[0] / (ex.rho * ex.g * ex.l0 * tot[1]))


def run_one(problem, cfg, size, comm, sample_every=10):
    """Run one (problem, configuration); returns (record dict)."""
    from ..problems.column import errors
    sim, ex, steps = build(problem, cfg, size, comm)
    metrics, failure, wall, done = {}, None, 0.0, 0
    e0 = _total_energy(sim) if problem == "discs" else None
    energy_err = []
    try:
        for k in range(steps):
            t0 = time.perf_counter()
            sim.step()
            wall += time.perf_counter() - t0
            done += 1
            if e0 is not None and (k + 1) % sample_every == 0:
                energy_err.append(_total_energy(sim) / e0 - 1.0)
    except Exception as exc:                 # recorded, not raised: a failing technique is data
        failure = f"{type(exc).__name__}: {exc}"
    wall = common.gmax(comm, wall)
    n = sim.particles.n_global()
    if failure is None:
        if problem == "V2":
            err = v2_current_stress_error(sim, ex)
            metrics.update(stress_error_ample=errors(sim, ex)["stress"],
                           displacement_error=errors(sim, ex)["displacement"])
        elif problem == "L1":
            err = errors(sim, ex)["stress"]
        elif problem == "discs":
            e_end = _total_energy(sim) / e0 - 1.0
            err = abs(e_end)
            metrics.update(energy_change=e_end,
                           max_energy_error=max([abs(e) for e in energy_err] + [abs(e_end)]))
        else:
            from ..problems.absorbing_column import summary
            s = summary(sim, ex, depth=50.0)
            err = s["reflection"]
            metrics.update(peak_stress_error=s["peak_stress_error"],
                           offset_error=s["offset_error"])
        metrics.update(error=err, error_x_time=err * wall)
    else:
        metrics.update(failed=1, failed_at_step=done)
    metrics["splits"] = sim.splitting.count if sim.splitting is not None else 0
    metrics["wall_per_step_s"] = wall / max(done, 1)
    config = dict(problem=problem, technique=cfg["name"], family=cfg["family"],
                  integrator="ExplicitGeneralizedAlpha" if cfg["scheme"] == "GA" else "Explicit",
                  scheme=cfg["scheme"], rho_b=cfg["rho_b"], shape=cfg["shape"],
                  transfer=cfg["transfer"], splitting=cfg["split"], stress_feedback="smoothed" if cfg["smoothed"] else None,
                  force_integration="mixed" if cfg["mixed"] else "particles",
                  h=float(ex["h"] if isinstance(ex, dict) else ex.h), dt=float(sim.dt), ppc=4,
                  cell_type="quadrilateral", size=size, error_measure=ERROR_NAMES[problem])
    if failure is not None:
        config["failure"] = failure
    n_cells = sim.grid.n_owned_cells
    n_cells = comm.allreduce(n_cells) if comm.size > 1 else n_cells
    rec = common.make_record(f"{problem} {cfg['name']}", config, n, n_cells, max(done, 1),
                             max(wall, 1e-12), metrics)
    rec.update(problem=problem, technique=cfg["name"])
    return rec


def warm_up(problem, cfg, comm):
    """A few steps of a tiny copy of the problem (JIT / cache loading); returns seconds."""
    t0 = time.perf_counter()
    sim, _, _ = build(problem, cfg, WARM[problem], comm)
    for _ in range(WARM_STEPS):
        sim.step()
    sim.energy()
    return common.gmax(comm, time.perf_counter() - t0)


# ---------------------------------------------------------------------------- analysis
def _xt(r):
    m = r["metrics"] if r else None
    return None if (m is None or m.get("error_x_time") is None) else m["error_x_time"]


def recommend(doc):
    """The ranking and the recommended defaults (module docstring rule), from the JSON."""
    runs = doc["runs"]
    by = {(r["problem"], r["technique"]): r for r in runs}
    ranking = {}
    for prob in doc["problems"]:
        rows = [r for r in runs if r["problem"] == prob]
        ok = sorted((r for r in rows if _xt(r) is not None), key=_xt)
        ranking[prob] = [r["technique"] for r in ok] + [r["technique"] for r in rows
                                                        if _xt(r) is None]
    defaults = []
    for fam, options in doc["families"].items():
        probs = [p for p in doc["problems"] if all((p, o) in by for o in options)]
        scores = {}
        for o in options:
            ratios = {}
            for p in probs:
                base, mine = _xt(by[(p, BASELINE)]), _xt(by[(p, o)])
                ratios[p] = (None if mine is None or base in (None, 0.0) else mine / base)
            vals = list(ratios.values())
            failed_on = [p for p, v in ratios.items() if v is None or v <= 0]
            score = (None if (failed_on or not vals)
                     else math.exp(sum(math.log(v) for v in vals) / len(vals)))
            scores[o] = dict(score=score, ratios=ratios, failed_on=failed_on)
        finite = [(s["score"], o) for o, s in scores.items() if s["score"] is not None]
        best = min(finite)[1] if finite else None
        defaults.append(dict(family=fam, problems=probs, options=options, scores=scores,
                             recommended=best))
    return dict(ranking=ranking, defaults=defaults)


def _fmt(x, digits=3):
    if x is None:
        return "-"
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return common.format_number(x, digits)


def _md(text):
    """Text for a markdown table cell (a '|' would end the cell)."""
    return text.replace("|", "\\|")


def _option_label(o):
    return {BASELINE: "MUSL mpm (baseline)"}.get(o, o)


def readme_block(doc, top=3):
    """The markdown between the README markers, generated from the JSON document."""
    rec = doc.get("recommendation") or recommend(doc)
    by = {(r["problem"], r["technique"]): r for r in doc["runs"]}
    m = doc["machine"]
    lines = [
        f"(generated by `python -m fenicsmpm.bench.techniques --readme` from "
        f"`techniques.json` of a {'quick' if doc['quick'] else 'full'} run on "
        f"{m['timestamp']}, {m['cpu']}, {m['ranks']} rank(s), load {m.get('load_average_1min')}; "
        f"wall time without JIT; rule and set-up in `fenicsmpm/bench/techniques.py`)", "",
        f"Best {top} configurations per problem by error × wall time (ratio: error × time "
        f"over the baseline MUSL with standard MPM shapes):", "",
        "| problem | error measure | rank | configuration | error | wall [s] | error × time | ratio |",
        "|---|---|---|---|---|---|---|---|"]
    for prob in doc["problems"]:
        base = _xt(by.get((prob, BASELINE)))
        for k, name in enumerate(rec["ranking"][prob][:top]):
            r = by[(prob, name)]
            xt = _xt(r)
            lines.append(
                f"| {prob if k == 0 else ''} | {_md(ERROR_NAMES[prob]) if k == 0 else ''} | {k + 1} | "
                f"{_option_label(name)} | {_fmt(r['metrics'].get('error'))} | "
                f"{_fmt(r['wall_s'])} | {_fmt(xt)} | "
                f"{_fmt(xt / base) if (xt is not None and base) else '-'} |")
        b = by.get((prob, BASELINE))
        if b is not None and BASELINE not in rec["ranking"][prob][:top]:
            pos = rec["ranking"][prob].index(BASELINE) + 1
            lines.append(f"| | | {pos} | {_option_label(BASELINE)} | "
                         f"{_fmt(b['metrics'].get('error'))} | {_fmt(b['wall_s'])} | "
                         f"{_fmt(_xt(b))} | 1 |")
    lines += ["", "Recommended defaults. Rule: in each family, the option with the smallest "
              "geometric mean, over the problems where every option of the family ran, of "
              "(error × time) / (baseline error × time); a failed run counts as infinite.", "",
              "| family | recommended | score | why (ratio to the baseline per problem) | other options (score) |",
              "|---|---|---|---|---|"]
    for d in rec["defaults"]:
        best = d["recommended"]
        if best is None:
            continue
        s = d["scores"][best]
        why = ", ".join(f"{p} {_fmt(v)}" for p, v in s["ratios"].items())
        others = ", ".join(f"{_option_label(o)} {_score_text(d['scores'][o])}"
                           for o in d["options"] if o != best)
        lines.append(f"| {d['family']} | {_option_label(best)} | {_fmt(s['score'])} | "
                     f"{why} | {others} |")
    na = doc.get("not_applicable", [])
    if na:
        lines += ["", "Not run (no number given): " + "; ".join(
            sorted({f"{n['technique'] if n['technique'] != '*' else ''}{n['reason']}"
                    for n in _collapse_na(na)}))]
    fails = [r for r in doc["runs"] if r["metrics"].get("failed")]
    if fails:
        lines += ["", "Failed runs: " + "; ".join(
            f"{r['name']} ({r['config'].get('failure', '')[:80]})" for r in fails)]
    splits = [r for r in doc["runs"] if r["metrics"].get("splits")]
    if splits:
        lines += ["", "Particles split: " + ", ".join(
            f"{r['problem']} {r['metrics']['splits']}" for r in splits)]
    return "\n".join(lines)


def _score_text(s):
    if s["failed_on"]:
        return f"inf (failed on {', '.join(s['failed_on'])})"
    return _fmt(s["score"])


def _collapse_na(na):
    """One note per reason (the shapes share one)."""
    seen, out = set(), []
    for n in na:
        if n["reason"] in seen:
            continue
        seen.add(n["reason"])
        names = sorted({m["technique"] for m in na if m["reason"] == n["reason"]})
        out.append(dict(technique=f"{', '.join(names)} on {n['problem']}: ", reason=n["reason"]))
    return out


def update_readme(doc, path):
    """Replace the text between the markers of `path` by readme_block(doc); nothing else of
    the file changes. Raises ValueError when the markers are missing or out of order."""
    with open(path, encoding="utf-8") as f:
        text = f.read()
    i, j = text.find(START), text.find(END)
    if i < 0 or j < 0 or j < i or text.count(START) != 1 or text.count(END) != 1:
        raise ValueError(f"{path}: needs exactly one {START} followed by one {END}")
    new = text[:i + len(START)] + "\n" + readme_block(doc) + "\n" + text[j:]
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(new)
    os.replace(tmp, path)
    return path


# ---------------------------------------------------------------------------- output
COLORS = {"baseline": "k", "update order": "tab:blue", "shape": "tab:green",
          "splitting": "tab:red", "stress feedback": "tab:purple",
          "force integration": "tab:orange", "transfer": "tab:brown"}


def plot(doc, path, comm):
    """techniques.png: per problem, error against wall time (log-log) with iso-lines of
    error x time through the baseline; N/A and failed configurations listed in the panel."""
    fig, axes = common.new_figure(ncols=len(doc["problems"]), size=(4.6, 4.4))
    for j, prob in enumerate(doc["problems"]):
        ax = axes[0, j]
        rows = [r for r in doc["runs"] if r["problem"] == prob]
        for r in rows:
            if _xt(r) is None:
                continue
            fam = r["config"]["family"]
            ax.loglog(r["wall_s"], r["metrics"]["error"], "s" if fam == "baseline" else "o",
                      color=COLORS.get(fam, "0.5"), ms=6)
            ax.annotate(r["technique"], (r["wall_s"], r["metrics"]["error"]), fontsize=5.5,
                        xytext=(3, 2), textcoords="offset points")
        b = next((r for r in rows if r["technique"] == BASELINE and _xt(r) is not None), None)
        if b is not None:
            ts = [r["wall_s"] for r in rows if _xt(r) is not None]
            t = np.geomspace(min(ts) / 1.5, max(ts) * 1.5, 20)
            ax.loglog(t, _xt(b) / t, "k:", lw=0.7, label="baseline error x time")
        notes = [f"failed: {r['technique']}" for r in rows if r["metrics"].get("failed")]
        notes += [f"n/a: {n['technique']}" for n in doc.get("not_applicable", [])
                  if n["problem"] == prob]
        if notes:
            ax.text(0.02, 0.02, "\n".join(notes), transform=ax.transAxes, fontsize=5,
                    va="bottom")
        ax.set_xlabel("wall time [s] (no JIT)")
        ax.set_ylabel(ERROR_NAMES[prob])
        ax.set_title(f"{prob}: size {doc['sizes'][prob]}", fontsize=9)
        ax.grid(True, which="both", lw=0.3)
    for fam, col in COLORS.items():
        axes[0, 0].plot([], [], "s" if fam == "baseline" else "o", color=col, label=fam)
    axes[0, 0].legend(fontsize=6, loc="center right")
    return common.save_figure(fig, path, comm, title=common.figure_title(
        doc, "techniques", ": error against run time"))


def print_report(doc, comm):
    cols = [("run", "name"), ("particles", "n_particles"), ("steps", "steps"),
            ("wall [s]", "wall_s"), ("error", lambda r: r["metrics"].get("error")),
            ("error x time", lambda r: r["metrics"].get("error_x_time")),
            ("splits", lambda r: r["metrics"].get("splits")),
            ("failed", lambda r: r["config"].get("failure", "")[:40] or None)]
    common.print_table(doc["runs"], cols, comm, title=common.table_title(doc))
    common.say(comm, "\n" + readme_block(doc))


def run(quick=False, out="bench-results", comm=None, problems=PROBLEMS, sizes=None,
        configs=None, repeats=None, verbose=True):
    """Run the case, write out/techniques.json and out/techniques.png, print the tables;
    returns the result dict. sizes: {problem: size} overrides; configs: names to run;
    repeats: runs per configuration, the fastest kept (default 1 quick, 2 full; the errors
    are deterministic, only the wall time varies on a shared machine)."""
    comm = common.world(comm)
    mode = "quick" if quick else "full"
    reps = (1 if quick else 2) if repeats is None else int(repeats)
    size = dict(SIZES[mode], **(sizes or {}))
    cfgs = configurations(quick)
    if configs is not None:
        cfgs = [c for c in cfgs if c["name"] in set(configs) | {BASELINE}]
    bad = [p for p in problems if p not in PROBLEMS]
    if bad:
        raise ValueError(f"{CASE}: unknown problems {bad}; known: {PROBLEMS}")
    t_start = time.perf_counter()
    runs, jit, na = [], {}, []
    for prob in problems:
        for cfg in cfgs:
            why = applicable(prob, cfg)
            if why is not None:
                na.append(dict(problem=prob, technique=cfg["name"], reason=why))
                continue
            jit[f"{prob} {cfg['name']}"] = warm_up(prob, cfg, comm)
            tries = [run_one(prob, cfg, size[prob], comm) for _ in range(reps)]
            r = min(tries, key=lambda t: t["wall_s"])
            if len(tries) > 1:
                r["metrics"]["wall_s_repeats"] = len(tries)
                if "error" in r["metrics"]:
                    r["metrics"]["error_x_time"] = r["metrics"]["error"] * r["wall_s"]
            runs.append(r)
            if verbose:
                m = r["metrics"]
                common.say(comm, f"[{CASE}] {r['name']}: {r['steps']} steps, {r['wall_s']:.3g} s"
                           + (f", error {m['error']:.3e}" if "error" in m
                              else f", FAILED: {r['config']['failure']}"))
    fam = family_options(cfgs)
    doc = common.result(CASE, runs, comm, quick=quick, problems=list(problems), sizes=size,
                        error_measures={p: ERROR_NAMES[p] for p in problems},
                        families=fam, baseline=BASELINE, not_applicable=na, jit_s=jit,
                        repeats=reps,
                        total_wall_s=common.gmax(comm, time.perf_counter() - t_start))
    doc["recommendation"] = common._clean(recommend(doc))
    common.write_result(doc, out, comm)
    plot(doc, os.path.join(out, f"{CASE}.png"), comm)
    if verbose:
        print_report(doc, comm)
    return doc


def load(out):
    import json
    with open(os.path.join(out, f"{CASE}.json")) as f:
        return json.load(f)


def default_readme():
    """The page holding the techniques block: docs/guide/choosing.md of the repository."""
    return os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                        "docs", "guide", "choosing.md")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m fenicsmpm.bench.techniques",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="CI size")
    ap.add_argument("--out", default="bench-results", metavar="DIR")
    ap.add_argument("--readme", action="store_true",
                    help="do not run: rewrite the README block from DIR/techniques.json")
    ap.add_argument("--readme-path", default=None, metavar="FILE",
                    help="page to rewrite (default: the repository's docs/guide/choosing.md)")
    args = ap.parse_args(argv)
    if args.readme:
        path = update_readme(load(args.out), args.readme_path or default_readme())
        print(f"rewrote the techniques block of {path}")
        return 0
    run(quick=args.quick, out=args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
