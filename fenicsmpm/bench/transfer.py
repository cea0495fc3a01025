"""Benchmark case `transfer`: the velocity transfer, FLIP against APIC, AFLIP and XPIC(2) (issue 15
item 2).

    python -m fenicsmpm.bench transfer [--quick] [--out DIR]

Rows (explicit, default shape="auto": cpGIMP on these lattices):
  spin-SCHEME-TRANSFER    an elastic disc spinning rigidly (problems.rotating_disc: radius 4
                          cells, 2 x 2 particles per cell, one turn; quick: half a turn).
                          Known answer: angular momentum L and kinetic energy K unchanged
                          (the elastic response to the centrifugal load is 0.4 %). Metrics:
                          L_error, K_error (with APIC's affine parts, rotating_disc.momenta).
  discs-SCHEME-TRANSFER   the colliding discs (BENCHMARKS L2, problems.elastic.colliding_discs,
                          cfl 0.2, to t = 3.5 s; 20 x 20 cells, quick 10 x 10). Known answer:
                          the total energy E = K + strain is conserved. Metric: E_error.
SCHEME: MUSL and AVG; TRANSFER: flip, apic, aflip (affine FLIP) and xpic (XPIC(2), Hammerquist &
Nairn 2017). Writes out/transfer.json and out/transfer.png (|error| per row and problem)."""
import os
import time

import numpy as np

from . import common

CASE = "transfer"
ROWS = [(s, t) for t in ("flip", "apic", "aflip", "xpic") for s in ("MUSL", "AVG")]


def _energy(sim):
    """Kinetic (with APIC's affine part) plus strain energy; collective."""
    from ..problems.rotating_disc import momenta
    return sim.energy()["strain"] + momenta(sim)[1]


def _spin(scheme, transfer, turns, comm):
    import fenicsmpm as fm
    from ..problems.rotating_disc import momenta, rotating_disc
    sim = rotating_disc(fm.Explicit(scheme, transfer=transfer), shape="auto", comm=comm)
    L0, K0 = momenta(sim)
    t0 = time.perf_counter()
    sim.run(t_end=turns * 1.0)                      # omega = 2 pi: one turn per second
    wall = common.gmax(comm, time.perf_counter() - t0)
    L1, K1 = momenta(sim)
    m = dict(L_error=L1 / L0 - 1.0, K_error=K1 / K0 - 1.0, turns=turns)
    cfg = dict(integrator="Explicit", scheme=scheme, transfer=transfer, shape=sim.shape,
               h=sim.grid.h, dt=sim.dt, ppc=4, cell_type="quadrilateral", problem="spinning disc")
    return common.make_record(f"spin-{scheme}-{transfer}", cfg, sim.particles.n_global(),
                              common.global_cells(sim), sim.step_count, wall, m)


def _discs(scheme, transfer, n_cells, comm):
    import fenicsmpm as fm
    from ..problems.elastic import colliding_discs
    sim, _ = colliding_discs(fm.Explicit(scheme, transfer=transfer), n_cells=n_cells, cfl=0.2,
                             comm=comm)
    E0 = _energy(sim)
    t0 = time.perf_counter()
    sim.run(t_end=3.5)
    wall = common.gmax(comm, time.perf_counter() - t0)
    m = dict(E_error=_energy(sim) / E0 - 1.0)
    cfg = dict(integrator="Explicit", scheme=scheme, transfer=transfer, shape=sim.shape,
               h=sim.grid.h, dt=sim.dt, ppc=4, cell_type="quadrilateral",
               problem="colliding discs (L2)")
    return common.make_record(f"discs-{scheme}-{transfer}", cfg, sim.particles.n_global(),
                              common.global_cells(sim), sim.step_count, wall, m)


def run(quick=False, out="bench-results", comm=None, verbose=True):
    comm = common.world(comm)
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    turns, n_cells = (0.5, 10) if quick else (1.0, 20)
    runs = []
    for scheme, transfer in ROWS:
        runs.append(_spin(scheme, transfer, turns, comm))
        runs.append(_discs(scheme, transfer, n_cells, comm))
        for r in runs[-2:]:
            say(f"{r['name']}: " + ", ".join(f"{k} {v:+.3%}" for k, v in r["metrics"].items()
                                              if k.endswith("error")) + f", {r['wall_s']:.2f} s")
    doc = common.result(CASE, runs, comm, quick=quick,
                        targets=dict(spin_L_error=0.005, spin_K_error=0.02))
    common.write_result(doc, out, comm)
    common.print_table([dict(name=r["name"], shape=r["config"]["shape"], wall=r["wall_s"],
                             **{k: r["metrics"].get(k) for k in ("L_error", "K_error", "E_error")})
                        for r in runs],
                       [("run", "name"), ("shape", "shape"), ("L error", "L_error"),
                        ("K error", "K_error"), ("E error", "E_error"), ("wall s", "wall")],
                       comm=comm, title=common.table_title(doc))
    fig, axes = common.new_figure(ncols=2, size=(6.5, 4.0))
    if comm.rank == 0:
        for ax, prefix, keys in ((axes[0][0], "spin", ("L_error", "K_error")),
                                 (axes[0][1], "discs", ("E_error",))):
            rows = [r for r in runs if r["name"].startswith(prefix)]
            x = np.arange(len(rows))
            for k, key in enumerate(keys):
                ax.bar(x + 0.35 * k, [100 * abs(r["metrics"][key]) for r in rows], 0.35,
                       label=key.split("_")[0])
            ax.set_xticks(x + 0.175 * (len(keys) - 1))
            ax.set_xticklabels([r["name"].split("-", 1)[1] for r in rows], fontsize=7)
            ax.set_yscale("log")
            ax.set_ylabel("|error| [%]")
            ax.set_title("spinning disc" if prefix == "spin" else "colliding discs", fontsize=9)
            ax.legend(fontsize=7)
    common.save_figure(fig, os.path.join(out, f"{CASE}.png"), comm,
                       title=common.figure_title(doc, "velocity transfer"))
    return doc
