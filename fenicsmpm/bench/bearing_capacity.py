"""Benchmark case `bearing-capacity`: Prandtl's strip footing with the library's defaults
(shape="auto", fbar="auto": cpGIMP with F-bar for the von Mises soil), with the standard
family with and without F-bar, on soil of Poisson's ratio 0.3 and under a rough footing
(issue 21; fenicsmpm.problems.footing, kernels.fbar).

    python -m fenicsmpm.bench bearing-capacity [--quick] [--out DIR]

Rows h<h>-<row> at cell sizes h = 0.25, 0.1 and 0.05 m (2, 5 and 10 cells under the
half-width; without F-bar only the first two; quick: h = 0.25 only), ROWS: default (smooth,
nu = 0.49), mpm-fbar-on, mpm-fbar-off, nu0.3 (defaults, nu = 0.3) and rough (defaults,
footing-soil friction mu = 10: the soil sticks to the footing; weightless Tresca soil has the
same limit (2 + pi) c_u under a rough footing); mc20 and mc30: the defaults on weightless
Mohr-Coulomb soil (c = 10 kPa, phi = psi = 20 and 30 degrees, nu = 0.3, 1 m of empty cells
above the surface for the heave) against Reissner's c N_c (cpGIMP since 2026-12-06); mc30-mpm
the same phi = 30 degree row with the standard family (the default for Mohr-Coulomb before;
at h = 0.25 and 0.1 only, as mpm-fbar-off).  The footing pressure over its
limit (problems.footing.limit_pressure) is recorded every step of the push to t_end = 0.8 s
(Mohr-Coulomb: 3 s; settlement = problems.footing's settlement(t)) and averaged over each
0.1 s (an explicit reaction rings from step to step).  Metrics: plateau = the time mean of
q / q_limit from t = 0.5 s (Mohr-Coulomb: 1.2 s) on, its spread (max - min of the 0.1 s
means there) and the plateau's error. Writes
out/bearing-capacity.json and out/bearing-capacity.png (pressure against settlement, one
curve per row).

Rows h<h_i>-centred, h<h_i>-rough-centred, h<h_i>-mc20-centred and h<h_i>-mc30-centred
(quick: only the rough one; h<h_i>-rough-centred-node the rough one with interface="node"):
the default, rough, mc20 and mc30 rows with the footing's edge at a cell centre, h_i =
implicit_cell_size(h) below (2.5 / 5.5 / 10.5 cells under B/2), where the footing is
exactly B/2 wide (with its edge on a grid line, the rigid footing's contact
reaches the nodes of that line, half a cell beyond B/2: contact.multi_velocity's gap check).
Rows h<h_i>-coverage-centred and h<h_i>-mc20-coverage-centred (full run only): the centred
and mc20-centred rows with fm.ExplicitContact(interface="coverage") (the node-wise projection
scaled by the footing's coverage of each node, contact.multi_velocity's "Coverage
interface", the default on 2026-12-07 until late that day); h<h>-coverage (full run only):
the default row with it (the edge on a grid line).

The explicit rows take fm.ExplicitContact's default interface="auto": against the footing (an
axis-aligned box of particles) one constraint per pair of nodes across its surface, scaled by
its coverage of the pair's node inside it (contact.multi_velocity's "Paired interface"; since
2026-12-07, late). Rows h<h>-node,
h<h>-mpm-fbar-on-node, h<h>-nu0.3-node, h<h>-rough-node and h<h>-mc20-node (the last in the full
run only): the default, mpm-fbar-on, nu0.3, rough and mc20 rows with interface="node" (every
node projected alone, the default before: the footing acts up to half a cell wider, and the
node on the symmetry line is held only in part, so the half model reads less than the whole
footing, problems.footing.strip_footing(half=False)).

Rows h<h_i>-implicit, -implicit-nu0.3, -implicit-rough: the same Tresca soil (nu = 0.49, 0.3;
rough: the footing row held sideways as well) under the implicit particle footing
(problems.localisation.strip_footing(footing="particles"), fm.QuasiStatic with the library's
defaults: the standard family with F-bar, Newton with line_search="auto"), B/2 = 0.5 m, pushed
30 mm in 60 steps; plateau = the mean over the last third of the push, spread = its max - min.
Their cell size h_i = implicit_cell_size(h) puts the footing's edge at a cell centre: 2.5 /
5.5 / 10.5 cells under B/2 (h_i = 0.2, 0.0909, 0.0476 m).

Rows w5-h<h>: the seed 000 W5 footing at its peak strength (issue 21; problems.localisation.
strip_footing(h, softening=False, **bench.localisation.FOOTING): weightless von Mises clay,
c_u = 10 kPa, nu = 0.41, E = 200 c_u, B/2 = 0.25 m, implicit QuasiStatic with the particle
footing, ghost=0.01, line_search=6, rtol=1e-6 as in the bench localisation), pushed 0.16 B =
80 mm in 40 steps, at h = problems.localisation.centred_cell_size(B/2, n) = B/2 / (n + 1/2)
for n = 2 / 4 / 8 (quick: 2): the footing's edge at a cell centre, where it is exactly B/2
wide (with its edge on a grid line, the seed's h = 0.0625 m, it acts half a cell wider:
problems.localisation.under_cells).
plateau = the collapse pressure / (2 + pi) c_u, the mean over settlements 0.12-0.16 B
(problems.localisation.collapse_pressure: the soft clay reaches its limit near 0.14 B),
spread = its max - min there; pressure_at_0.1B the usual footing criterion, for comparison."""
import os
import time

