"""Benchmark case `dmgc`: double mapping + composite MPM (DM-GC, seed 000 §2.7-2.9,
fenicsmpm.integrators.dmgc) against plain implicit GIMP on the V2 small-strain column
(fenicsmpm.integrators.dmgc.self_weight_errors): stress, displacement and settlement errors
and wall time against the cell count, uGIMP and cpGIMP. Writes out/dmgc.json and out/dmgc.png.
DM-GC is a small-strain technique here: on the large-deformation V2 column Newton stalls
(the DM-GC tangent is not the derivative of its residual; integrators.dmgc docstring)."""
import os

from . import common
from ..problems.elastic import self_weight_errors

CASE = "dmgc"
SIZES = {"quick": (5, 10, 20), "full": (5, 10, 20, 40)}


def run(quick=False, out="bench-results", comm=None, verbose=True):
    comm = common.world(comm)
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    self_weight_errors("dmgc", n_cells=4, comm=comm)          # JIT warm-up
    self_weight_errors("standard", n_cells=4, comm=comm)
    runs = []
    for shape in ("ugimp", "cpgimp"):
        for method in ("dmgc", "standard"):
            for n in SIZES["quick" if quick else "full"]:
                r = self_weight_errors(method, shape=shape, n_cells=n, comm=comm)
                cfg = dict(integrator="DoubleMappingQuasiStatic" if method == "dmgc" else "QuasiStatic",
                           scheme="Newton", shape=shape, h=10.0 / n, dt=1.0, ppc=4,
                           cell_type="quadrilateral", method=method, n_cells=n)
                m = dict(error=r["stress"], stress_error=r["stress"], displacement_error=r["displacement"],
                         settlement_error=r["settlement"], newton_iterations=int(sum(r["newton"])))
                runs.append(common.make_record(f"{method}-{shape}-n{n}", cfg, 4 * n, n + 1, 5,
                                               r["wall"], m))
                say(f"{method} {shape} n = {n}: stress {r['stress']:.3e}, displacement "
                    f"{r['displacement']:.3e}, wall {r['wall']:.3f} s")
    doc = common.result(CASE, runs, comm, quick=quick,
                        notes=["V2 small strain, H = 10, 5 load steps; stress error: AMPLE's norm "
                               "as a fraction of rho g H."])
    common.write_result(doc, out, comm)
    common.print_table([dict(name=r["name"], s=r["metrics"]["stress_error"],
                             u=r["metrics"]["displacement_error"], wall=r["wall_s"]) for r in runs],
                       [("run", "name"), ("stress error", "s"), ("displ. error", "u"), ("wall s", "wall")],
                       comm=comm)
    curves = [(f"{method} {shape}", ls, color,
               [r for r in runs if r["config"]["shape"] == shape and r["config"]["method"] == method],
               "stress_error")
              for shape, color in (("ugimp", "tab:blue"), ("cpgimp", "tab:orange"))
              for method, ls in (("dmgc", "-o"), ("standard", "--s"))]
    common.error_figure(doc, curves, "stress error / (rho g H)", os.path.join(out, f"{CASE}.png"),
                        comm, ("V2 small strain: DM-GC vs implicit GIMP",))
    return doc
