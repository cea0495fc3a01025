"""Benchmark case `absorbing`: W1 and W3 (BENCHMARKS.md section W). W1: the 100 m column
under a Gaussian surface pulse on a fixed, a viscous and a viscoelastic base, each absorbing
base both on the mesh boundary and as a particle layer: reflection ratio, final-offset error
and wall time against cell size and Courant number. W3: the 20 m column under the same pulse
scaled to 300 kPa (large deformation): fixed base, mesh-boundary dashpots and a
particle-layer dashpot whose mesh extends below the material.

W1 scene (fenicsmpm.problems.absorbing_column): H = 100 m, E = 20 MPa, nu = 0.25, rho = 1500 kg/m^3,
side rollers, p(t) = 0.375 / (a sqrt(pi)) exp(-((t - t0) / a)^2) kPa (t0 = 0.05 s,
a = 0.021 s), 2x2 particles per cell. Bases:
  fixed         Dirichlet (all components of the base nodes),
  mesh boundary (seed 000 method 1): fm.Viscous (Lysmer-Kuhlemeyer, a = b = 1) or
                fm.Viscoelastic (the dashpots plus Deeks-Randolph springs G / (2 r_b),
                r_b = H) as Robin forms on the base facets,
  particle layer (seed 000 method 2: the law on the bottom row of particles, interpolated
                with the run's shape functions: standard Q1 explicit, cpGIMP implicit by
                default): fm.ParticleLayer(fm.Viscous() or
                fm.Viscoelastic(r_b=H), region = the particles below dx / 2 (the lowest
                particle row), normal (0, -1)); built from the fixed-base column with the
                base released (sim.release) and the side rollers fixed again.

W1 runs (full / --quick), each for the fixed base and for both laws by both methods:
  cell size   explicit MUSL, Courant c_p dt / dx = 0.5, dx = 1, 0.5, 0.25 m
  Courant     explicit MUSL at dx = 0.5 m, Courant 0.25, 0.5, 0.9
              implicit Newmark (beta = 1/4, gamma = 1/2) at dx = 0.5 m, Courant 1, 2, 4
              (dt = 0.004, 0.008, 0.016 s; W1's dt = 0.005 s is Courant 1.26), and in the
              full run also at dx = 0.25 m (Courant 1, 2, 4: dt = 0.002, 0.004, 0.008 s)
  full: 1 m wide (W1: 4 cells at dx = 0.25), to t = 2.5 s; quick: one cell wide, to 1.4 s
  (the base's reflection has passed mid-depth by 1.31 s).

W3 scene (seed 000 section 4.2.2, L1218-1270): the same material and pulse shape (the
thesis's "Delta load function", eq. 4.1) scaled to a 300 kPa peak (impulse 11.17 kPa s),
H = 20 m, side rollers, probes at mid-height (10 m) and at the base. Exact 1D answers:
particle velocity 300 kPa / (rho c_p) = 1.58 m/s, peak strain 1.25 %, arrival at mid-height
t0 + 10 / c_p = 0.129 s, the fixed base's reflection back at mid-height at t0 + 30 / c_p =
0.287 s, and a viscous base leaves the column displaced by I / (rho c_p) = 0.0589 m: the
material moves out of the base cell at dx = 0.125 m (its lowest particles start dx / 4 =
0.031 m above the base). Bases: fixed (Dirichlet at y = 0); mesh-boundary fm.Viscous on the
facets at y = 0 (the mesh ends at the material's base); particle-layer fm.Viscous on the
lowest particle row with the mesh extended 1 m below the material (so the material can move
down freely; no facet lies on its base). The mesh extends 1 m above the material in every
W3 run (the free top rises by more than dx / 4 when the fixed base's reflection comes
back) and the load acts as forces on the top particle row through the shape functions
(sim.add_particle_load; the thesis also applies it through shape functions): facet
tractions stay on the mesh and are lost once the loaded particles leave the top cell row. Runs: explicit MUSL at Courant 0.5 for dx = 0.5, 0.25, 0.125 m and implicit Newmark at
Courant 2 for dx = 0.25, 0.125 m; one cell wide (quick) or 1 m wide (full), to t = 0.6 s. A
run that stops (e.g. particles leaving the mesh) is recorded with the time it stopped
(metric failed_at, reflection null, wall_s the time until it stopped) and the error in
config["failure"].

Metrics per run: reflection (largest |sigma_yy| at mid-depth after t0 + H / c_p over the
incident peak there), incident_peak_stress_error and incident_peak_velocity_error (against
the applied peak and p / (rho c_p)), arrival_error (time of the incident peak at mid-depth
against t0 + y / c_p), base_displacement (the deepest probe particle's axial displacement at
the end), offset_error ((-base_displacement - I / (rho c_p)) / (I / (rho c_p)); viscous base
only: the exact final offset of the other bases is 0, not I / (rho c_p)), courant,
wall_per_step_s; W3 also tail_stress (largest |sigma_yy| at mid-height over the last 0.1 s
over the incident peak: stress left behind). wall_s: the time-stepping loop after 2 warm-up
steps (numba compilation, form set-up), slowest rank; the probes record every step inside
it. config: benchmark ("W1" / "W3"), base, method ("dirichlet", "mesh" or "layer"),
boundary_method (in words), group ("size", "courant" or "w3")."""
import math
import os
import time

