"""K0 initial stress (BENCHMARKS L1, issue 7): sigma_v = -rho g d, sigma_h = K0 sigma_v.

The stress is set exactly from the depth, so the checks are tight: sigma_yy = -rho g d within
1 % (measured to round-off) and sigma_xx = sigma_zz = K0 sigma_yy; the depth comes from a given
surface function or from the top of the particle cloud per vertical column (the top of a
regular fill with 2 x 2 particles per cell of height h is the top particle + h/4).  Runs
serially and under mpirun -n 2 (the columns are split across ranks).
"""
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.materials.initial_stress import k0_stress

RHO, G = 1800.0, 9.81


def _cloud(region, material=None, size=(2.0, 5.0), cells=(8, 20)):
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], list(size)], list(cells),
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = material or fm.LinearElastic(E=1e7, nu=0.3, density=RHO)
    return fm.Particles.fill(grid, mat, per_cell=2, region=region)


def _worst(p, a, b):
    """Global max |a/b - 1| over the local rows (b != 0), reduced over ranks."""
    err = np.abs(a / b - 1.0).max(initial=0.0)
    return p.grid.comm.allreduce(float(err), op=MPI.MAX)


def _check(p, top, K0):
    y = p.x[:, 1]
    exact = -RHO * G * (top - y)
    s = p.stress
    assert p.n_global() > 0
    assert _worst(p, s[:, 1, 1], exact) < 0.01
    assert _worst(p, s[:, 0, 0], K0 * s[:, 1, 1]) < 1e-12
    assert _worst(p, s[:, 2, 2], K0 * s[:, 1, 1]) < 1e-12
    off = np.abs(s[:, [0, 0, 1], [1, 2, 2]]).max(initial=0.0)
    assert p.grid.comm.allreduce(float(off), op=MPI.MAX) == 0.0


def test_flat_surface_from_cloud_default_k0():
    """Level ground at y = 4 (the particle cloud), K0 = nu / (1 - nu) by default."""
    p = _cloud(lambda x: x[:, 1] < 4.0)
    d = k0_stress(p, gravity=G)
    assert p.grid.comm.allreduce(float(np.abs(d - (4.0 - p.x[:, 1])).max(initial=0.0)),
                                 op=MPI.MAX) < 1e-12
    _check(p, 4.0, 0.3 / 0.7)


def test_stepped_cloud_per_column():
    """Two terraces (y = 4 for x < 1, y = 2.5 for x > 1): each vertical column finds its own
    surface; under MPI the columns are shared between ranks."""
    p = _cloud(lambda x: x[:, 1] < np.where(x[:, 0] < 1.0, 4.0, 2.5))
    k0_stress(p, gravity=G, K0=0.6)
    _check(p, np.where(p.x[:, 0] < 1.0, 4.0, 2.5), 0.6)


def test_sloping_surface_function_and_density():
    """surface(x) = 3 + 0.25 x, given density and K0; the mesh density is ignored."""
    surf = lambda x: 3.0 + 0.25 * x[:, 0]                              # noqa: E731
    p = _cloud(lambda x: x[:, 1] < surf(x), material=fm.LinearElastic(1e7, 0.3, 1000.0))
    k0_stress(p, density=RHO, gravity=G, K0=0.5, surface=surf)
    _check(p, surf(p.x), 0.5)


def test_mohr_coulomb_default_k0_is_elastic():
    """The documented default for every material, MohrCoulomb included, is nu / (1 - nu)
    (the L3 column-collapse state); Jaky's 1 - sin(phi) must be passed explicitly."""
    mc = fm.MohrCoulomb(E=20e6, nu=0.42, density=RHO, phi=42.0, c=1e3)
    p = _cloud(lambda x: x[:, 1] < 4.0, material=mc)
    k0_stress(p, gravity=G)
    _check(p, 4.0, 0.42 / 0.58)
    k0_stress(p, gravity=G, K0=1.0 - np.sin(np.radians(42.0)))
    _check(p, 4.0, 1.0 - np.sin(np.radians(42.0)))


def test_3d_vertical_axis_is_z():
    msh = dmesh.create_box(MPI.COMM_WORLD, [[0.0, 0.0, 0.0], [1.0, 1.0, 2.0]], [2, 2, 4],
                           dmesh.CellType.hexahedron)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(1e7, 0.25, RHO), per_cell=2,
                          region=lambda x: x[:, 2] < 1.5)
    k0_stress(p, gravity=G)
    s, z = p.stress, p.x[:, 2]
    assert _worst(p, s[:, 2, 2], -RHO * G * (1.5 - z)) < 0.01
    assert _worst(p, s[:, 0, 0], s[:, 2, 2] / 3.0) < 1e-12
    assert _worst(p, s[:, 1, 1], s[:, 2, 2] / 3.0) < 1e-12


@pytest.mark.parametrize("kw,match", [(dict(gravity=0.0), "'gravity'"),
                                      (dict(K0=-0.1), "'K0'"),
                                      (dict(density=-5.0), "'density'")])
def test_bad_inputs(kw, match):
    p = _cloud(lambda x: x[:, 1] < 4.0)
    with pytest.raises(ValueError, match=match):
        k0_stress(p, **kw)
