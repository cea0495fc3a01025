"""Fused particle passes (kernels.fused; issue 16): the one-pass linear-elastic stress update
gives the same bits as the three passes it replaces (incremental_F, the Jaumann stress,
commit_step), per kernel and over whole explicit runs (MUSL, USF, AVG, explicit
generalized-alpha), serial and under mpirun -n 2 (there to round-off in global sums: two
meshes built in one process may be partitioned differently); the `fused` bench case."""
import numpy as np
import pytest

import fenicsmpm as fm
from fenicsmpm.kernels import transfer as kt
from fenicsmpm.kernels.fused import elastic_step
from fenicsmpm.materials.linear_elastic import linear_elastic_stress_kernel


def _random_particles(rng, n, n_nodes, nv, d):
    nodes = rng.integers(0, n_nodes, size=(n, nv)).astype(np.int32)
    dN = rng.standard_normal((n, nv, d))
    w = 0.05 * rng.standard_normal((n_nodes, d))
    F = np.tile(np.eye(3), (n, 1, 1)) + 0.1 * rng.standard_normal((n, 3, 3))
    V = rng.uniform(0.5, 1.5, n)
    sigma = rng.standard_normal((n, 3, 3))
    sigma = 0.5 * (sigma + sigma.transpose(0, 2, 1))
    if d == 2:          # plane strain: F_zz = 1, no out-of-plane shear (sigma_zz stays)
        F[:, 2, :2] = F[:, :2, 2] = 0.0
        F[:, 2, 2] = 1.0
        sigma[:, 2, :2] = sigma[:, :2, 2] = 0.0
    return nodes, dN, w, F, V, sigma, rng.standard_normal(n)


@pytest.mark.parametrize("d", [2, 3])
def test_elastic_step_is_bit_identical_to_the_three_passes(d):
    rng = np.random.default_rng(7)
    n, n_nodes, nv = 500, 60, 2 ** d
    nodes, dN, w, F, V, sigma, work = _random_particles(rng, n, n_nodes, nv, d)
    w[nodes[3]] *= 200.0                       # some increments invert particles
    D = (0,) * d
    lam, mu = 3.0e6, 2.0e6
    # three passes
    dF = np.empty((n, 3, 3))
    kt.incremental_F(D, nodes, dN, w, 0.7, dF)
    s_new = np.empty((n, 3, 3))
    linear_elastic_stress_kernel(np.arange(n), dF, sigma, s_new, lam, mu)
    F1, V1, s1, w1, inv1 = F.copy(), V.copy(), sigma.copy(), work.copy(), np.zeros(n, np.int8)
    bad1 = kt.commit_step(dF, F1, V1, s1, s_new, w1, inv1)
    # one pass
    F2, V2, s2, w2, inv2 = F.copy(), V.copy(), sigma.copy(), work.copy(), np.zeros(n, np.int8)
    bad2 = elastic_step(D, nodes, dN, w, 0.7, lam, mu, F2, V2, s2, w2, inv2)
    assert bad1 == bad2 > 0
    for a, b in ((F1, F2), (V1, V2), (s1, s2), (w1, w2), (inv1, inv2)):
        assert np.array_equal(a, b)


class _Unfused(fm.LinearElastic):
    """A LinearElastic that Simulation.stress_update does not fuse (the three-pass path)."""


def _run(material, integrator, shape):
    from dolfinx import mesh
    from mpi4py import MPI
    grid = fm.Grid(mesh.create_rectangle(MPI.COMM_WORLD, [[0, 0], [2, 1]], [16, 8],
                                         mesh.CellType.quadrilateral))
    p = fm.Particles.fill(grid, material, per_cell=2, region=lambda x: x[:, 1] < 0.6)
    p.v[:, 0] = 0.3 * np.sin(np.pi * p.x[:, 0])
    sim = fm.Simulation(grid, p, integrator, dt="auto", gravity=(0.0, -9.81), shape=shape)
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    sim.run(steps=60)
    q = sim.particles
    return sim, {k: getattr(q, k).copy() for k in ("x", "u", "v", "stress", "F", "V", "work")}


@pytest.mark.parametrize("integrator,shape", [
    (lambda: fm.Explicit("MUSL"), "auto"), (lambda: fm.Explicit("USF"), "mpm"),
    (lambda: fm.Explicit("AVG"), "mpm"), (lambda: fm.ExplicitGeneralizedAlpha(), "mpm")])
def test_simulation_uses_the_fused_pass_with_the_same_result(integrator, shape):
    from mpi4py import MPI
    kw = dict(E=1e6, nu=0.3, density=1000.0)
    sim_f, fused = _run(fm.LinearElastic(**kw), integrator(), shape)
    sim_p, plain = _run(_Unfused(**kw), integrator(), shape)
    assert "dF" not in sim_f._scratch and "dF" in sim_p._scratch     # which path ran
    comm = sim_f.comm
    for k in fused:
        if comm.size == 1:
            assert np.array_equal(fused[k], plain[k]), k
        else:       # the two meshes may be partitioned differently: compare global sums
            sums = [comm.allreduce(np.array([a.sum(), (a * a).sum()])) for a in (fused[k], plain[k])]
            assert np.allclose(sums[0], sums[1], rtol=1e-12, atol=0.0), (k, sums)
    moved = comm.allreduce(float(np.abs(fused["u"]).max()) if len(fused["u"]) else 0.0,
                                 op=MPI.MAX)
    assert moved > 1e-4            # the scene did move (the comparison is not trivially true)