import numpy as np

from . import common

CASE = "absorbing"
BASES = ("fixed", "viscous", "viscoelastic")
WARMUP = 2

NOTES = [
    "Two methods for each absorbing law: the mesh boundary (seed 000 method 1: Robin forms "
    "fm.Viscous / fm.Viscoelastic on the base facets) and the particle layer (seed 000 "
    "method 2: fm.ParticleLayer on the lowest particle row, with the run's shape functions: "
    "shape='auto' gives the standard Q1 family to explicit runs with a particle layer and "
    "cpGIMP to implicit ones, close to the thesis's best method 4, a particle layer with "
    "GIMP functions in its DM-GC framework).",
    "W3 (large deformation): the material's base moves I / (rho c_p) = 0.059 m down under a "
    "viscous base. The mesh-boundary dashpots sit on the mesh facets at y = 0, so the mesh "
    "must end at the material's base and the material may not leave it; the particle layer "
    "runs on a mesh extending 1 m below the material.",
    "W3 at dx = 0.125 m: the particles move 0.059 m, more than the dx / 4 = 0.031 m to the "
    "next cell edge, so they cross cells during the pulse, and standard MPM (Q1 shape "
    "functions, the explicit rows) produces the cell-crossing error: the incident peak at "
    "mid-height overshoots (about +50 % explicit; +15 % with Newmark and standard MPM, "
    "-0.5 % with the implicit default cpGIMP) and the "
    "noise left after the pulse (tail_stress) dominates the 'reflection' of the absorbing "
    "bases. The mesh-boundary viscous base cannot run there at all: its lowest particles "
    "leave the mesh through the base (failed_at). The thesis sees the same kind of "
    "oscillation with basic MPM (fixed base: ~700 kPa at mid-height, DM-GC ~400 kPa).",
    "W3 load: the thesis's text gives the W1 pulse (eq. 4.1, 'Delta load function') and a "
    "300 kPa peak, used here; it also reports a 0.4 m permanent displacement under a "
    "viscous base, which that pulse cannot produce (I / (rho c_p) = 0.059 m), so its "
    "figure 4.13 pulse was probably longer; the reflection ratios do not depend on it.",
    "Reflection ratio: the reflected pulse has travelled 2 (H - y) further than the incident "
    "one at mid-depth y, so the scheme's dispersion lowers it too (the fixed base's ratio "
    "shows how much: 1 would be exact).",
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
    "seed 000 (Do Chinh Phuong 2021), W3 20 m column, 300 kPa, at mid-height": {
        "fixed base peak stress [kPa]": {"basic MPM": 700, "DM-GC": 400},
        "absorbing peak stress [kPa]": 300,
        "ranking": "method 4 (particle layer, GIMP) best; method 1 (mesh nodes) absorbs but "
                   "oscillates and leaves a permanent stress; method 2 (particle layer, "
                   "linear shape functions) worst"},
}
TARGETS = {"viscous_reflection_max": 0.05, "viscous_offset_error_max": 0.05,
           "fixed_reflection_min": 0.80}

