"""Threaded particle kernels (kernels.threads): the results do not depend on the thread count.

1. Kernels: each threaded pass cut into 1, 2, 3 and 5 chunks against its serial loop over
   all particles: per-particle passes (G2P, dF, gradient restriction, commit) bit for bit,
   P2G sums to round-off (1e-14 relative).
2. A run: the same explicit MUSL run (an elastic block spinning and stretching, no
   boundary conditions, no gravity; 17,956 particles, so the passes are cut into chunks) in
   child processes with NUMBA_NUM_THREADS=1 and 2, for the standard shape functions and
   cpGIMP: positions, velocities and stresses agree to 1e-12 relative, and the total
   momentum is conserved to 1e-12 (relative to sum_p m_p |v_p|) on either thread count.
3. Under MPI without NUMBA_NUM_THREADS each rank gets its share of the cores.
"""
import json
import os
import subprocess
import sys

import numba
import numpy as np
import pytest
from mpi4py import MPI

from fenicsmpm.kernels import threads as th
from fenicsmpm.kernels import transfer as kt

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# ------------------------------------------------------------------------------ kernels
@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(7)
    n, nn, nv, d = 20000, 6000, 9, 2
    base = np.sort(rng.integers(0, nn - 100, n))
    nodes = (base[:, None] + rng.integers(0, 100, (n, nv))).astype(np.int32)
    return dict(D=(0,) * d, n=n, nn=nn, d=d, nodes=nodes, N=rng.random((n, nv)),
                dN=rng.standard_normal((n, nv, d)), mass=rng.random(n),
                v=rng.standard_normal((n, d)), V=rng.random(n),
                S=rng.standard_normal((n, 3, 3)), g=rng.standard_normal(d),
                C=rng.standard_normal((n, d, d)), x=rng.random((n, d)),
                node_x=rng.random((nn, d)), w=rng.standard_normal((nn, d)),
                w2=rng.standard_normal((nn, d)))


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def _bufs(nc, *outs):
    """Per-chunk nodal arrays of the P2G drivers, filled with NaN (a node a chunk adds to
    must be zeroed by it first)."""
    return [np.full((nc - 1,) + o.shape, np.nan) for o in outs]


@pytest.mark.parametrize("nc", [1, 2, 3])
def test_force_pass_restricts_as_the_separate_pass(data, nc):
    """p2g_force with the active-node mask restricts each row's gradients in its own pass:
    the same gradients, bit for bit, as restrict_gradients before the force, and the same
    force to round-off of the chunk sums (Simulation.active_mask(m, restrict=False) then
    internal_force(..., active=...), the explicit MUSL/USL step)."""
    D, nodes, N, nn, d = (data[k] for k in ("D", "nodes", "N", "nn", "d"))
    active = np.random.default_rng(3).random(nn) > 0.2        # a fifth of the nodes inactive
    dN0, dN1 = data["dN"].copy(), data["dN"].copy()
    kt.restrict_gradients(D, nodes, N, dN0, active[:, None], np.zeros(len(nodes), dtype=np.int64))
    assert not np.array_equal(dN0, data["dN"])
    args = (data["mass"], data["V"], data["S"], data["g"], np.zeros((0, 1), dtype=np.bool_))
    f0, f1 = np.zeros((nn, d)), np.zeros((nn, d))
    kt._force(D, nodes, N, dN0, *args, 0, data["n"], f0)
    kt._p2g_force_chunks(nc, D, nodes, N, dN1, *args[:-1], active[:, None], f1, *_bufs(nc, f1))
    assert np.array_equal(dN1, dN0)
    assert _rel(f1, f0) < 1e-14


