"""Benchmark case `contact`: BENCHMARKS C1, the cylinder on an incline (seed 004 §2.6.9):
centre-displacement error at t_end against wall time for each contact algorithm and cell size.

Scene (`incline`): the incline is tilted through gravity, g = 10 (sin theta, -cos theta) m/s^2
(as tests/test_friction.py does), so the plane is horizontal on the mesh: a deformable plane
0.8 m thick over the whole mesh width, its base nodes (y = 0) fixed, and a cylinder R = 1.6 m
resting on it (centre 2.4 m above the base, no gap). Neo-Hookean cylinder K = 6 MPa,
G = 3 MPa (E = 54/7 MPa, nu = 2/7), rho = 1000 kg/m^3; the plane 10x stiffer, same density.
Both start stress-free and at rest (the seed evaluates gravity stresses at zero inclination
first; here the cylinder settles while it starts to roll). Particles: `ppc` x `ppc` per cell
in the quadrilateral cells whose points fall in the cylinder or the plane; standard MPM
shape functions, explicit MUSL at Courant 0.5 (the plane's p-wave speed 316 m/s).
Known answers (rigid cylinder): theta = 45 deg, mu = 0.495 rolls without slip,
x(t) = (5 sqrt 2 / 3) t^2; theta = 60 deg, mu = 2/7 slips, x(t) = (5/2)(sqrt 3 - 2/7) t^2.
x is the mass-weighted mean x displacement of the cylinder's particles.

Algorithms: "multi-velocity" (fm.ExplicitContact, seed 004 eqs 2.34-2.39, mass-gradient
normals of the master body, with the gap check), "multi-velocity-nogap" (the same without
the gap check: the seed's plain algorithm, contact from the moment two bodies share a node),
"penalty" (fm.ExplicitContact(algorithm="penalty"), node-to-segment penalty contact, seed 004
eqs 2.40-2.53: the cylinder's circle and the plane's top edge as polylines of 0.1 m segments
(the seed's), k_n = k_t = (K + 4G/3)/h of the cylinder, so the penalty step limit is the
cylinder's h / c_p) and "single-field" (fm.Explicit: the bodies share one velocity field and
stick together).
Metrics per run: x_end, x_exact, error (relative, at t_end), wall_s (the time loop, after
JIT warm-up in a first throw-away run)."""
import math
import time

import numpy as np

from . import common

CASE = "contact"
R, PLANE_T, G = 1.6, 0.8, 10.0
K_CYL, G_CYL, RHO = 6e6, 3e6, 1000.0
CASES = {"rolling": (45.0, 0.495), "slipping": (60.0, 2.0 / 7.0)}
ALGORITHMS = ("multi-velocity", "multi-velocity-nogap", "penalty", "single-field")
CONTACT_OPTIONS = {"multi-velocity": {}, "multi-velocity-nogap": dict(gap=None),
                   "penalty": dict(algorithm="penalty")}
SEGMENT = 0.1                   # polyline segment length (the seed's 0.1 m)


def exact_x(theta_deg, mu, t):
    """Centre displacement of a rigid cylinder on a rough incline (rolls without slip when
    mu >= tan(theta) / 3, else slips)."""
    th = math.radians(theta_deg)
    a_roll = 2.0 / 3.0 * G * math.sin(th)
    a = a_roll if mu >= math.tan(th) / 3.0 else G * (math.sin(th) - mu * math.cos(th))
    return 0.5 * a * np.asarray(t) ** 2


def _elastic(K, Gs):
    return 9 * K * Gs / (3 * K + Gs), (3 * K - 2 * Gs) / (2 * (3 * K + Gs))