W3_HEIGHT, W3_PEAK, W3_T_END, W3_BELOW, W3_ABOVE = 20.0, 300.0e3, 0.6, 1.0, 1.0
METHOD_WORDS = {"dirichlet": "Dirichlet (base nodes fixed)",
                "mesh": "mesh boundary (Robin forms on the base facets)",
                "layer": "particle layer (fm.ParticleLayer on the lowest particle row)"}


def _spec(integrator, base, dx, courant, group, method=None, bench="W1"):
    tag = "explicit" if integrator == "Explicit" else "implicit"
    method = method or ("dirichlet" if base == "fixed" else "mesh")
    name = f"{tag}-{base}{'-layer' if method == 'layer' else ''}-dx{dx:g}-C{courant:g}"
    return dict(name=("w3-" + name) if bench == "W3" else name, integrator=integrator,
                base=base, dx=dx, courant=courant, group=group, method=method, bench=bench)


def scenes(quick=False, tiny=False):
    """The run specifications (tiny: four short runs, for the test-suite)."""
    if tiny:
        return [_spec("Explicit", "viscous", 1.0, 0.5, "size"),
                _spec("Newmark", "fixed", 1.0, 4.0, "courant"),
                _spec("Explicit", "viscous", 1.0, 0.5, "size", "layer"),
                _spec("Explicit", "viscous", 0.5, 0.5, "w3", "layer", "W3")]
    out = []
    for base in BASES:
        for method in (("dirichlet",) if base == "fixed" else ("mesh", "layer")):
            for dx in (1.0, 0.5, 0.25):
                out.append(_spec("Explicit", base, dx, 0.5, "size", method))
            for c in (0.25, 0.9):
                out.append(_spec("Explicit", base, 0.5, c, "courant", method))
            for dx in ((0.5,) if quick else (0.5, 0.25)):
                for c in (1.0, 2.0, 4.0):
                    out.append(_spec("Newmark", base, dx, c, "courant", method))
    for base, method in (("fixed", "dirichlet"), ("viscous", "mesh"), ("viscous", "layer")):
        for dx in (0.5, 0.25, 0.125):
            out.append(_spec("Explicit", base, dx, 0.5, "w3", method, "W3"))
        for dx in (0.25, 0.125):
            out.append(_spec("Newmark", base, dx, 2.0, "w3", method, "W3"))
    return out


def w3_load(t):
    """The W3 surface pressure [Pa]: the W1 pulse scaled to a 300 kPa peak."""
    from ..problems.absorbing_column import A, T0
    return W3_PEAK * math.exp(-((t - T0) / A) ** 2)