import numpy as np

from . import common

CASE = "bearing-capacity"
T_END = 0.8
PLATEAU_FROM = 0.5


PUSH = (T_END, PLATEAU_FROM)
MC_PUSH = (3.0, 1.2)      # Mohr-Coulomb rows: pushed to 3 s (276 mm), plateau from 1.2 s
W5_CELLS = {"quick": (2,), "full": (2, 4, 8)}    # n + 1/2 cells under B/2 (centred_cell_size)
W5_WINDOW = (0.12, 0.16)        # collapse pressure: the mean over 0.12-0.16 B (collapse_pressure)
W5_STEPS = 40                   # pushed to W5_WINDOW[1] B = 80 mm in steps of 2 mm


def _mohr_coulomb(phi):
    """Weightless Mohr-Coulomb soil with associated flow (Reissner's c N_c assumes it)."""
    from ..materials import MohrCoulomb
    return MohrCoulomb(E=10e6, nu=0.3, density=1800.0, phi=phi, c=10e3, psi=phi)


# name, shape, fbar, problems.footing.strip_footing options, (t_end, plateau from) [s]
ROWS = (("default", "auto", "auto", {}, PUSH),
        ("mpm-fbar-on", "mpm", True, {}, PUSH),
        ("mpm-fbar-off", "mpm", False, {}, PUSH),
        ("nu0.3", "auto", "auto", dict(nu=0.3), PUSH),
        ("rough", "auto", "auto", dict(mu=10.0), PUSH),
        ("mc20", "auto", "auto", dict(soil=_mohr_coulomb(20.0), room=1.0), MC_PUSH),
        ("mc30", "auto", "auto", dict(soil=_mohr_coulomb(30.0), room=1.0), MC_PUSH),
        ("mc30-mpm", "mpm", "auto", dict(soil=_mohr_coulomb(30.0), room=1.0), MC_PUSH),
        ("node", "auto", "auto", dict(interface="node"), PUSH),
        ("mpm-fbar-on-node", "mpm", True, dict(interface="node"), PUSH),
        ("nu0.3-node", "auto", "auto", dict(nu=0.3, interface="node"), PUSH),
        ("rough-node", "auto", "auto", dict(mu=10.0, interface="node"), PUSH),
        ("mc20-node", "auto", "auto", dict(soil=_mohr_coulomb(20.0), room=1.0,
                                           interface="node"), MC_PUSH),
        ("coverage", "auto", "auto", dict(interface="coverage"), PUSH))
COARSE_ONLY = ("mpm-fbar-off", "mc30-mpm")     # rows run at h >= 0.1 only
FULL_ONLY = ("mc20-node", "coverage")     # not in the quick run
# the defaults with the footing's edge at a cell centre (implicit_cell_size: B/2 exactly);
# name, strip_footing options, in the quick run too, (t_end, plateau from)
CENTRED_ROWS = (("centred", {}, False, PUSH), ("rough-centred", dict(mu=10.0), True, PUSH),
                ("rough-centred-node", dict(mu=10.0, interface="node"), True, PUSH),
                ("mc20-centred", dict(soil=_mohr_coulomb(20.0), room=1.0), False, MC_PUSH),
                ("mc30-centred", dict(soil=_mohr_coulomb(30.0), room=1.0), False, MC_PUSH),
                ("coverage-centred", dict(interface="coverage"), False, PUSH),
                ("mc20-coverage-centred", dict(soil=_mohr_coulomb(20.0), room=1.0,
                                               interface="coverage"), False, MC_PUSH))


