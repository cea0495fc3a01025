"""Benchmark case `axisymmetric`: the thick cylinder under internal pressure
(fenicsmpm.problems.cylinder), error against cell size and wall time.

Runs: "lame" (linear elastic, Lame solution: the cell-mean sigma_rr error relative to p,
sigma_tt and u_r relative errors) and "hill" (Mohr-Coulomb phi = 0, plastic to rho = 1.5 b/2:
Hill's Tresca solution, the stress error relative to p), standard MPM and cpGIMP shapes,
nx radial cells (nx/4 axial), 2 x 2 particles per cell, quasi-static (1 and 5 load steps).
Writes out/axisymmetric.json and out/axisymmetric.png (error vs h and vs wall time)."""
import os

from . import common
from ..problems import cylinder as vc

CASE = "axisymmetric"
P, E, NU, C, RHO = 1.0e4, 1.0e8, 0.3, 1.0e4, 1.5
SIZES = {"quick": (8, 16, 32), "full": (8, 16, 32, 64)}
SHAPES = ("mpm", "cpgimp")


def _one(kind, nx, shape, comm):
    import fenicsmpm as fm
    if kind == "lame":
        sim, wall = vc.thick_cylinder(nx, fm.LinearElastic(E=E, nu=NU, density=1.0), P,
                                      shape=shape, comm=comm)
        e_rr, e_tt, e_u = vc.lame_errors(sim, nx, P, E, NU)
        metrics = dict(error=max(e_rr, e_tt), stress_rr_error=e_rr, stress_tt_error=e_tt,
                       displacement_error=e_u)
    else:
        mat = fm.MohrCoulomb(E=E, nu=NU, density=1.0, phi=0.0, c=C)
        sim, wall = vc.thick_cylinder(nx, mat, vc.hill_pressure(C, RHO), steps=5, shape=shape,
                                      comm=comm)
        metrics = dict(error=vc.hill_error(sim, nx, C, RHO))
    metrics["newton_iterations"] = int(sum(sim.integrator.iterations))
    return sim, wall, metrics


def run(quick=False, out="bench-results", comm=None, verbose=True):
    comm = common.world(comm)
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    _one("hill", 4, "mpm", comm)                       # JIT and form compilation warm-up
    runs = []
    for kind in ("lame", "hill"):
        for shape in SHAPES:
            for nx in SIZES["quick" if quick else "full"]:
                sim, wall, m = _one(kind, nx, shape, comm)
                h = (vc.B_OUT - vc.A_IN) / nx
                cfg = dict(integrator="QuasiStatic", scheme="Newton", shape=shape, h=h, dt=1.0,
                           ppc=4, cell_type="quadrilateral", problem=kind, nx=nx)
                runs.append(common.make_record(f"{kind}-{shape}-nx{nx}", cfg,
                                               sim.particles.n_global(), nx * max(1, nx // 4),
                                               sim.step_count, wall, m))
                say(f"{kind} {shape} nx = {nx}: error {m['error']:.3e}, wall {wall:.3f} s")
    doc = common.result(CASE, runs, comm, quick=quick,
                        notes=["Stresses: cell means at the cell centres (fenicsmpm."
                               "problems.cylinder); error relative to p (sigma_rr, Hill) "
                               "or to the local exact value (sigma_tt)."])
    common.write_result(doc, out, comm)
    common.print_table([dict(name=r["name"], h=r["config"]["h"], err=r["metrics"]["error"],
                             wall=r["wall_s"]) for r in runs],
                       [("run", "name"), ("h", "h"), ("stress error", "err"), ("wall s", "wall")],
                       comm=comm)
    curves = [(f"{kind} {shape}", marker + ("-" if shape == "mpm" else "--"), color,
               [r for r in runs if r["config"]["problem"] == kind and r["config"]["shape"] == shape],
               "error")
              for kind, marker in (("lame", "o"), ("hill", "s"))
              for shape, color in zip(SHAPES, ("tab:blue", "tab:orange"))]
    common.error_figure(doc, curves, "max stress error (cell means)", os.path.join(out, f"{CASE}.png"),
                        comm, ("thick cylinder: error vs h", "error vs wall time"))
    return doc