def w3_column(integrator, method, dx, width, dt, comm):
    """W3 (see the module docstring). Returns (sim, exact) like absorbing_column, with probes
    at depths 10 m (mid-height) and 20 m (the base). The mesh extends W3_ABOVE above the
    material (the free top rises when a reflection comes back) and, for the particle layer,
    W3_BELOW below it; the load acts on the top particle row (sim.add_particle_load)."""
    import fenicsmpm as fm
    from dolfinx import mesh as dmesh
    from ..problems.absorbing_column import A, E, NU, RHO, T0
    H = W3_HEIGHT
    nb = int(round(W3_BELOW / dx)) if method == "layer" else 0
    na = int(round(W3_ABOVE / dx))
    nx, ny = int(round(width / dx)), int(round(H / dx))
    msh = dmesh.create_rectangle(comm, [[0.0, -nb * dx], [width, H + na * dx]],
                                 [nx, ny + nb + na], dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=E, nu=NU, density=RHO)
    pts = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: (x[:, 1] > 0.0) & (x[:, 1] < H))
    sim = fm.Simulation(grid, pts, integrator, dt=dt)
    tol = 1e-8 * H
    sim.fix(lambda x: (np.abs(x[:, 0]) < tol) | (np.abs(x[:, 0] - width) < tol), [0])
    sim.add_particle_load(lambda x: x[:, 1] > H - 0.5 * dx, lambda t: (0.0, -w3_load(t) * width))
    base = lambda x: np.abs(x[:, 1]) < tol
    if method == "dirichlet":
        sim.fix(base)
    elif method == "mesh":
        sim.add_boundary(fm.Viscous(base))
    else:
        sim.add_boundary(fm.ParticleLayer(fm.Viscous(), region=lambda x: x[:, 1] < 0.5 * dx,
                                          normal=(0.0, -1.0)))
    cp = mat.p_wave_speed
    probes = {d: sim.probe((0.5 * width, H - d), ["stress", "velocity", "displacement",
                                                   "position"]) for d in (10.0, 20.0)}
    impulse = W3_PEAK * A * math.sqrt(math.pi)
    exact = dict(c_p=cp, density=RHO, axis=np.array([0.0, 1.0]), height=H, width=width, t0=T0,
                 a=A, arrival=lambda depth: T0 + depth / cp, peak_stress=W3_PEAK,
                 peak_velocity=W3_PEAK / (RHO * cp), final_offset=impulse / (RHO * cp),
                 impulse=impulse, probes=probes, courant=cp * sim.dt / dx)
    return sim, exact


def _layer_column(integ, spec, width, dt, comm):
    """W1 column with a particle-layer base: the fixed-base column, base released, side
    rollers fixed again, and fm.ParticleLayer on the lowest particle row."""
    import fenicsmpm as fm
    from ..problems.absorbing_column import absorbing_column
    dx = spec["dx"]
    sim, exact = absorbing_column(integ, base="fixed", dx=dx, width=width, dt=dt,
                                  depths=(50.0, 100.0), comm=comm)
    sim.release(exact["base_where"])
    sim.fix(exact["sides_where"], [0])
    law = fm.Viscous() if spec["base"] == "viscous" else fm.Viscoelastic(r_b=exact["height"])
    sim.add_boundary(fm.ParticleLayer(law, region=lambda x: x[:, 1] < 0.5 * dx,
                                      normal=(0.0, -1.0)))
    return sim, exact


def run_scene(spec, quick, comm):
    import fenicsmpm as fm
    from ..problems.absorbing_column import absorbing_column, histories, summary
    dx, c = spec["dx"], spec["courant"]
    w3 = spec["bench"] == "W3"
    width = dx if quick else max(dx, 1.0)
    t_end = W3_T_END if w3 else (1.4 if quick else 2.5)
    integ = fm.Explicit("MUSL") if spec["integrator"] == "Explicit" else fm.Newmark()
    soil = fm.LinearElastic(E=20.0e6, nu=0.25, density=1500.0)
    dt = c * dx / soil.p_wave_speed
    if w3:
        sim, exact = w3_column(integ, spec["method"], dx, width, dt, comm)
    elif spec["method"] == "layer":
        sim, exact = _layer_column(integ, spec, width, dt, comm)
    else:
        sim, exact = absorbing_column(integ, base=spec["base"], dx=dx, width=width, dt=dt,
                                      depths=(50.0, 100.0), comm=comm)
    steps = int(math.ceil(t_end / sim.dt - 1e-9))
    failed = None
    t_start = time.perf_counter()
    try:
        timing = common.time_steps(sim, steps - WARMUP, warmup=WARMUP)
        wall = timing["wall_s"]
    except RuntimeError as err:              # raised on every rank (e.g. particles left the mesh)
        failed, steps = str(err), sim.step_count
        wall = common.gmax(comm, time.perf_counter() - t_start)   # until it stopped, warm-up included
    cfg = dict(integrator=spec["integrator"], scheme="MUSL" if integ.explicit else "Newmark",
               shape=sim.shape, h=dx, dt=sim.dt, ppc=4, per_cell=2,
               cell_type="quadrilateral", base=spec["base"], group=spec["group"],
               benchmark=spec["bench"], method=spec["method"],
               courant=exact["courant"], height=exact["height"], width=width, t_end=sim.t,
               boundary_method=METHOD_WORDS[spec["method"]],
               spring="deeks-randolph, r_b = H" if spec["base"] == "viscoelastic" else None,
               cfl_rule="dt = courant * dx / c_p", warmup_steps=WARMUP)
    if w3:
        cfg.update(peak_pressure=W3_PEAK, load="forces on the top particle row",
                   mesh_below_material=W3_BELOW if spec["method"] == "layer" else 0.0,
                   mesh_above_material=W3_ABOVE)
    if failed is not None:
        cfg["failure"] = failed
        m = dict(courant=exact["courant"], failed_at=sim.t, reflection=float("nan"))
    else:
        s = summary(sim, exact, depth=10.0 if w3 else 50.0)
        m = dict(reflection=s["reflection"], incident_peak_stress=s["incident_peak_stress"],
                 incident_peak_stress_error=s["peak_stress_error"],
                 incident_peak_velocity_error=s["peak_velocity_error"],
                 arrival_error=s["arrival_error"], base_displacement=s["base_displacement"],
                 courant=exact["courant"], wall_per_step_s=wall / (steps - WARMUP))
        if spec["base"] == "viscous":
            m["offset_error"] = s["offset_error"]
        if w3:
            h = histories(exact["probes"][10.0], exact)
            tail = h["t"] >= h["t"][-1] - 0.1
            m["tail_stress"] = float(np.max(np.abs(h["stress"][tail]))) / s["incident_peak_stress"]
    if not integ.explicit:
        if integ.iterations:
            m["newton_iterations"] = float(np.mean(integ.iterations))
        cfg.update(beta=0.25, gamma=0.5)
        integ.system.destroy()
    n_cells = sim.grid.comm.allreduce(sim.grid.n_owned_cells)
    return common.make_record(spec["name"], cfg, sim.particles.n_global(), n_cells, steps, wall, m)


