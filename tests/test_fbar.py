"""F-bar against volumetric locking (kernels.fbar, Simulation(fbar=True); issue 21).

Prandtl's smooth strip footing on weightless Tresca soil (fenicsmpm.problems.footing:
VonMises nu = 0.49, c_u = 10 kPa, rigid footing B/2 = 0.5 m pushed at 2e-3 c_s through
frictionless multi-velocity contact), coarse h = 0.25 m (2 cells under the half-width), the
pressure averaged over every step of t = 0.5-0.8 s (the quick `bearing-capacity` bench
case). Exact: (2 + pi) c_u.
Measured q / (2 + pi) c_u at h = 0.25 m with node-wise contact (interface="node", the default
before 2026-12-07): the defaults (cpGIMP and F-bar for von Mises) 1.165; standard family 1.065
with F-bar, 2.23 without (locking: still rising); the defaults with nu = 0.3 1.131, under a
rough footing 1.269; on Mohr-Coulomb soil (cpGIMP since 2026-12-06) 1.063 (phi 20) and 0.829
(phi 30) of c N_c. With the coverage contact (the default on 2026-12-07 until late that
day): 1.3416, 1.1026, 1.8654, 1.2155, 1.3549, 0.948, 0.8309; with the default since, the
paired contact scaled by the coverage: 1.1331, 1.1026, 1.8654, 1.0098, 1.1615, 0.9884,
0.8607. The h series is in docs/measured.md (`python -m fenicsmpm.bench
bearing-capacity`) and docs/guide/contact.md.
Also: F-bar leaves an isochoric increment alone and makes a cell's particles share one
volume change; serial and under mpirun -n 2."""
import numpy as np
import pytest

import fenicsmpm as fm
from fenicsmpm.kernels.fbar import fbar


@pytest.mark.heavy
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
    q = {r["name"]: r["metrics"]["plateau"] for r in doc["runs"]}
    print(f"\nq / (2 + pi) c_u at h = 0.25 m: {q}")
    # interface="node" (every node projected alone, the default before 2026-12-07), the
    # bounds of then: standard family with F-bar 1.065, the defaults 1.165, nu = 0.3 1.131,
    # rough 1.269 (1.083 / 1.053 at 5 / 10 cells; 1.349 while it stuck a cell row of soil to
    # the footing, docs/guide/choosing.md); its half model holds the node on the symmetry
    # line only in part (the whole footing reads 1.374: test_coverage_contact.py)
    assert abs(q["h0.25-mpm-fbar-on-node"] - 1.0) < 0.10, q
    assert abs(q["h0.25-node"] - 1.0) < 0.20, q
    assert abs(q["h0.25-nu0.3-node"] - 1.0) < 0.20, q
    assert 1.0 < q["h0.25-rough-node"] < 1.3, q
    assert q["h0.25-mpm-fbar-off"] > 1.8, q
    # the default interface="auto" (the footing, a box: pairs of nodes across its surface,
    # scaled by its coverage of them): from above at 2 cells, 1.1026 (standard family +
    # F-bar), 1.1331 (the defaults), 1.0098 (nu = 0.3), 1.1615 (rough; the coverage
    # interface, the default before: 1.3416 / 1.2155 / 1.3549); within 3 % at 10 cells
    # (0.9989 / 1.0008 / 1.0079, bench bearing-capacity, docs/guide/contact.md)
    assert abs(q["h0.25-mpm-fbar-on"] - 1.0) < 0.15, q
    for row in ("default", "nu0.3", "rough"):
        assert 1.0 < q[f"h0.25-{row}"] < 1.2, q
    # the rough footing with its edge at a cell centre (2.5 cells under B/2), node-wise: 1.087,
    # still rising at the end of the push (1.004 / 1.029 at 5.5 / 10.5 cells,
    # docs/guide/choosing.md); with the default interface 0.9645 (the coverage interface,
    # the default before: 1.1124; docs/guide/contact.md)
    assert abs(q["h0.2-rough-centred-node"] - 1.0) < 0.1, q
    assert abs(q["h0.2-rough-centred"] - 1.0) < 0.05, q
    # weightless associated Mohr-Coulomb (cpGIMP without F-bar, the defaults for it since
    # 2026-12-06) against Reissner's c N_c over 110-276 mm, ringing +-13 % from window to
    # window: 1.063 (phi 20) and 0.829 (phi 30) at these 2 cells under B/2 node-wise (0.9884
    # / 0.8607 with the default interface), 1.096 / 1.054 and 1.021 / 1.015 at 5 / 10 cells (the standard family, the default before: 1.031 /
    # 1.039 / 1.004 and 0.963 / 0.948 / 0.945, docs/guide/choosing.md). At 2 cells the
    # phi = 30 deg mechanism (4.3 m long, a cell deep near the surface) is under-resolved
    # and its plateau decays after the peak (1.12 at 1 s): asserted within 20 % here,
    # within 5 % at 10 cells in the bench.
    # The standard family keeps its bound of before (0.963 measured): the mc30 row's wider
    # one is for cpGIMP, a different method at this size, not a loosened check of the same.
    assert abs(q["h0.25-mc20"] - 1.0) < 0.1, q
    assert abs(q["h0.25-mc30"] - 1.0) < 0.2, q
    assert abs(q["h0.25-mc30-mpm"] - 1.0) < 0.1, q
    # the implicit particle footing, 30 mm in 60 steps, its edge at a cell centre (2.5 cells
    # under B/2): 1.010 (nu 0.49) / 0.989 (nu 0.3) / 1.019 (rough) (0.996 / 0.973 / 1.007 at
    # 10.5 cells, docs/guide/choosing.md; with the edge on a grid line 1.261 / 1.224 / 1.273)
    for row in ("implicit", "implicit-nu0.3", "implicit-rough"):
        assert abs(q[f"h0.2-{row}"] - 1.0) < 0.03, q
    # the implicit W5 footing at peak strength, 2.5 cells under B/2 (its edge at a cell
    # centre): collapse pressure (mean over 0.12-0.16 B) measured 0.973 (test_w5_collapse)
    assert abs(q["w5-h0.1"] - 1.0) < 0.05, q
    m = {r["name"]: r["metrics"] for r in doc["runs"]}
    assert m["w5-h0.1"]["half_width_effective"] == pytest.approx(0.25)
    assert m["h0.2-implicit"]["half_width_effective"] == pytest.approx(0.5)
    assert {r["name"]: (r["config"]["shape"], r["config"]["fbar"]) for r in doc["runs"]}[
        "h0.25-default"] == ("cpgimp", True)


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


