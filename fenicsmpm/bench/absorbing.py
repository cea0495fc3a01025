"""Benchmark case `absorbing`: W1 (BENCHMARKS.md section W), the 100 m column under a Gaussian
surface pulse on a fixed, a viscous and a viscoelastic base: reflection ratio, final-offset
error and wall time against cell size and Courant number.

Scene (fenicsmpm.absorbing_column): H = 100 m, E = 20 MPa, nu = 0.25, rho = 1500 kg/m^3,
side rollers, p(t) = 0.375 / (a sqrt(pi)) exp(-((t - t0) / a)^2) kPa (t0 = 0.05 s,
a = 0.021 s), 2x2 particles per cell. Bases on the mesh boundary (Robin forms on the base
facets, seed 000 method 1): fixed (Dirichlet), viscous (Lysmer-Kuhlemeyer, a = b = 1),
viscoelastic (the dashpots plus Deeks-Randolph springs G / (2 r_b), r_b = H).

Runs (full / --quick):
  cell size   explicit MUSL, Courant c_p dt / dx = 0.5, dx = 1, 0.5, 0.25 m
  Courant     explicit MUSL at dx = 0.5 m, Courant 0.25, 0.5, 0.9
              implicit Newmark (beta = 1/4, gamma = 1/2) at dx = 0.5 m, Courant 1, 2, 4
              (dt = 0.004, 0.008, 0.016 s; W1's dt = 0.005 s is Courant 1.26), and in the
              full run also at dx = 0.25 m (Courant 1, 2, 4: dt = 0.002, 0.004, 0.008 s)
  each for the three bases; full: 1 m wide (W1: 4 cells at dx = 0.25), to t = 2.5 s;
  quick: one cell wide, to 1.4 s (the base's reflection has passed mid-depth by 1.31 s).
Metrics per run: reflection (largest |sigma_yy| at mid-depth after t0 + H / c_p over the
incident peak there), incident_peak_stress_error and incident_peak_velocity_error (against
10.07 kPa and p / (rho c_p)), arrival_error (time of the incident peak at mid-depth against
t0 + y / c_p), base_displacement (the deepest particle's axial displacement at the end),
offset_error ((-base_displacement - I / (rho c_p)) / (I / (rho c_p)); viscous base only: the
exact final offset of the other bases is 0, not I / (rho c_p)), courant, wall_per_step_s.
wall_s: the time-stepping loop after 2 warm-up steps (numba compilation, form set-up),
slowest rank; the probes record every step inside it."""
import math
import os

import numpy as np

from . import common

CASE = "absorbing"
BASES = ("fixed", "viscous", "viscoelastic")
WARMUP = 2

NOTES = [
    "Absorbing boundaries by the mesh-boundary method only (seed 000 method 1: Robin forms "
    "fm.Viscous / fm.Viscoelastic on the base facets). The particle-layer method (seed 000 "
    "methods 2/4, fm.ParticleLayer) did not exist when this case was written and arrived "
    "in the library alongside it; it is not benchmarked here (tests/test_particle_layer.py "
    "checks it on W1), so the W3 ranking of methods is not reproduced.",
    "W3 (large deformation, 300 kPa pulse on a 20 m column) is not run by this case.",
    "Reflection ratio: the reflected pulse has travelled 100 m further than the incident one "
    "at mid-depth, so the scheme's dispersion lowers it too (the fixed base's ratio shows how "
    "much: 1 would be exact).",
    "Implicit Newmark at Courant >= 2 resolves the pulse (a = 0.021 s) with few steps: the "
    "trapezoidal rule's period error damps and delays the incident peak (see "
    "incident_peak_stress_error); the reflection ratio divides by the measured incident "
    "peak.",
]
PEERS = {
    "Anura3D (50 m column, 5 m pulse, Courant 0.5), reflection at mid-height": {
        "dx 0.25 m": {"fixed": 0.83, "absorbing (default)": 0.17,
                      "absorbing (nodal-data option)": 0.078, "wall_s": "2-2.7"},
        "dx 0.125 m": {"fixed": 0.97, "absorbing (default)": 0.20,
                       "absorbing (nodal-data option)": 0.041, "wall_s": "9.4-10"}},
}
TARGETS = {"viscous_reflection_max": 0.05, "viscous_offset_error_max": 0.05,
           "fixed_reflection_min": 0.80}


