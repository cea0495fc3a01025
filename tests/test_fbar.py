"""F-bar against volumetric locking (kernels.fbar, Simulation(fbar=True); issue 21).

Prandtl's smooth strip footing on weightless Tresca soil (fenicsmpm.problems.footing:
VonMises nu = 0.49, c_u = 10 kPa, rigid footing B/2 = 0.5 m pushed at 2e-3 c_s through
frictionless multi-velocity contact), coarse h = 0.25 m (2 cells under the half-width), the
pressure averaged over settlements 14-38 mm (t = 0.5-0.8 s; the quick `bearing-capacity`
bench case). Exact: (2 + pi) c_u.
Measured q / (2 + pi) c_u: 1.045 with F-bar, 2.21 without (locking: still rising); at
h = 0.1 m (`python -m fenicsmpm.bench bearing-capacity`): 1.02 with F-bar, 1.81 without.
Also: F-bar leaves an isochoric increment alone and makes a cell's particles share one
volume change; serial and under mpirun -n 2."""
import numpy as np
import pytest

import fenicsmpm as fm
from fenicsmpm.kernels.fbar import fbar


def test_prandtl_footing_with_and_without_fbar(tmp_path_factory):
    """The quick `bearing-capacity` bench case: its JSON, PNG and plateaus."""
    import os
    from mpi4py import MPI
    from demo_helpers import exist_on_rank0
    from fenicsmpm.bench import bearing_capacity
    comm = MPI.COMM_WORLD
    out = comm.bcast(str(tmp_path_factory.mktemp("bc")) if comm.rank == 0 else None)
    doc = bearing_capacity.run(quick=True, out=out, verbose=False)
    assert exist_on_rank0(os.path.join(out, "bearing-capacity.json"),
                          os.path.join(out, "bearing-capacity.png"))
    q = {r["config"]["fbar"]: r["metrics"]["plateau"] for r in doc["runs"]}
    print(f"\nq / (2 + pi) c_u at h = 0.25 m: F-bar {q[True]:.3f}, without {q[False]:.3f}")
    assert abs(q[True] - 1.0) < 0.10, q
    assert q[False] > 1.8, q


def test_fbar_kernel_shares_the_volume_change():
    rng = np.random.default_rng(1)
    dF = np.tile(np.eye(3), (4, 1, 1))
    dF[:, :2, :2] += 0.05 * rng.standard_normal((4, 2, 2))
    iso = dF.copy()
    iso[3, :2, :2] /= np.sqrt(np.linalg.det(iso[3, :2, :2]))     # det 1
    cell = np.array([0, 0, 0, 1], dtype=np.int32)
    V = np.array([1.0, 2.0, 3.0, 1.0])
    out = iso.copy()
    fbar(cell, V, out, 2, 2)
    J = np.linalg.det(iso[:3])
    Jbar = np.sum(V[:3] * J) / V[:3].sum()
    assert np.allclose(np.linalg.det(out[:3]), Jbar, rtol=1e-13)
    assert np.allclose(out[3], iso[3], rtol=1e-14)                   # alone in its cell: unchanged
    assert np.allclose(out[:, 2, 2], 1.0)                            # plane strain: dF_33 stays
    # deviatoric part kept: dF / sqrt(det) unchanged
    dev = lambda a: a[:, :2, :2] / np.sqrt(np.linalg.det(a[:, :2, :2]))[:, None, None]
    assert np.allclose(dev(out), dev(iso), rtol=1e-12)


def test_fbar_needs_an_explicit_integrator():
    from dolfinx import mesh
    from mpi4py import MPI
    grid = fm.Grid(mesh.create_rectangle(MPI.COMM_WORLD, [[0, 0], [1, 1]], [4, 4],
                                         mesh.CellType.quadrilateral))
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1e3))
    with pytest.raises(NotImplementedError, match="fbar"):
        fm.Simulation(grid, p, fm.Newmark(), dt=1e-3, fbar=True)
    with pytest.raises(ValueError, match="fbar"):
        fm.Simulation(grid, p, fm.Explicit(), dt=1e-3, fbar="yes")