def test_fbar_refuses_what_it_does_not_support():
    from dolfinx import mesh
    from mpi4py import MPI
    grid = fm.Grid(mesh.create_rectangle(MPI.COMM_WORLD, [[0, 0], [1, 1]], [4, 4],
                                         mesh.CellType.quadrilateral))
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1e3))
    axi = fm.Grid(grid.mesh, axisymmetric=True)
    with pytest.raises(NotImplementedError, match="fbar=True needs a plane or 3D grid"):
        fm.Simulation(axi, fm.Particles.fill(axi, fm.LinearElastic(E=1e6, nu=0.3, density=1e3)),
                      fm.Newmark(), dt=1e-3, fbar=True)
    with pytest.raises(NotImplementedError, match="fbar"):
        fm.Simulation(grid, p, fm.DoubleMappingQuasiStatic(), dt=1e-3, fbar=True, shape="cpgimp")
    with pytest.raises(ValueError, match="fbar"):
        fm.Simulation(grid, p, fm.Explicit(), dt=1e-3, fbar="yes")


def _tangent_scene(cells, plastic, shape):
    """The F-bar tangent test's scene on a serial cells x cells mesh (nu = 0.45, a distorted,
    stressed state, F-bar, QuasiStatic): (sim, internal(du) -> (-f_int, stress), du,
    assemble() -> K as a dense array (None: assemble only), rng)."""
    from dolfinx import mesh
    from mpi4py import MPI
    from fenicsmpm.materials import first_piola, first_piola_tangent
    grid = fm.Grid(mesh.create_rectangle(MPI.COMM_SELF, [[0, 0], [1, 1]], [cells, cells],
                                         mesh.CellType.quadrilateral))
    mat = (fm.VonMises(E=1e6, nu=0.45, density=1e3, c_u=2e3) if plastic
           else fm.LinearElastic(E=1e6, nu=0.45, density=1e3))
    p = fm.Particles.fill(grid, mat, per_cell=2)
    rng = np.random.default_rng(1)
    p.F[:, :2, :2] += 0.05 * rng.standard_normal((len(p), 2, 2))
    s = 1e3 * rng.standard_normal((len(p), 2, 2))
    p.stress[:, :2, :2] += s + s.transpose(0, 2, 1)
    sim = fm.Simulation(grid, p, fm.QuasiStatic(), dt=1.0, fbar=True, shape=shape)
    sim.locate_and_shape()
    integ, n, idx = sim.integrator, len(p), np.arange(len(p))

    def internal(du):
        integ.strain_increment(sim, du)
        sig = sim.trial_stress(sim._dF)
        P = np.empty((n, 3, 3))
        first_piola(idx, sim._dF, sim.dynamic_stress(sig), P)
        out = np.zeros_like(du)
        sim.internal_force(P, out)                    # -f_int
        return out, sig

    du = 0.01 * rng.standard_normal((grid.n_nodes, 2))
    _, sig = internal(du)
    if plastic:
        assert np.any(sim._state_new[:, 0] > p.state[:, 0])      # some particles yield

    def assemble(dense=True):
        dsig, A4 = np.empty((n, 3, 3, 3, 3)), np.empty((n, 3, 3, 3, 3))
        for m, g in sim.material_groups():
            m.tangent(g, sim._dF, p.F, p.stress, sig, p.state, dsig)
        first_piola_tangent(idx, sim._dF, sim.dynamic_stress(sig), dsig, A4)
        nd = grid.n_nodes * 2
        integ.assemble_tangent(sim, A4, integ.system.plan(sim.nodes), np.zeros(nd),
                               np.zeros(nd, dtype=bool))
        return integ.system.A.convert("dense").getDenseArray() if dense else None
    return sim, internal, du, assemble, rng