def _row(h, name, shape, use_fbar, comm, push=PUSH, **scene):
    """One footing run (problems.footing.strip_footing(h, **scene)) pushed to push[0] s, its
    plateau the mean from push[1] s on, as a bench record."""
    from ..problems.footing import strip_footing
    sim, q, settlement = strip_footing(h=h, fbar=use_fbar, shape=shape, comm=comm, **scene)
    t0 = time.perf_counter()
    t, d, qs, every_step = [], [], [], []
    sim.observe(lambda s: every_step.append(float(q())), every=1)
    for k in range(int(round(push[0] / 0.1))):
        n0 = len(every_step)
        sim.run(t_end=0.1 * (k + 1))
        t.append(sim.t)
        d.append(settlement(sim.t))
        qs.append(float(np.mean(every_step[n0:])))
    wall = common.gmax(comm, time.perf_counter() - t0)
    late = np.array(t) >= push[1] + 0.1 - 1e-9        # the windows after t = push[1]
    plateau = float(np.mean(np.array(qs)[late]))
    m = dict(plateau=plateau, plateau_error=plateau - 1.0, spread=float(np.ptp(np.array(qs)[late])))
    cfg = dict(integrator="ExplicitContact", scheme="MUSL", shape=sim.shape, fbar=sim.fbar,
               h=h, dt=sim.dt, ppc=4, cell_type="quadrilateral",
               nu=scene["soil"].nu if "soil" in scene else scene.get("nu", 0.49),
               mu=scene.get("mu", 0.0), soil=repr(scene["soil"]) if "soil" in scene else "VonMises",
               interface=sim.integrator.interface,
               cells_under_half_width=0.5 / h)
    rec = common.make_record(f"h{h:g}-{name}", cfg,
                             sim.particles.n_global(), common.global_cells(sim),
                             sim.step_count, wall, m)
    rec["curve"] = dict(settlement_mm=[1e3 * x for x in d], pressure=qs)
    return rec


IMPLICIT_ROWS = (("implicit", dict(nu=0.49)), ("implicit-nu0.3", dict(nu=0.3)),
                 ("implicit-rough", dict(nu=0.49, rough=True)))
IMPLICIT_STEPS = 60


def implicit_cell_size(h):
    """The implicit rows' cell size next to the explicit rows' h: B/2 / h_i = round(B/2 / h)
    + 1/2 cells, so that the edge of the particle footing lies at a cell centre, where it is
    exactly B/2 wide (problems.localisation.under_cells; with the edge on a grid line it acts
    half a cell wider: 1.261 / 1.095 / 1.052 (2 + pi) c_u at 2 / 5 / 10 cells)."""
    from ..problems.footing import B2
    from ..problems.localisation import centred_cell_size
    return centred_cell_size(B2, round(B2 / h))