STYLE = {"fixed": "0.4", "viscous": "C0", "viscoelastic": "C1"}
W3_STYLE = {"dirichlet": ("0.4", "fixed (Dirichlet)"), "mesh": ("C0", "viscous, mesh boundary"),
            "layer": ("C3", "viscous, particle layer")}


def _method(r):
    return r["config"].get("method", "dirichlet" if r["config"]["base"] == "fixed" else "mesh")


def _marker(r):
    """Marker, fill: circle explicit / square Newmark; filled mesh boundary or Dirichlet,
    open particle layer."""
    mk = "o" if r["config"]["integrator"] == "Explicit" else "s"
    return mk, "none" if _method(r) == "layer" else None


def _ok(v):
    return v is not None and math.isfinite(v)


def plot(doc, path, comm):
    runs = [r for r in doc["runs"] if r["config"].get("benchmark", "W1") == "W1"]
    w3 = [r for r in doc["runs"] if r["config"].get("benchmark") == "W3"]
    fig, axes = common.new_figure(ncols=3, nrows=2, size=(5.2, 4.4))
    (ax1, ax2, ax3), (ax4, ax5, ax6) = axes
    for r in runs:
        b, m = r["config"]["base"], r["metrics"]
        if not _ok(m.get("reflection")) or not _ok(r["wall_s"]):
            continue
        mk, mfc = _marker(r)
        lab = f"dx {r['config']['h']:g}, C {m['courant']:.2g}"
        ax1.plot(r["wall_s"], m["reflection"], mk, color=STYLE[b], mfc=mfc, ms=5)
        ax1.annotate(lab, (r["wall_s"], m["reflection"]), fontsize=4.5, xytext=(3, 2),
                     textcoords="offset points")
        if _ok(m.get("offset_error")):
            y = max(abs(m["offset_error"]), 1e-6)
            ax2.plot(r["wall_s"], y, mk, color=STYLE[b], mfc=mfc, ms=5)
            ax2.annotate(lab, (r["wall_s"], y), fontsize=4.5, xytext=(3, 2),
                         textcoords="offset points")
    ax1.plot([], [], "o", color=STYLE["fixed"], label="fixed (explicit)")
    ax1.plot([], [], "s", color=STYLE["fixed"], label="fixed (Newmark)")
    for b in ("viscous", "viscoelastic"):
        ax1.plot([], [], "o", color=STYLE[b], label=f"{b}, mesh boundary (explicit)")
        ax1.plot([], [], "o", color=STYLE[b], mfc="none", label=f"{b}, particle layer (explicit)")
    ax1.plot([], [], "s", color="k", mfc="none", label="squares: Newmark")
    for y, txt in ((0.17, "Anura3D absorbing, dx 0.25"), (0.078, "Anura3D nodal option")):
        ax1.axhline(y, color="k", lw=0.6, ls=":")
        ax1.text(0.01, y, txt, fontsize=6, va="bottom", transform=ax1.get_yaxis_transform())
    for ax in (ax1, ax2):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time [s]")
    ax1.set_ylabel("reflection ratio at mid-depth")
    ax1.set_title("W1: reflection vs wall time (filled: mesh boundary, open: particle layer)",
                  fontsize=8)
    ax1.legend(fontsize=5.5, loc="center right")
    ax2.set_ylabel("|final offset error| (viscous base)")
    ax2.set_title("W1: offset error I / (rho c_p) vs wall time", fontsize=8)
    # reflection against the Courant number and against the cell size, per method
    keys = sorted({(r["config"]["integrator"], r["config"]["h"], r["config"]["base"], _method(r))
                   for r in runs})
    for integ, h, b, meth in keys:
        sel = sorted((r["metrics"]["courant"], r["metrics"]["reflection"]) for r in runs
                     if (r["config"]["integrator"], r["config"]["h"], r["config"]["base"],
                         _method(r)) == (integ, h, b, meth) and _ok(r["metrics"]["reflection"]))
        if len(sel) < 2:
            continue
        x, y = zip(*sel)
        ax3.plot(x, y, ("-" if meth != "layer" else "--") + ("o" if integ == "Explicit" else "s"),
                 color=STYLE[b], mfc="none" if meth == "layer" else None, ms=4,
                 label=f"{b}{', layer' if meth == 'layer' else ''}, "
                       f"{'explicit' if integ == 'Explicit' else 'Newmark'}, dx {h:g}")
    for b in BASES:
        for meth in ("dirichlet", "mesh", "layer"):
            sel = sorted((r["config"]["h"], r["metrics"]["reflection"]) for r in runs
                         if r["config"]["base"] == b and _method(r) == meth
                         and r["config"]["group"] == "size" and _ok(r["metrics"]["reflection"]))
            if len(sel) < 1:
                continue
            x, y = zip(*sel)
            ax4.plot(x, y, "-o" if meth != "layer" else "--o", color=STYLE[b],
                     mfc="none" if meth == "layer" else None, ms=5,
                     label=f"{b}" + {"dirichlet": "", "mesh": ", mesh boundary",
                                     "layer": ", particle layer"}[meth])
    ax3.set_xlabel(r"Courant number $c_p \Delta t / \Delta x$")
    ax3.set_title("W1: reflection vs Courant (solid: mesh boundary, dashed: layer)", fontsize=8)
    ax3.legend(fontsize=4.5, loc="center left", ncol=2)
    ax4.set_xlabel("cell size dx [m]")
    ax4.set_title("W1: reflection vs cell size (explicit MUSL, Courant 0.5)", fontsize=8)
    ax4.legend(fontsize=6)
    for ax in (ax3, ax4):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylabel("reflection ratio at mid-depth")
    # W3: reflection and stress left behind at mid-height, per run
    labels = []
    for k, r in enumerate(w3):
        meth, m = _method(r), r["metrics"]
        col, _ = W3_STYLE[meth]
        labels.append(f"{'expl' if r['config']['integrator'] == 'Explicit' else 'Newmark'} "
                      f"dx {r['config']['h']:g}")
        if _ok(m.get("reflection")):
            ax5.bar(k, m["reflection"], 0.8, color=col)
            ax5.text(k, m["reflection"], f"{m['reflection']:.3f}", ha="center", va="bottom",
                     fontsize=5, rotation=90)
            if _ok(m.get("tail_stress")):
                ax5.plot(k, max(m["tail_stress"], 1e-4), "kv", ms=4)
            if _ok(r["wall_s"]):
                ax6.plot(r["wall_s"], m["reflection"], _marker(r)[0], color=col, ms=6)
                ax6.annotate(labels[-1], (r["wall_s"], m["reflection"]), fontsize=5,
                             xytext=(3, 2), textcoords="offset points")
        else:
            ax5.text(k, 1e-3, f"failed at t = {m.get('failed_at', float('nan')):.3g} s",
                     ha="center", va="bottom", fontsize=5, rotation=90, color=col)
    from matplotlib.patches import Patch
    handles = [Patch(color=col, label=lab) for col, lab in W3_STYLE.values()]
    for col, lab in W3_STYLE.values():
        ax6.plot([], [], "o", color=col, label=lab)
    handles += ax5.plot([], [], "kv", label="stress left in the last 0.1 s")
    ax5.set_xticks(range(len(w3)))
    ax5.set_xticklabels(labels, rotation=60, ha="right", fontsize=5.5)
    ax5.set_yscale("log")
    ax5.set_ylim(1e-3, 2.0)
    ax5.set_ylabel("reflection ratio at mid-height (10 m)")
    ax5.set_title("W3: 20 m column, 300 kPa pulse (large deformation)", fontsize=8)
    ax5.legend(handles=handles, fontsize=6, loc="upper right")
    ax6.set_xscale("log")
    ax6.set_yscale("log")
    ax6.set_xlabel("wall time [s]")
    ax6.set_ylabel("reflection ratio at mid-height")
    ax6.set_title("W3: reflection vs wall time (circle explicit, square Newmark)", fontsize=8)
    ax6.legend(fontsize=6)
    for ax in (ax1, ax2, ax3, ax4, ax5, ax6):
        ax.grid(alpha=0.3, which="both")
    return common.save_figure(fig, path, comm, title=common.figure_title(
        doc, "absorbing boundaries, W1 and W3 columns"))