def _spec(integrator, base, dx, courant, group):
    tag = "explicit" if integrator == "Explicit" else "implicit"
    return dict(name=f"{tag}-{base}-dx{dx:g}-C{courant:g}", integrator=integrator, base=base,
                dx=dx, courant=courant, group=group)


def scenes(quick=False, tiny=False):
    """The run specifications (tiny: two runs, for the test-suite)."""
    if tiny:
        return [_spec("Explicit", "viscous", 1.0, 0.5, "size"),
                _spec("Newmark", "fixed", 1.0, 4.0, "courant")]
    out = []
    for base in BASES:
        for dx in (1.0, 0.5, 0.25):
            out.append(_spec("Explicit", base, dx, 0.5, "size"))
        for c in (0.25, 0.9):
            out.append(_spec("Explicit", base, 0.5, c, "courant"))
        for dx in ((0.5,) if quick else (0.5, 0.25)):
            for c in (1.0, 2.0, 4.0):
                out.append(_spec("Newmark", base, dx, c, "courant"))
    return out


def run_scene(spec, quick, comm):
    import fenicsmpm as fm
    from ..absorbing_column import absorbing_column, summary
    dx, c = spec["dx"], spec["courant"]
    width = dx if quick else max(dx, 1.0)
    t_end = 1.4 if quick else 2.5
    integ = fm.Explicit("MUSL") if spec["integrator"] == "Explicit" else fm.Newmark()
    soil = fm.LinearElastic(E=20.0e6, nu=0.25, density=1500.0)
    dt = c * dx / soil.p_wave_speed
    sim, exact = absorbing_column(integ, base=spec["base"], dx=dx, width=width, dt=dt,
                                  depths=(50.0, 100.0), comm=comm)
    steps = int(math.ceil(t_end / sim.dt - 1e-9))
    timing = common.time_steps(sim, steps - WARMUP, warmup=WARMUP)
    s = summary(sim, exact)
    wall = timing["wall_s"]
    m = dict(reflection=s["reflection"], incident_peak_stress=s["incident_peak_stress"],
             incident_peak_stress_error=s["peak_stress_error"],
             incident_peak_velocity_error=s["peak_velocity_error"],
             arrival_error=s["arrival_error"], base_displacement=s["base_displacement"],
             courant=exact["courant"], wall_per_step_s=wall / (steps - WARMUP))
    if spec["base"] == "viscous":
        m["offset_error"] = s["offset_error"]
    if not integ.explicit:
        m["newton_iterations"] = float(np.mean(integ.iterations))
    cfg = dict(integrator=spec["integrator"], scheme="MUSL" if integ.explicit else "Newmark",
               shape="Q1 (standard MPM)", h=dx, dt=sim.dt, ppc=4, per_cell=2,
               cell_type="quadrilateral", base=spec["base"], group=spec["group"],
               courant=exact["courant"], height=exact["height"], width=width, t_end=sim.t,
               boundary_method="mesh boundary (Robin forms on facets)",
               spring="deeks-randolph, r_b = H" if spec["base"] == "viscoelastic" else None,
               cfl_rule="dt = courant * dx / c_p", warmup_steps=WARMUP)
    if not integ.explicit:
        cfg.update(beta=0.25, gamma=0.5)
        integ.system.destroy()
    n_cells = sim.grid.comm.allreduce(sim.grid.n_owned_cells)
    return common.make_record(spec["name"], cfg, sim.particles.n_global, n_cells, steps, wall, m)


STYLE = {"fixed": "0.4", "viscous": "C0", "viscoelastic": "C1"}