@pytest.mark.parametrize("nc", [2, 3, 5])
def test_p2g_chunks_match_serial(data, nc):
    """P2G with nc chunks (per-chunk nodal arrays, added afterwards) equals one pass."""
    D, nodes, N, m, v, nn, d = (data[k] for k in ("D", "nodes", "N", "mass", "v", "nn", "d"))
    n = data["n"]
    # serial references from the range loops; outputs start non-zero (kernels add into them)
    m0, mv0 = np.ones(nn), np.ones((nn, d))
    kt._mass_momentum(D, nodes, N, m, v, 0, n, m0, mv0)
    m1, mv1 = np.ones(nn), np.ones((nn, d))
    kt._p2g_mass_momentum_chunks(nc, D, nodes, N, m, v, m1, mv1, *_bufs(nc, m1, mv1))
    assert _rel(m1, m0) < 1e-14 and _rel(mv1, mv0) < 1e-14
    f0, f1 = np.ones((nn, d)), np.ones((nn, d))
    args = (D, nodes, N, data["dN"], m, data["V"], data["S"], data["g"],
            np.zeros((0, 1), dtype=np.bool_))
    kt._force(*args, 0, n, f0)
    kt._p2g_force_chunks(nc, *args, f1, *_bufs(nc, f1))
    assert _rel(f1, f0) < 1e-14
    q0, q1 = np.zeros((nn, d)), np.zeros((nn, d))
    kt._weighted(D, nodes, N, m, v, 0, n, q0)
    kt._p2g_weighted_chunks(nc, D, nodes, N, m, v, q1, *_bufs(nc, q1))
    assert _rel(q1, q0) < 1e-14
    s0, s1 = np.zeros(nn), np.zeros(nn)
    kt._mass(nodes, N, m, 0, n, s0)
    kt._p2g_mass_chunks(nc, nodes, N, m, s1, *_bufs(nc, s1))
    assert _rel(s1, s0) < 1e-14
    aff = (D, nodes, N, m, v, data["C"], data["x"], data["node_x"])
    a0, b0, a1, b1 = np.zeros(nn), np.zeros((nn, d)), np.zeros(nn), np.zeros((nn, d))
    kt._affine(*aff, 0, n, a0, b0)
    kt._p2g_affine_chunks(nc, *aff, a1, b1, *_bufs(nc, a1, b1))
    assert _rel(a1, a0) < 1e-14 and _rel(b1, b0) < 1e-14


def test_per_particle_passes_match_serial(data):
    """G2P, dF, FLIP blend, gradient restriction and commit cut into particle_chunks(n) > 1
    chunks give the serial loop's bits."""
    D, nodes, N, dN, n = (data[k] for k in ("D", "nodes", "N", "dN", "n"))
    assert th.particle_chunks(n) > 1
    x, v, w, w2 = data["x"], data["v"], data["w"], data["w2"]
    s0 = [x.copy(), v.copy(), x.copy()]
    s1 = [x.copy(), v.copy(), x.copy()]
    kt._g2p(D, nodes, N, w, w2, w, 0.9, *s0, 0, n)
    kt.g2p(D, nodes, N, w, w2, w, 0.9, *s1)
    assert all(np.array_equal(a, b) for a, b in zip(s0, s1))
    F0, F1 = np.empty((n, 3, 3)), np.empty((n, 3, 3))
    kt._incremental_F(D, nodes, dN, w, 0.3, 0, n, F0)
    kt.incremental_F(D, nodes, dN, w, 0.3, F1)
    assert np.array_equal(F0, F1)
    q0, q1 = v.copy(), v.copy()
    kt._flip_blend(D, nodes, N, w, w2, 0.7, q0, 0, n)
    kt.flip_blend(D, nodes, N, w, w2, 0.7, q1)
    assert np.array_equal(q0, q1)
    active = (np.arange(data["nn"]) % 7 != 0)[:, None]
    g0, g1 = dN.copy(), dN.copy()
    field = np.zeros(n, dtype=np.int64)
    kt._restrict(D, nodes, N, g0, active, field, 0, n)
    kt.restrict_gradients(D, nodes, N, g1, active, field)
    assert np.array_equal(g0, g1)
    rng = np.random.default_rng(3)
    dF = np.eye(3) + 0.1 * rng.standard_normal((n, 3, 3))
    dF[::97] *= -1.0                                    # some inverted increments
    st0 = [np.tile(np.eye(3), (n, 1, 1)), data["V"].copy(), data["S"].copy(), 2 * data["S"],
           np.zeros(n), np.zeros(n, dtype=np.int8)]
    st1 = [a.copy() for a in st0]
    assert kt._commit(dF, *st0, 0, n) == kt.commit_step(dF, *st1) > 0
    assert all(np.array_equal(a, b) for a, b in zip(st0, st1))