def test_bench_case_quick(tmp_path_factory):
    """`python -m fenicsmpm.bench fused --quick`: JSON and PNG, the elastic pass at 4 and 9
    nodes per particle (timings are recorded, not asserted: shared machine)."""
    import json
    import os
    from mpi4py import MPI
    from demo_helpers import exist_on_rank0
    from fenicsmpm import bench
    comm = MPI.COMM_WORLD
    out = comm.bcast(str(tmp_path_factory.mktemp("fused")) if comm.rank == 0 else None)
    doc = bench.get_case("fused")(quick=True, out=out, verbose=False)
    assert exist_on_rank0(os.path.join(out, "fused.json"), os.path.join(out, "fused.png"))
    assert sorted(r["name"] for r in doc["runs"]) == ["elastic-nv4", "elastic-nv9"]
    for r in doc["runs"]:
        m = r["metrics"]
        assert m["ms_fused"] > 0 and m["ms_separate"] > 0 and m["speed_up"] > 0
    if comm.rank == 0:
        with open(os.path.join(out, "fused.json")) as f:
            assert json.load(f)["case"] == "fused"


@pytest.mark.parametrize("material", [
    fm.MohrCoulomb(E=1e7, nu=0.3, density=1800.0, phi=30.0, c=5e3, psi=5.0, tension_cutoff=1e3,
                   phi_res=20.0, c_res=1e3, eta=10.0),
    fm.VonMises(E=1e7, nu=0.45, density=1800.0, c_u=2e4, c_res=5e3, H=-2e5),
    fm.Hypoplastic(phi_c=30.0, h_s=5.8e9, n=0.28, e_d0=0.53, e_c0=0.84, e_i0=1.0, alpha=0.13,
                   beta=1.0, m_R=10.0, m_T=2.0, R=5e-5, beta_r=0.3, chi=1.0, density=2600.0,
                   e_0=0.65, p_t=1600.0)],                          # seed 004 Table 3.1
    ids=["MohrCoulomb", "VonMises", "Hypoplastic"])
def test_threaded_return_mapping_is_bit_identical_to_one_pass(material):
    """The plastic stress (and tangent) kernels run in chunks of kernels.threads.RETURN_CHUNK particles
    (threaded); per-particle results do not depend on the chunks: compare 4096 particles in
    one call against 16 calls of 256 (one chunk each), with elastic, plastic, apex/cut-off
    and gap-closing states mixed."""
    rng = np.random.default_rng(11)
    n = 4096
    dF = np.tile(np.eye(3), (n, 1, 1))
    dF[:, :2, :2] += 0.004 * rng.standard_normal((n, 2, 2))
    sigma = np.zeros((n, 3, 3))
    sigma[:, range(3), range(3)] = -rng.uniform(0.0, 1e5, (n, 3))
    state = np.zeros((n, material.n_state))
    state[:, 0] = rng.uniform(0.0, 0.05, n)
    if isinstance(material, fm.Hypoplastic):
        state[:] = 0.0                           # fresh: the material sets e_0, delta_0
        sigma[:, range(3), range(3)] = -rng.uniform(5e4, 1e5, (n, 3))   # e_0 admissible
    elif material.n_state > 2:
        state[::3, 2] = rng.uniform(0.0, 1e-3, len(state[::3]))       # MC gaps to close
    out1, st1 = np.empty((n, 3, 3)), state.copy()
    material.stress(np.arange(n), dF, None, sigma, out1, st1)
    out2, st2 = np.empty((n, 3, 3)), state.copy()
    for k in range(0, n, 256):
        material.stress(np.arange(k, k + 256), dF, None, sigma, out2, st2)
    assert np.array_equal(out1, out2) and np.array_equal(st1, st2)
    if not isinstance(material, fm.Hypoplastic):          # the consistent tangents likewise
        t1, t2 = np.empty((n, 3, 3, 3, 3)), np.empty((n, 3, 3, 3, 3))
        material.tangent(np.arange(n), dF, None, sigma, out1, state, t1)
        for k in range(0, n, 256):
            material.tangent(np.arange(k, k + 256), dF, None, sigma, out1, state, t2)
        assert np.array_equal(t1, t2)
    changed = st1[:, 0] != state[:, 0] if not isinstance(material, fm.Hypoplastic) else \
        np.abs(out1 - sigma).max(axis=(1, 2)) > 0
    assert np.count_nonzero(changed) > n // 10        # the states did evolve
