"""V2, small strain (BENCHMARKS.md): elastic column under self-weight, quasi-static.

H = 10, 10 cells of h = 1, rho = 2000, g = 10, E = 1e8, nu = 0 (M = E), gravity ramped over
5 load steps. Exact (linear): sigma_yy(y) = -rho g (H - y), top settlement rho g H^2 / (2 M).

- Mid-depth stress: the particles of the cell row just below y = H/2 (for quadrilaterals
  the cell containing y = H/2 - h/2; for triangles the two triangles of that row, whose
  constant stresses are the row value, so the row's mean height is the matching point):
  mean sigma_yy within 2 % of the exact value at their mean initial height (x - u).
  Likewise the row just above H/2.
- Top settlement: the settlement of the top particles (mean) within 3 % of rho g H^2 / (2M).
- Newton converges in <= 3 iterations per load step.
"""
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems.elastic import self_weight_column

H, RHO, G = 10.0, 2000.0, 10.0
LOAD_STEPS = 5


@pytest.fixture(scope="module", params=[dmesh.CellType.quadrilateral, dmesh.CellType.triangle],
                ids=lambda c: c.name)
def column(request):
    sim, exact = self_weight_column(fm.QuasiStatic(load_steps=LOAD_STEPS), height=H,
                                    density=RHO, g=G, cell_type=request.param)
    sim.run(steps=LOAD_STEPS)
    return request.param.name, sim, exact


def _row_mean(p, y_lo, y_hi):
    """Global mean initial height and sigma_yy of the particles with y_lo < Y < y_hi."""
    Y = (p.x - p.u)[:, 1]
    sel = (Y > y_lo) & (Y < y_hi)
    n = p.total(np.count_nonzero(sel))
    return p.total(Y[sel].sum()) / n, p.total(p.stress[sel, 1, 1].sum()) / n, n


@pytest.mark.parametrize("row", ["below", "above"])
def test_mid_depth_stress(column, row):
    name, sim, exact = column
    h = exact["h"]
    lo = H / 2 - h if row == "below" else H / 2
    Ym, syy, n = _row_mean(sim.particles, lo, lo + h)
    ref = exact["stress_yy"](Ym)
    err = abs(syy / ref - 1.0)
    expected_n = 4 if name == "quadrilateral" else 8      # 2 x 2 per quad, 4 per triangle
    assert n == expected_n, f"{n} particles in the cell row, expected {expected_n}"
    assert abs(Ym - (lo + h / 2)) < 1e-9, f"mean initial height {Ym}, expected {lo + h / 2}"
    assert err < 0.02, (f"{name}: sigma_yy = {syy:.6g} at Y = {Ym:.4g} vs exact {ref:.6g}: "
                        f"error {100 * err:.4f} % (tol 2 %)")


def test_stress_profile(column):
    """Row by row, the mean sigma_yy matches -rho g (H - y) at the row's centre: a standard
    MPM column with particles that have not crossed cells is exact up to the load-step ramp
    (2 % allowed, as at mid-depth)."""
    name, sim, exact = column
    h = exact["h"]
    worst = 0.0
    for j in range(int(round(H / h))):
        Ym, syy, _ = _row_mean(sim.particles, j * h, (j + 1) * h)
        worst = max(worst, abs(syy / exact["stress_yy"](Ym) - 1.0))
    assert worst < 0.02, f"{name}: worst row sigma_yy error {100 * worst:.4f} % (tol 2 %)"


def test_top_settlement(column):
    name, sim, exact = column
    p = sim.particles
    Y = (p.x - p.u)[:, 1]
    ytop = sim.comm.allreduce(float(Y.max()) if len(Y) else -np.inf, op=MPI.MAX)
    top = np.abs(Y - ytop) < 1e-9
    n = p.total(np.count_nonzero(top))
    uy = p.total(p.u[top, 1].sum()) / n
    settle = -uy
    ref = exact["top_settlement"]
    err = abs(settle / ref - 1.0)
    assert abs(ref - RHO * G * H ** 2 / (2 * exact["M"])) < 1e-15
    assert err < 0.03, (f"{name}: top settlement {settle:.6g} vs rho g H^2 / 2M = {ref:.6g}: "
                        f"error {100 * err:.3f} % (tol 3 %)")


def test_newton_iterations(column):
    name, sim, _ = column
    its = sim.integrator.iterations
    assert len(its) == LOAD_STEPS, f"{len(its)} Newton solves recorded, expected {LOAD_STEPS}"
    assert max(its) <= 3, f"{name}: Newton iterations per load step {its} (tol <= 3)"