def test_chunks():
    """Chunks cover [0, n) contiguously; small passes run as one chunk."""
    for n, nc in ((10, 1), (4097, 2), (10**6, 7)):
        b = [th.chunk(n, nc, c) for c in range(nc)]
        assert b[0][0] == 0 and b[-1][1] == n and all(b[k][1] == b[k + 1][0] for k in range(nc - 1))
    assert th.n_chunks(2 * th.MIN_CHUNK - 1) == 1 and th.particle_chunks(2 * th.MIN_CHUNK - 1) == 1
    assert th.particle_chunks(10**9) == th.MAX_CHUNKS
    assert th.n_chunks(10**9) == numba.get_num_threads()


def test_mpi_ranks_share_the_cores(monkeypatch):
    """Without NUMBA_NUM_THREADS, k ranks on a node get cores // k threads each (>= 1)."""
    before = numba.get_num_threads()
    try:
        monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
        monkeypatch.setenv("OMPI_COMM_WORLD_LOCAL_SIZE", "2")
        share = max(1, numba.config.NUMBA_NUM_THREADS // 2)
        assert th.default_threads() == share == numba.get_num_threads()
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        monkeypatch.setenv("NUMBA_NUM_THREADS", str(numba.config.NUMBA_NUM_THREADS))
        assert th.default_threads() is None                     # the user's choice stands
        monkeypatch.delenv("NUMBA_NUM_THREADS")
        monkeypatch.setenv("OMPI_COMM_WORLD_LOCAL_SIZE", "1")
        assert th.default_threads() is None                     # one rank: numba's default
        assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS
    finally:
        numba.set_num_threads(before)


# ------------------------------------------------------------------------------ a run
RUN = r"""
import json, sys
import numba
import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI
import fenicsmpm as fm
from fenicsmpm.kernels.threads import n_chunks

out = {}
for shape in ("mpm", "cpgimp"):
    msh = dmesh.create_rectangle(MPI.COMM_SELF, [[0.0, 0.0], [1.0, 1.0]], [96, 96],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=1.0e4, nu=0.3, density=1.0)
    pts = fm.Particles.fill(grid, mat, per_cell=2,
                            region=lambda x: np.all(np.abs(x - 0.5) < 0.35, axis=1))
    r = pts.x - 0.5
    c = mat.p_wave_speed
    pts.v[:] = 0.05 * c * np.stack([-r[:, 1] + 0.5 * r[:, 0], r[:, 0] + np.sin(7 * r[:, 0])], 1)
    sim = fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt="auto", shape=shape)
    p0 = pts.total(pts.mass[:, None] * pts.v)
    scale = float(np.sum(pts.mass * np.linalg.norm(pts.v, axis=1)))
    sim.run(steps=25)
    p1 = pts.total(pts.mass[:, None] * pts.v)
    o = np.argsort(pts.id)
    out[shape] = dict(x=pts.x[o].tolist(), v=pts.v[o].tolist(), stress=pts.stress[o].tolist(),
                      momentum_error=float(np.max(np.abs(p1 - p0)) / scale), n=len(pts),
                      chunks=n_chunks(len(pts)), threads=numba.get_num_threads())
json.dump(out, open(sys.argv[1], "w"))
"""


def _run(threads, path):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "PMI_"))}
    env["NUMBA_NUM_THREADS"] = str(threads)
    r = subprocess.run([sys.executable, "-c", RUN, path], capture_output=True, text=True,
                       timeout=600, env=env, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    with open(path) as f:
        return json.load(f)


def test_run_on_1_and_2_threads(tmp_path):
    comm = MPI.COMM_WORLD
    res = None
    if comm.rank == 0:
        one, two = _run(1, str(tmp_path / "one.json")), _run(2, str(tmp_path / "two.json"))
        res = {}
        for shape in one:
            a, b = one[shape], two[shape]
            res[shape] = dict(n=a["n"], threads=(a["threads"], b["threads"]),
                              chunks=(a["chunks"], b["chunks"]),
                              momentum=(a["momentum_error"], b["momentum_error"]),
                              **{k: _rel(np.array(b[k]), np.array(a[k]))
                                 for k in ("x", "v", "stress")})
    res = comm.bcast(res, root=0)
    for shape, r in res.items():
        assert r["threads"] == (1, 2) and r["chunks"] == (1, 2), (shape, r)
        assert r["n"] == 17956, (shape, r)
        assert max(r["momentum"]) < 1e-12, (shape, r)
        assert r["x"] < 1e-12 and r["v"] < 1e-12 and r["stress"] < 1e-12, (shape, r)


def test_nonlocal_average_same_bits_on_1_and_2_threads():
    """materials.regularisation.nonlocal_average: chunks in parallel, the same bits as one
    thread (and 2048 points > RETURN_CHUNK, so there are several chunks)."""
    from fenicsmpm.materials.regularisation import nonlocal_average
    rng = np.random.default_rng(3)
    x = rng.random((2048, 2))
    vol = rng.random(2048) * 1e-3
    kap = np.where(rng.random(2048) < 0.5, rng.random(2048), 0.0)
    outs = []
    before = numba.get_num_threads()
    try:
        for t in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(t)
            out = np.empty(2000)
            nonlocal_average(x, vol, kap, 2000, np.zeros(2), 0.02, 0.03, out)
            outs.append(out)
    finally:
        numba.set_num_threads(before)
    assert np.any(outs[0] != 0.0)
    assert np.array_equal(outs[0], outs[1])


@pytest.mark.parametrize("d", [2, 3])
def test_affine_matrix_is_B_times_inverse_of_D(d):
    """kernels.transfer._affine_matrix (closed-form inverse, no allocation): C_p = B_p D_p^-1
    of numpy's solve to 1e-12, in 2D and 3D; the gradient fallback where D_p is singular."""
    rng = np.random.default_rng(11 + d)
    n, nn, nv = 200, 300, 3 ** d
    nodes = np.array([rng.choice(nn, nv, replace=False) for _ in range(n)], dtype=np.int32)
    N, dN = rng.random((n, nv)), rng.standard_normal((n, nv, d))
    x, node_x, v = rng.random((n, d)), rng.random((nn, d)), rng.standard_normal((nn, d))
    C = np.zeros((n, d, d))
    for p in range(n):
        kt._affine_matrix((0,) * d, nodes, N, dN, node_x, v, x, p, C)
    r = node_x[nodes] - x[:, None, :]                                  # (n, nv, d)
    B = np.einsum("pa,pak,pal->pkl", N, v[nodes], r)
    Dm = np.einsum("pa,pak,pal->pkl", N, r, r)
    ref = np.linalg.solve(np.transpose(Dm, (0, 2, 1)), np.transpose(B, (0, 2, 1)))
    assert _rel(C, np.transpose(ref, (0, 2, 1))) < 1e-12
    node_x[:] = x[0]                                # every node at particle 0: D_0 = 0
    kt._affine_matrix((0,) * d, nodes, N, dN, node_x, v, x, 0, C)
    assert np.allclose(C[0], np.einsum("ak,al->kl", v[nodes[0]], dN[0]), rtol=1e-14, atol=0)


@pytest.mark.parametrize("nc", [1, 2, 5])
def test_fused_affine_g2p_momentum_equals_the_two_passes(data, nc):
    """g2p_affine_momentum (MUSL's G2P and its affine P2G in one particle pass, cut into nc
    chunks) gives g2p_affine's particle state bit for bit and p2g_affine's momentum at the
    start positions to 1e-14."""
    D, nodes, N, dN, n, nn, d = (data[k] for k in ("D", "nodes", "N", "dN", "n", "nn", "d"))
    x, v, w, w2, m, nx = data["x"], data["v"], data["w"], data["w2"], data["mass"], data["node_x"]
    s0 = [x.copy(), v.copy(), x.copy(), data["C"].copy()]
    s1 = [a.copy() for a in s0]
    kt.g2p_affine(D, nodes, N, dN, nx, 0.01 * w, w2, w, 0.9, *s0)
    mv0 = np.zeros((nn, d))
    kt._affine(D, nodes, N, m, s0[1], s0[3], x, nx, 0, n, np.zeros(nn), mv0)
    mv1 = np.ones((nn, d))
    kt._g2p_affine_momentum_chunks(nc, D, nodes, N, dN, nx, 0.01 * w, w2, w, 0.9, *s1, m, mv1,
                                   *_bufs(nc, mv1))
    assert all(np.array_equal(a, b) for a, b in zip(s0, s1))
    assert _rel(mv1 - 1.0, mv0) < 1e-14
