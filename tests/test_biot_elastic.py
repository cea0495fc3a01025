"""Semi-linear (Biot-strain) hyperelasticity, fm.BiotElastic (fenicsmpm.materials.biot).

- Uniaxial strain, stretch l: sigma_yy = M (l - 1) and sigma_xx = sigma_zz = lambda (l - 1) / l
  (nu = 0: the nominal stress E (l - 1), the linear relation) to 1e-12 relative.
- A rigid rotation is stress-free (1e-12 E); a rotation applied after F gives R sigma R^T.
- At small strain it is fm.LinearElastic's first increment from rest (to 1e-3 relative at
  strains of 1e-4; the difference is of second order).
- The analytic tangent d sigma / d dF equals central differences (step 1e-6) to 1e-6 relative,
  at the random and repeated-eigenvalue states of tests/test_hencky.py.
The suddenly loaded PEERS.md column with it is in tests/test_bench_column_peers.py (rows
"-auto-biot")."""
import numpy as np
import pytest
from test_hencky import _states, _stress, tangent_error

import fenicsmpm as fm

E, NU, RHO = 1e4, 0.3, 80.0


@pytest.mark.parametrize("nu", [0.0, 0.3])
def test_uniaxial_strain_is_linear_in_the_stretch(nu):
    m = fm.BiotElastic(E, nu, RHO)
    for lam in (0.6, 0.9, 1.05, 1.3):
        s = _stress(m, np.array([np.diag([1.0, lam, 1.0])]), np.array([np.eye(3)]))[0]
        syy, sxx = m.constrained_modulus * (lam - 1.0), m.lame_lambda * (lam - 1.0) / lam
        assert abs(s[1, 1] / syy - 1) < 1e-12, (lam, s[1, 1], syy)
        assert np.abs(s - np.diag([sxx, syy, sxx])).max() < 1e-12 * abs(syy)
        if nu == 0.0:
            assert abs(s[1, 1] - E * (lam - 1.0)) < 1e-12 * E


def test_rotation_is_stress_free_and_objective():
    m = fm.BiotElastic(E, NU, RHO)
    th = 0.7
    R = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1.0]])
    assert np.abs(_stress(m, R[None], np.eye(3)[None])).max() < 1e-12 * E
    dF, F_old = _states()
    s = _stress(m, dF, F_old)
    sr = _stress(m, np.einsum("ij,pjk->pik", R, dF), F_old)
    ref = np.einsum("ij,pjk,lk->pil", R, s, R)
    assert np.abs(sr - ref).max() < 1e-10 * np.abs(s).max()


def test_small_strain_is_linear_elasticity():
    rng = np.random.default_rng(3)
    h = 1e-4 * rng.standard_normal((4, 3, 3))
    dF, F_old = np.eye(3) + h, np.repeat(np.eye(3)[None], 4, axis=0)
    s = _stress(fm.BiotElastic(E, NU, RHO), dF, F_old)
    lin = np.zeros_like(s)
    fm.LinearElastic(E, NU, RHO).stress(np.arange(4), dF, F_old, np.zeros_like(s), lin,
                                        np.zeros((4, 0)))
    assert np.abs(s - lin).max() < 1e-3 * np.abs(lin).max()


def test_tangent_matches_finite_differences():
    err = tangent_error(fm.BiotElastic(E, NU, RHO))
    assert err < 1e-6, err


def test_bad_parameters_name_themselves():
    with pytest.raises(ValueError, match="nu"):
        fm.BiotElastic(E, 0.5, RHO)
    with pytest.raises(ValueError, match="E"):
        fm.BiotElastic(-1.0, NU, RHO)


def _reference(m, F):
    """sigma from numpy's eigh of b (module formula)."""
    b = F @ F.T
    w, Q = np.linalg.eigh(b)
    V = Q @ np.diag(np.sqrt(w)) @ Q.T
    tau = m.lame_lambda * (np.trace(V) - 3.0) * V + 2.0 * m.shear_modulus * (b - V)
    return tau / np.linalg.det(F)


def test_plane_and_general_states_match_the_eigen_formula():
    """In-plane F (the 2 x 2 square-root shortcut) and general 3D F (eigensolve) both give
    the module formula to 1e-10 relative."""
    m = fm.BiotElastic(E, NU, RHO)
    rng = np.random.default_rng(11)
    F = np.eye(3) + 0.3 * rng.standard_normal((8, 3, 3))
    F[:4, :2, 2] = F[:4, 2, :2] = 0.0                       # in plane, F_22 free
    F[np.linalg.det(F) < 0] *= -1.0
    s = _stress(m, F, np.repeat(np.eye(3)[None], 8, axis=0))
    for p in range(8):
        ref = _reference(m, F[p])
        assert np.abs(s[p] - ref).max() < 1e-10 * np.abs(ref).max(), p


def column_error(material_class):
    """The largest |u_y - u(Y)| of the 1 x 8 quasi-static column below over the exact top
    settlement, u(Y) = -rho g (H Y - Y^2 / 2) / M the small-strain solution (collective)."""
    from dolfinx import mesh
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    H, n, rho, g = 1.0, 8, 1000.0, 10.0
    M = rho * g * H / 0.2
    mat = material_class(E=M * (1 + NU) * (1 - 2 * NU) / (1 - NU), nu=NU, density=rho)
    assert mat.constrained_modulus == pytest.approx(M, rel=1e-12)
    msh = mesh.create_rectangle(comm, [[0, 0], [H / n, H]], [1, n], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, mat, per_cell=2)
    sim = fm.Simulation(grid, p, fm.QuasiStatic(load_steps=10), dt=1.0, gravity=(0, -g))
    sim.fix(lambda x: np.isclose(x[:, 0], 0) | np.isclose(x[:, 0], H / n), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0), [0, 1])
    sim.run(steps=10, progress=False)
    assert sim.shape == "cpgimp"
    Y = p.x[:, 1] - p.u[:, 1]
    exact = -rho * g * (H * Y - 0.5 * Y ** 2) / M
    err = comm.allreduce(np.abs(p.u[:, 1] - exact).max(initial=0.0), op=MPI.MAX)
    sim.integrator.system.destroy()
    return err / (rho * g * H ** 2 / (2 * M))


def test_quasi_static_column_at_20_percent_strain_is_the_linear_solution():
    """Uniaxial strain under gravity: BiotElastic's nominal stress M (l - 1) makes the static
    column the small-strain one at any strain. A 1 x 8 column with rho g H / M = 0.2 (20 %
    strain at the base), nu = 0.3, fm.QuasiStatic (10 load steps, its tangent: this
    material's), shape "auto" (cpGIMP): every particle's u_y within 0.4 % of the exact top
    settlement (measured 0.26 %; column_error(fm.LinearElastic) 5.7 %,
    column_error(fm.Hencky) 16 %, their own finite-strain columns)."""
    err = column_error(fm.BiotElastic)
    assert err < 0.004, err