def _implicit_row(h, name, comm, nu=0.49, rough=False):
    """Prandtl's footing under the implicit particle footing, as a bench record (module
    docstring); h: the cell size (implicit_cell_size(h) in the bench)."""
    from ..problems.footing import B2, C_U, PRANDTL, tresca_soil
    from ..problems.localisation import strip_footing
    opts = dict(footing="particles", rough=rough)
    r = strip_footing(h, material=tresca_soil(nu), width=5.0,
                      depth=3.0, half_width=B2, settlement=0.03, steps=IMPLICIT_STEPS, comm=comm,
                      **opts)
    q = r["pressure"] / (PRANDTL * C_U)
    late = q[1:][2 * IMPLICIT_STEPS // 3:] if r["completed"] else np.array([np.nan])
    return _quasi_static_record(f"h{h:.3g}-{name}", r, q, float(np.mean(late)), float(np.ptp(late)),
                                dt=1.0 / IMPLICIT_STEPS, nu=nu, soil="VonMises",
                                cells_under_half_width=B2 / h, **opts)


def _quasi_static_record(name, r, q, plateau, spread, **config):
    """The bench record of an implicit footing run r (problems.localisation.strip_footing's
    result) with its pressure q / limit, plateau and spread; config: the run's settings.
    Also the footing's effective half-width (problems.localisation.effective_half_width;
    B/2 for every row here: their footing's edge lies at a cell centre)."""
    m = dict(plateau=plateau, plateau_error=plateau - 1.0, spread=spread,
             half_width_effective=r["half_width_effective"],
             newton_mean=float(np.mean(r["newton"] or [0])), newton_max=int(max(r["newton"] or [0])))
    cfg = dict(integrator="QuasiStatic", scheme="Newton", shape="auto", fbar="auto", h=r["h"],
               ppc=4, cell_type="quadrilateral", **config)
    rec = common.make_record(name, cfg, r["n_particles"], r["n_particles"] // 4,
                             len(r["newton"]), r["wall_s"], m)
    rec["curve"] = dict(settlement_mm=(1e3 * r["settlement"]).tolist(), pressure=q.tolist())
    rec["stopped"] = r["stopped"]
    return rec


def _w5_row(h, comm):
    """The W5 footing at peak strength pushed to 0.16 B, as a bench record (module docstring)."""
    from ..problems.footing import PRANDTL
    from ..problems.localisation import W5_HALF_WIDTH, W5_SOIL, collapse_pressure, strip_footing
    from .localisation import FOOTING
    r = strip_footing(h, softening=False, settlement=W5_WINDOW[1] * 2.0 * W5_HALF_WIDTH,
                      steps=W5_STEPS, comm=comm, **FOOTING)
    q = r["pressure"] / (PRANDTL * W5_SOIL["c_u"])
    s = r["settlement"]
    if r["completed"]:
        collapse = collapse_pressure(s, q, W5_HALF_WIDTH, W5_WINDOW)
        spread = float(np.ptp(q[s >= W5_WINDOW[0] * 2.0 * W5_HALF_WIDTH - 1e-12]))
    else:
        collapse = spread = float("nan")
    m = _quasi_static_record(f"w5-h{h:.3g}", r, q, collapse, spread, dt=1.0 / W5_STEPS,
                             nu=W5_SOIL["nu"], mu=0.0, soil="W5 VonMises, peak strength",
                             cells_under_half_width=W5_HALF_WIDTH / h,
                             collapse="mean pressure over settlements 0.12-0.16 B", **FOOTING)
    m["metrics"]["pressure_at_0.1B"] = float(np.interp(0.2 * W5_HALF_WIDTH, s, q))
    return m


def run(quick=False, out="bench-results", comm=None, verbose=True):
    from ..problems.localisation import W5_HALF_WIDTH, centred_cell_size
    comm = common.world(comm)
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    runs = []

    def explicit_row(r):
        runs.append(r)
        say(f"{r['name']}: plateau {r['metrics']['plateau']:.3f} q_limit, spread "
            f"{r['metrics']['spread']:.3f}, {r['wall_s']:.1f} s")
    for h in ((0.25,) if quick else (0.25, 0.1, 0.05)):
        for name, shape, use_fbar, scene, push in ROWS:
            if (h < 0.1 and name in COARSE_ONLY) or (quick and name in FULL_ONLY):
                continue
            explicit_row(_row(h, name, shape, use_fbar, comm, push, **scene))
        for name, scene, in_quick, push in CENTRED_ROWS:
            if quick and not in_quick:
                continue
            explicit_row(_row(implicit_cell_size(h), name, "auto", "auto", comm, push, **scene))
        for name, scene in IMPLICIT_ROWS:
            r = _implicit_row(implicit_cell_size(h), name, comm, **scene)
            runs.append(r)
            say(f"{r['name']}: plateau {r['metrics']['plateau']:.3f} q_limit, {r['wall_s']:.1f} s")
    for n in W5_CELLS["quick" if quick else "full"]:
        r = _w5_row(centred_cell_size(W5_HALF_WIDTH, n), comm)
        runs.append(r)
        say(f"{r['name']}: collapse pressure {r['metrics']['plateau']:.3f} (2 + pi) c_u, "
            f"{r['wall_s']:.1f} s")
    doc = common.result(CASE, runs, comm, quick=quick,
                        targets=dict(plateau_error=0.03, plateau_error_mohr_coulomb=0.05,
                                     plateau_error_w5=0.05))
    common.write_result(doc, out, comm)
    common.print_table([dict(name=r["name"], particles=r["n_particles"], wall=r["wall_s"],
                             **{k: r["metrics"][k] for k in ("plateau", "plateau_error", "spread")})
                        for r in runs],
                       [("run", "name"), ("particles", "particles"), ("q / q_limit", "plateau"),
                        ("error", "plateau_error"), ("spread", "spread"), ("wall s", "wall")],
                       comm=comm, title=common.table_title(doc))
    fig, axes = common.new_figure(size=(6.0, 4.2))
    ax = axes[0][0]
    if comm.rank == 0:
        for r in runs:
            ax.plot(r["curve"]["settlement_mm"], r["curve"]["pressure"], "o-", ms=3,
                    label=r["name"])
        ax.axhline(1.0, color="k", ls="--", lw=0.8, label="limit: (2 + pi) c_u, c N_c")
        ax.set_xlabel("settlement [mm]")
        ax.set_ylabel("q / q_limit")
        ax.legend(fontsize=7)
    common.save_figure(fig, os.path.join(out, f"{CASE}.png"), comm,
                       title=common.figure_title(doc, "Prandtl strip footing"))
    return doc
