"""Hencky (logarithmic-strain) hyperelasticity (fenicsmpm.materials.hencky), the material of
the V2 large-deformation column.

- Uniaxial strain, nu = 0, stretch l: sigma_yy = E ln(l) / l, other components 0 (1e-12
  relative), the relation of the V2 exact solution.
- The analytic tangent d sigma / d dF equals central differences (step 1e-6) to 1e-6
  relative, at random states and at states with repeated eigenvalues of b (the divided
  difference's limit).
- Objectivity: a rotation R applied after F gives R sigma R^T (1e-10 relative).
- V2 column (BENCHMARKS.md), QuasiStatic, 40 load steps, 4 cells: the exact top settlement is
  25.94 m; Newton converges and every particle's u_y is within 5 % of the top settlement of
  the exact u(Y) at its height (standard MPM; measured max deviation 3.4e-2 of 25.94 m, AMPLE-norm stress
  error 6.3e-2).
"""
import numpy as np
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.materials.hencky import Hencky

E, NU, RHO = 1e4, 0.3, 80.0


def _stress(m, dF, F_old):
    n = len(dF)
    s = np.zeros((n, 3, 3))
    m.stress(np.arange(n), dF, F_old, s, s, np.zeros((n, 0)))
    return s


def test_uniaxial_strain():
    m = Hencky(E, 0.0, RHO)
    for lam in (0.48, 0.9, 1.3):
        s = _stress(m, np.array([np.diag([1.0, lam, 1.0])]), np.array([np.eye(3)]))[0]
        ref = E * np.log(lam) / lam
        assert abs(s[1, 1] / ref - 1) < 1e-12
        assert np.abs(s - np.diag([0, ref, 0])).max() < 1e-12 * abs(ref)


def _states():
    rng = np.random.default_rng(7)
    dF = np.eye(3) + 0.2 * rng.standard_normal((5, 3, 3))
    F_old = np.eye(3) + 0.2 * rng.standard_normal((5, 3, 3))
    dF[3], F_old[3] = np.diag([1.0, 0.7, 1.0]), np.diag([1.0, 0.9, 1.0])   # b = diag(1, l, 1)
    dF[4], F_old[4] = np.eye(3), np.eye(3)                                 # b = I
    for k in (0, 1, 2):
        if np.linalg.det(dF[k] @ F_old[k]) <= 0:
            dF[k] *= -1 if np.linalg.det(dF[k]) < 0 else 1
            F_old[k] *= -1 if np.linalg.det(F_old[k]) < 0 else 1
    return dF, F_old


def tangent_error(m):
    """The largest relative difference, over the states of _states, between m's analytic
    tangent d sigma / d dF and central differences of its stress (step 1e-6)."""
    dF, F_old = _states()
    n = len(dF)
    idx = np.arange(n)
    s = _stress(m, dF, F_old)
    D = np.zeros((n, 3, 3, 3, 3))
    m.tangent(idx, dF, F_old, s, s, np.zeros((n, 0)), D)
    worst = 0.0
    for p in range(n):
        fd = np.zeros((3, 3, 3, 3))
        for k in range(3):
            for l in range(3):
                dp, dm = dF.copy(), dF.copy()
                dp[p, k, l] += 1e-6
                dm[p, k, l] -= 1e-6
                fd[:, :, k, l] = (_stress(m, dp, F_old)[p] - _stress(m, dm, F_old)[p]) / 2e-6
        worst = max(worst, np.abs(fd - D[p]).max() / np.linalg.norm(D[p]))
    return worst


def test_tangent_matches_finite_differences():
    err = tangent_error(Hencky(E, NU, RHO))
    assert err < 1e-6, err


def test_objectivity():
    m = Hencky(E, NU, RHO)
    dF, F_old = _states()
    th = 0.7
    R = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1.0]])
    s = _stress(m, dF, F_old)
    sr = _stress(m, np.einsum("ij,pjk->pik", R, dF), F_old)
    ref = np.einsum("ij,pjk,lk->pil", R, s, R)
    assert np.abs(sr - ref).max() < 1e-10 * np.abs(s).max()


def test_v2_column_quasistatic():
    from fenicsmpm.problems.column import errors, large_deformation_column
    integ = fm.QuasiStatic(load_steps=40, rtol=1e-9)
    sim, ex = large_deformation_column(integ, n_cells=4)
    sim.run(steps=ex.steps, progress=False)
    assert abs(ex.top_settlement - 25.94) < 0.01
    p = sim.particles
    Y = (p.x - p.u)[:, 1]
    dev = float(np.max(np.abs(p.u[:, 1] - ex.displacement_y(Y)))) if len(Y) else 0.0
    dev = sim.comm.allreduce(dev, op=MPI.MAX) / ex.top_settlement
    assert dev < 0.05, dev
    err = errors(sim, ex)
    print(f"\nV2 QuasiStatic mpm 4 cells: stress error {err['stress']:.3e}, displacement "
          f"{err['displacement']:.3e}, max |u - u_a| / 25.94 m = {dev:.3e}")
    integ.system.destroy()