def print_report(doc, comm):
    cols = [("run", "name"), ("particles", "n_particles"), ("steps", "steps"),
            ("wall [s]", "wall_s"),
            ("Courant", lambda r: r["metrics"]["courant"]),
            ("reflection", lambda r: r["metrics"].get("reflection")),
            ("offset err", lambda r: r["metrics"].get("offset_error")),
            ("peak err", lambda r: r["metrics"].get("incident_peak_stress_error")),
            ("arrival err", lambda r: r["metrics"].get("arrival_error")),
            ("u_base [m]", lambda r: r["metrics"].get("base_displacement")),
            ("tail σ", lambda r: r["metrics"].get("tail_stress")),
            ("failed at [s]", lambda r: r["metrics"].get("failed_at"))]
    common.print_table(doc["runs"], cols, comm, title=common.table_title(doc))
    for n in doc["notes"]:
        common.say(comm, f"  note: {n}")


def run(quick=False, out="bench-results", comm=None, tiny=False, verbose=True):
    """Run the case, write out/absorbing.json and out/absorbing.png, print the table.
    tiny: four short runs (for the tests). Returns the result dict (on every rank)."""
    comm = common.world(comm)
    quick = quick or tiny
    runs = []
    for spec in scenes(quick, tiny):
        runs.append(run_scene(spec, quick, comm))
        if verbose:
            r = runs[-1]
            m = r["metrics"]
            common.say(comm, f"[{CASE}] {r['name']}: {r['steps']} steps, "
                       + (f"failed at t = {m['failed_at']:.4g} s" if "failed_at" in m else
                          f"{r['wall_s']:.3g} s, reflection {m['reflection']:.4f}"))
    doc = common.result(CASE, runs, comm, quick=quick, tiny=tiny, notes=NOTES, peers=PEERS,
                        targets=TARGETS)
    common.write_result(doc, out, comm)
    plot(doc, os.path.join(out, f"{CASE}.png"), comm)
    if verbose:
        print_report(doc, comm)
    return doc