@pytest.mark.parametrize("plastic,shape", [(False, "mpm"), (True, "mpm"), (False, "cpgimp"),
                                           (True, "cpgimp")])
def test_implicit_fbar_tangent_matches_finite_differences(plastic, shape):
    """The implicit F-bar tangent (kernels.fbar.fbar_stiffness, assembled by the Newton
    integrators) is the derivative of the F-bar internal force: K d against a central
    difference of f_int along a random direction d, at a random increment du from a
    distorted, stressed state (nu = 0.45; von Mises yielding with its consistent tangent),
    standard and cpGIMP shapes (the latter couples the nodes of all particles of a cell).
    Measured relative error 5.4e-11 / 1.9e-10 (standard, elastic / plastic), 4.2e-11 /
    2.5e-10 (cpGIMP); K unsymmetric (3-5 %). Each rank checks its own serial mesh."""
    sim, internal, du, assemble, rng = _tangent_scene(3, plastic, shape)
    K = assemble()
    d = rng.standard_normal(du.shape)
    eps = 1e-6
    fd = -(internal(du + eps * d)[0] - internal(du - eps * d)[0]).ravel() / (2 * eps)
    err = np.abs(K @ d.ravel() - fd).max() / np.abs(fd).max()
    print(f"\nF-bar tangent ({'plastic' if plastic else 'elastic'}, {shape}): FD error {err:.1e}, "
          f"asymmetry {np.abs(K - K.T).max() / np.abs(K).max():.3f}")
    assert err < 1e-7, err


def test_fbar_tangent_same_on_any_chunk_count(monkeypatch):
    """kernels.fbar.fbar_stiffness cut into 1, 2, 3 and 5 chunks of cells (threaded; chunk c >=
    1 adds into its own CSR values): the same matrix to round-off (1e-13 relative), on the
    tangent test's plastic cpGIMP scene at 66 x 66 cells (17,424 particles, two chunks of
    8192 or more: the size at which the library cuts the pass)."""
    from fenicsmpm.integrators import linear_system
    from fenicsmpm.kernels import fbar as kf
    from fenicsmpm.kernels.threads import MIN_CHUNK
    seen = []

    def record(*args):
        seen.append(args)
        return kf.fbar_stiffness(*args)
    monkeypatch.setattr(linear_system, "fbar_stiffness", record)
    sim, _, _, assemble, _ = _tangent_scene(66, True, "cpgimp")
    assert len(sim.particles) >= 2 * MIN_CHUNK
    assemble(dense=False)
    args = seen[-1]
    out = []
    for nc in (1, 2, 3, 5):
        data = np.zeros_like(args[-1])
        bad = kf._fbar_chunks(nc, *args[:-1], data, np.full((nc - 1,) + data.shape, np.nan))
        assert bad == -1
        out.append(data)
    assert np.any(out[0] != 0.0)
    for data in out[1:]:
        assert np.max(np.abs(data - out[0])) <= 1e-13 * np.max(np.abs(out[0]))


