"""The implicit particle-quadrature stiffness (kernels.transfer.assemble_stiffness): against a
numpy evaluation of sum_p V_p grad N_a A_p grad N_b, and the threaded pass (one chunk per
thread, per-chunk CSR copies) against the serial one."""
import numpy as np
import pytest

from fenicsmpm.kernels import transfer as kt
from fenicsmpm.bench import throughput


def _scene(shape):
    spec = dict(name="k", integrator="Newmark", scheme="Newmark", cells=24, per_cell=2, steps=1,
                warmup=0, dt_factor=5.0, shape=shape)
    sim = throughput.build_scene(throughput.scene_config(spec))
    sim.run(steps=1)                     # a deformed state: particles off their fill positions
    sim.locate_and_shape()
    return sim


def _assemble(sim, A4, constrained, monkeypatch=None, chunks=None):
    system = sim.integrator.system
    plan = system.plan(sim.nodes)
    data = np.zeros(len(system.indices))
    if chunks is not None:
        monkeypatch.setattr(kt, "n_chunks", lambda n: chunks)
    kt.assemble_stiffness(sim.grid.D, sim.nodes, sim.dN, sim.particles.V, A4, plan, system.nodeptr,
                          constrained, data)
    return data, plan


@pytest.mark.parametrize("shape", ["mpm", "cpgimp"])
def test_stiffness_matches_numpy_and_threads(shape, monkeypatch):
    sim = _scene(shape)
    n, d = len(sim.particles), sim.gdim
    rng = np.random.default_rng(1)
    A4 = rng.standard_normal((n, 3, 3, 3, 3))          # any tangent, not symmetric
    constrained = np.zeros(sim.grid.n_nodes * d, dtype=bool)
    constrained[::7] = True
    one, plan = _assemble(sim, A4, constrained)
    # numpy: K[p, a, b, r, c] = V_p sum_JL dN[p,a,J] A[p,r,J,c,L] dN[p,b,L], scattered by plan
    dN = sim.dN[:, :, :d]
    K = np.einsum("p,paj,prjcl,pbl->pabrc", sim.particles.V, dN, A4[:, :d, :d, :d, :d], dN)
    ref = np.zeros_like(one)
    nodes, deg = sim.nodes, np.diff(sim.integrator.system.nodeptr)
    for r in range(d):
        for c in range(d):
            i, j = nodes[:, :, None] * d + r, nodes[:, None, :] * d + c
            keep = ~constrained[i] & ~constrained[np.broadcast_to(j, i.shape[:2] + (j.shape[2],))]
            off = plan + r * deg[nodes][:, :, None] * d + c
            np.add.at(ref, off[keep], K[:, :, :, r, c][keep])
    scale = np.abs(ref).max()
    assert np.abs(one - ref).max() <= 1e-12 * scale
    for chunks in (2, 3):              # the threaded pass (chunks run on any thread count)
        many, _ = _assemble(sim, A4, constrained, monkeypatch, chunks=chunks)
        assert np.abs(many - one).max() <= 1e-13 * scale