def plot(doc, path, comm):
    runs = doc["runs"]
    fig, axes = common.new_figure(ncols=3, size=(5.0, 4.4))
    ax1, ax2, ax3 = axes[0]
    for r in runs:
        b, m = r["config"]["base"], r["metrics"]
        mk = "o" if r["config"]["integrator"] == "Explicit" else "s"
        lab = f"dx {r['config']['h']:g}, C {m['courant']:.2g}"
        ax1.plot(r["wall_s"], m["reflection"], mk, color=STYLE[b], ms=5)
        ax1.annotate(lab, (r["wall_s"], m["reflection"]), fontsize=5, xytext=(3, 2),
                     textcoords="offset points")
        if "offset_error" in m and m["offset_error"] is not None:
            ax2.plot(r["wall_s"], max(abs(m["offset_error"]), 1e-6), mk, color=STYLE[b], ms=5)
            ax2.annotate(lab, (r["wall_s"], max(abs(m["offset_error"]), 1e-6)), fontsize=5,
                         xytext=(3, 2), textcoords="offset points")
    for b in BASES:
        ax1.plot([], [], "o", color=STYLE[b], label=f"{b} (explicit)")
        ax1.plot([], [], "s", color=STYLE[b], label=f"{b} (implicit)")
    for y, txt in ((0.17, "Anura3D absorbing, dx 0.25"), (0.078, "Anura3D nodal option")):
        ax1.axhline(y, color="k", lw=0.6, ls=":")
        ax1.text(0.01, y, txt, fontsize=6, va="bottom", transform=ax1.get_yaxis_transform())
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    ax1.set_xlabel("wall time [s]")
    ax1.set_ylabel("reflection ratio at mid-depth")
    ax1.set_title("reflection vs wall time", fontsize=9)
    ax1.legend(fontsize=6, loc="center right")
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    ax2.set_xlabel("wall time [s]")
    ax2.set_ylabel("|final offset error| (viscous base)")
    ax2.set_title("offset error I / (rho c_p) vs wall time", fontsize=9)
    # reflection against the Courant number, per cell size and integrator
    keys = sorted({(r["config"]["integrator"], r["config"]["h"], r["config"]["base"])
                   for r in runs})
    for integ, h, b in keys:
        sel = sorted((r["metrics"]["courant"], r["metrics"]["reflection"]) for r in runs
                     if (r["config"]["integrator"], r["config"]["h"], r["config"]["base"])
                     == (integ, h, b))
        if len(sel) < 2:
            continue
        x, y = zip(*sel)
        ax3.plot(x, y, "-o" if integ == "Explicit" else "--s", color=STYLE[b], ms=4,
                 label=f"{b}, {'explicit' if integ == 'Explicit' else 'Newmark'}, dx {h:g}")
    ax3.set_xscale("log")
    ax3.set_yscale("log")
    ax3.set_xlabel(r"Courant number $c_p \Delta t / \Delta x$")
    ax3.set_ylabel("reflection ratio at mid-depth")
    ax3.set_title("reflection vs Courant number", fontsize=9)
    ax3.legend(fontsize=6, loc="center left")
    for ax in (ax1, ax2, ax3):
        ax.grid(alpha=0.3, which="both")
    quick = " (quick)" if doc.get("quick") else ""
    return common.save_figure(fig, path, comm,
                              title=f"fenicsmpm absorbing boundaries, W1 column{quick}\n"
                                    f"{common.machine_title(doc['machine'])}")


def print_report(doc, comm):
    cols = [("run", "name"), ("particles", "n_particles"), ("steps", "steps"),
            ("wall [s]", "wall_s"),
            ("Courant", lambda r: r["metrics"]["courant"]),
            ("reflection", lambda r: r["metrics"]["reflection"]),
            ("offset err", lambda r: r["metrics"].get("offset_error")),
            ("peak err", lambda r: r["metrics"]["incident_peak_stress_error"]),
            ("arrival err", lambda r: r["metrics"]["arrival_error"]),
            ("u_base [m]", lambda r: r["metrics"]["base_displacement"])]
    common.print_table(doc["runs"], cols, comm, title=f"\n== {CASE}"
                       f"{' (quick)' if doc['quick'] else ''}: {doc['machine']['ranks']} rank(s)")
    for n in doc["notes"]:
        common.say(comm, f"  note: {n}")


def run(quick=False, out="bench-results", comm=None, tiny=False, verbose=True):
    """Run the case, write out/absorbing.json and out/absorbing.png, print the table.
    tiny: two short runs (for the tests). Returns the result dict (on every rank)."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD if comm is None else comm
    quick = quick or tiny
    runs = []
    for spec in scenes(quick, tiny):
        runs.append(run_scene(spec, quick, comm))
        if verbose:
            r = runs[-1]
            common.say(comm, f"[{CASE}] {r['name']}: {r['steps']} steps, {r['wall_s']:.3g} s, "
                       f"reflection {r['metrics']['reflection']:.4f}")
    doc = common.result(CASE, runs, comm, quick=quick, tiny=tiny, notes=NOTES, peers=PEERS,
                        targets=TARGETS)
    common.write_result(doc, out, comm)
    plot(doc, os.path.join(out, f"{CASE}.png"), comm)
    if verbose:
        print_report(doc, comm)
    return doc