@pytest.mark.heavy
def test_rough_and_smooth_contact_footings():
    """Tresca soil has the same limit under a smooth and a rough footing. With penalty
    contact (node-to-segment, problems.footing.strip_footing(algorithm="penalty")) the two
    agree at h = 0.25 m (measured 1.234 / 1.228 (2 + pi) c_u). With multi-velocity contact
    the rough footing sticks only the nodes on its side of its base (contact.multi_velocity,
    "Friction against a rigid body"; node-wise, interface="node", where it mattered):
    measured 1.269 against 1.165 smooth; when it also stuck the contact nodes of the cell
    below its base, 1.349, and the upper node row carried 0.741 of the load against 0.316
    smooth (problems.footing.contact_load_shares; now 0.167)."""
    from mpi4py import MPI
    from fenicsmpm.bench import bearing_capacity as bc
    from fenicsmpm.problems.footing import contact_load_shares
    comm = MPI.COMM_WORLD
    q = [bc._row(0.25, "p", "auto", "auto", comm, bc.PUSH, mu=mu, algorithm="penalty")["metrics"]["plateau"]
         for mu in (0.0, 10.0)]
    assert abs(q[0] - q[1]) < 0.02 * q[0] and 1.0 < q[1] < 1.35, q
    upper, qs = [], []
    for mu in (0.0, 10.0):
        x, share, qm = contact_load_shares(0.25, mu=mu, interface="node")
        assert abs(comm.allreduce(float(share.sum())) - 1.0) < 1e-12
        upper.append(comm.allreduce(float(share[np.isclose(x[:, 1], 3.0)].sum())))
        qs.append(qm)
    assert 1.0 < qs[0] < qs[1] < 1.1 * qs[0] and qs[1] < 1.3, qs
    assert upper[1] < 0.7 * upper[0], upper


@pytest.mark.parametrize("shape", ["mpm", "cpgimp"])
def test_implicit_fbar_oedometer_is_exact(shape):
    """Implicit F-bar with the standard and a wide family (kernels.fbar.fbar_stiffness: with
    cpGIMP a cell's particles couple one ring further), serially and on 2 ranks: a nearly
    incompressible elastic block (nu = 0.49, 4 x 4 cells, 2 x 2 particles per cell) compressed
    oedometrically by 1e-3 of its height in two quasi-static steps carries the homogeneous
    sigma_yy = -M eps (M the constrained modulus) at every particle: standard family to
    round-off (measured 4.5e-13), cpGIMP to 2e-3 (measured 1.50e-3 at worst, 7.5e-7 on
    average; 1.51e-3 without F-bar: cpGIMP's own error, not F-bar's: the compressed body's top
    lies eps H inside the top cell row, so the domains there fall short of the nodes' support
    by O(eps H / h)); Newton converges in at most 3 iterations per step."""
    from mpi4py import MPI
    from scenes import oedometric_block, pushed_top
    eps = 1e-3
    qs = fm.QuasiStatic(displacement=pushed_top(eps))
    sim, M = oedometric_block(qs, nu=0.49, dt=0.5, fbar=True, shape=shape)
    p = sim.particles
    sim.run(t_end=1.0, progress=False)
    assert sim.shape == shape and max(qs.iterations) <= 3, qs.iterations
    err = np.abs(p.stress[:, 1, 1] / (-M * eps) - 1.0)
    worst = sim.comm.allreduce(float(err.max()) if len(p) else 0.0, op=MPI.MAX)
    assert worst < (1e-10 if shape == "mpm" else 2e-3), worst


def test_limit_pressures_of_the_footing_scene():
    """problems.footing.limit_pressure: Prandtl's (2 + pi) c_u and Reissner's c N_c, against
    the textbook bearing-capacity factors N_c(20 deg) = 14.83, N_c(30 deg) = 30.14."""
    from fenicsmpm.problems.footing import limit_pressure
    assert limit_pressure(fm.VonMises(E=1e7, nu=0.3, density=1.0, c_u=1e4)) == \
        pytest.approx((2.0 + np.pi) * 1e4, rel=1e-14)
    for phi, n_c in ((20.0, 14.83), (30.0, 30.14)):
        mc = fm.MohrCoulomb(E=1e7, nu=0.3, density=1.0, phi=phi, c=1e4, psi=phi)
        assert limit_pressure(mc) == pytest.approx(1e4 * n_c, rel=5e-4)
    with pytest.raises(ValueError, match="'soil'"):
        limit_pressure(fm.LinearElastic(E=1e7, nu=0.3, density=1.0))
    from fenicsmpm.problems.footing import strip_footing
    with pytest.raises(ValueError, match="'room'"):
        strip_footing(room=-1.0)