def incline(theta_deg, mu, algorithm="multi-velocity", h=0.4, ppc=2, t_end=1.0, scheme="MUSL",
            length=None, comm=None, record_every=None, **contact):
    """Run the C1 scene; returns dict(t, x (centre displacement series), x_end, x_exact, error,
    wall_s, steps, sim). Collective under MPI (every rank gets the same numbers)."""
    from dolfinx import mesh
    import fenicsmpm as fm
    comm = common.world(comm)
    x_run = float(exact_x(theta_deg, mu, t_end))
    L = length if length is not None else h * math.ceil((2 * R + x_run + 2.5) / h)
    H = h * math.ceil((PLANE_T + 2 * R + 0.6) / h)
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [L, H]], [round(L / h), round(H / h)],
                                mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    E, nu = _elastic(K_CYL, G_CYL)
    cyl_mat = fm.NeoHookean(E=E, nu=nu, density=RHO)
    plane_mat = fm.NeoHookean(E=10 * E, nu=nu, density=RHO)
    xc, yc = R + 1.0, PLANE_T + R
    cyl = fm.Particles.fill(grid, cyl_mat, per_cell=ppc,
                            region=lambda x: (x[:, 0] - xc) ** 2 + (x[:, 1] - yc) ** 2 < R ** 2)
    plane = fm.Particles.fill(grid, plane_mat, per_cell=ppc, region=lambda x: x[:, 1] < PLANE_T)
    p = cyl + plane                              # material_id 0: cylinder, 1: plane (the bodies)
    th = math.radians(theta_deg)
    if algorithm in CONTACT_OPTIONS:
        opts = {**CONTACT_OPTIONS[algorithm], **contact}
        if algorithm == "penalty":
            opts.setdefault("penalty", dict(k_n=(K_CYL + 4 * G_CYL / 3) / h))
        integ = fm.ExplicitContact(scheme, mu=mu, **opts)
        if algorithm == "penalty":
            from ..contact.penalty import circle, line
            integ.add_polyline(0, circle((xc, yc), R, round(2 * math.pi * R / SEGMENT)), closed=True)
            integ.add_polyline(1, line((L, PLANE_T), (0.0, PLANE_T), round(L / SEGMENT)))
    elif algorithm == "single-field":
        integ = fm.Explicit(scheme)
    else:
        raise ValueError(f"incline: unknown algorithm {algorithm!r}; choose from {ALGORITHMS}")
    sim = fm.Simulation(grid, p, integ, dt="auto", gravity=(G * math.sin(th), -G * math.cos(th)))
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))

    def centre():
        q = sim.particles
        sel = q.material_id == 0
        mc = q.total(q.mass[sel])
        return float(q.total(q.mass[sel] * q.u[sel, 0]) / mc)

    steps = int(math.ceil(t_end / sim.dt - 1e-9))
    every = record_every or max(1, steps // 100)
    ts, xs = [0.0], [0.0]
    if comm.size > 1:
        comm.barrier()
    t0 = time.perf_counter()
    for k in range(steps):
        sim.step()
        if (k + 1) % every == 0 or k == steps - 1:
            ts.append(sim.t)
            xs.append(centre())
    wall = common.gmax(comm, time.perf_counter() - t0)
    x_end = xs[-1]
    x_ex = float(exact_x(theta_deg, mu, sim.t))
    return dict(t=np.array(ts), x=np.array(xs), x_end=x_end, x_exact=x_ex,
                error=(x_end - x_ex) / x_ex, wall_s=wall, steps=steps, sim=sim,
                n_particles=p.n_global(), n_cells=round(L / h) * round(H / h))


SIZES = {"quick": dict(cells=(0.4,), t_end=1.0), "full": dict(cells=(0.4, 0.2, 0.1), t_end=1.0)}


def run(quick=False, out="bench-results", comm=None, verbose=True, cells=None, t_end=None):
    """Run every case x algorithm x cell size; write out/contact.json and out/contact.png."""
    comm = common.world(comm)
    S = dict(SIZES["quick" if quick else "full"])
    if cells is not None:
        S["cells"] = tuple(cells)
    if t_end is not None:
        S["t_end"] = float(t_end)
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    incline(45.0, 0.495, "multi-velocity", h=0.8, t_end=0.01, comm=comm)   # JIT warm-up
    incline(45.0, 0.495, "single-field", h=0.8, t_end=0.01, comm=comm)
    incline(45.0, 0.495, "penalty", h=0.8, t_end=0.01, comm=comm)
    runs, series = [], {}
    for case, (theta, mu) in CASES.items():
        for alg in ALGORITHMS:
            for h in S["cells"]:
                say(f"{case} {alg} h = {h} ...")
                r = incline(theta, mu, alg, h=h, t_end=S["t_end"], comm=comm)
                sim = r["sim"]
                cfg = dict(integrator=type(sim.integrator).__name__, scheme="MUSL",
                           shape=sim.shape, h=h, dt=sim.dt, ppc=4,
                           cell_type="quadrilateral", case=case, theta_deg=theta, mu=mu,
                           algorithm=alg, t_end=sim.t)
                runs.append(common.make_record(
                    f"{case}-{alg}-h{h:g}", cfg, r["n_particles"], r["n_cells"], r["steps"],
                    r["wall_s"], dict(x_end=r["x_end"], x_exact=r["x_exact"], error=r["error"],
                                      abs_error=abs(r["error"]))))
                series[(case, alg, h)] = (r["t"], r["x"])
                say(f"    x = {r['x_end']:.4f} m (exact {r['x_exact']:.4f}), error "
                    f"{r['error']:+.2%}, wall {r['wall_s']:.2f} s")
    doc = common.result(CASE, runs, comm, quick=quick,
                        notes=["Incline tilted through gravity; single-field MPM glues the "
                               "cylinder to the plane (error reported, not a target).",
                               "Penalty: polylines of 0.1 m segments, k_n = k_t = (K + 4G/3)/h "
                               "of the cylinder."])
    common.write_result(doc, out, comm)
    common.print_table([dict(name=r["name"], h=r["config"]["h"], x=r["metrics"]["x_end"],
                             exact=r["metrics"]["x_exact"], err=r["metrics"]["error"],
                             wall=r["wall_s"]) for r in runs],
                       [("run", "name"), ("h", "h"), ("x(t_end)", "x"), ("exact", "exact"),
                        ("rel. error", "err"), ("wall s", "wall")], comm=comm)
    fig, ax = common.new_figure(2, 1)
    colors = {"multi-velocity": "tab:blue", "multi-velocity-nogap": "tab:green",
              "penalty": "tab:purple", "single-field": "tab:red"}
    for r in runs:
        c = r["config"]
        k = list(CASES).index(c["case"])
        ax[0, 0].loglog(r["wall_s"], max(abs(r["metrics"]["error"]), 1e-6),
                        "o" if k == 0 else "s", color=colors[c["algorithm"]],
                        label=f"{c['case']} {c['algorithm']}")
        ax[0, 0].annotate(f"h={c['h']:g}", (r["wall_s"], max(abs(r["metrics"]["error"]), 1e-6)),
                          fontsize=7)
    h0, l0 = ax[0, 0].get_legend_handles_labels()
    uniq = dict(zip(l0, h0))
    ax[0, 0].legend(uniq.values(), uniq.keys(), fontsize=7)
    ax[0, 0].set_xlabel("wall time [s]")
    ax[0, 0].set_ylabel(f"|x - x_exact| / x_exact at t = {S['t_end']:g} s")
    ax[0, 0].set_title("C1 incline: error vs wall time", fontsize=9)
    hmin = min(S["cells"])
    for case, (theta, mu) in CASES.items():
        t = np.linspace(0, S["t_end"], 100)
        ax[0, 1].plot(t, exact_x(theta, mu, t), "k--", lw=1)
        for alg in ALGORITHMS:
            ts, xs = series[(case, alg, hmin)]
            ax[0, 1].plot(ts, xs, color=colors[alg], ls="-" if case == "rolling" else ":",
                          label=f"{case} {alg} h={hmin:g}")
    ax[0, 1].set_xlabel("t [s]")
    ax[0, 1].set_ylabel("centre displacement [m]")
    ax[0, 1].legend(fontsize=7)
    import os
    common.save_figure(fig, os.path.join(out, f"{CASE}.png"), comm,
                       title=common.machine_title(doc["machine"]))
    return doc
