"""Fused particle passes (issue 16): stages that read the same particle data run in one loop.

elastic_step: the explicit stress update of a linear-elastic body in one pass per particle,
    dF_p = I + dt sum_i v_i (x) grad N_ip                       (kernels.transfer.particle_dF)
    sigma_p <- sigma_p + lam tr(eps) I + 2 mu eps + om sigma_p - sigma_p om
                                                  (materials.linear_elastic.jaumann_update)
    work_p += trapezoidal stress work, V_p <- det(dF) V_p, F_p <- dF F_p
                                                  (kernels.transfer.commit_particle)
instead of three passes (incremental_F, the material's stress, commit_step) that write and
re-read dF and the trial stress (2 x 9 doubles per particle). The arithmetic is the same
function calls in the same order: the result is bit-identical to the three passes
(tests/test_fused.py). Simulation.stress_update chooses it where it applies.

g2p_remap: G2P and the momentum P2G of MUSL/AVG's remap (seed 002 §2) in one particle pass,
    x_p += sum_i N_ip du_i, u_p likewise, v_p <- FLIP/PIC blend          (kernels.transfer.g2p)
    (m v)_i += N_ip m_p v_p  with the updated v_p and the same N_ip     (kernels.transfer.p2g_weighted)
instead of two passes that both read every particle's nodes and weights. The nodal sums use
the chunks of p2g_weighted (one per thread, kernels.threads) in the same order: the same bits
as the two passes. Explicit.step uses it for transfer="flip" with MUSL and AVG."""
import numpy as np
from numba import njit, prange

from ..materials.linear_elastic import jaumann_update
from ..materials.piola import det3
from .threads import PRANGE, add_chunks2, chunk, n_chunks, node_range, particle_chunks, scratch
from .transfer import (commit_particle, g2p_particle, inversion_flag, particle_dF,
                       scatter_weighted)


@njit(cache=True)
def _elastic(D, nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted, lo, hi):
    dF = np.empty((3, 3))
    s = np.empty((3, 3))
    eps = np.empty((3, 3))
    om = np.empty((3, 3))
    tmp = np.empty((3, 3))
    n_bad = 0
    for p in range(lo, hi):
        particle_dF(D, nodes, dN, w, scale, p, dF)
        J = det3(dF)
        flag = inversion_flag(J)
        if flag:
            inverted[p] = flag
            n_bad += 1
            continue
        jaumann_update(dF, sigma[p], lam, mu, s, eps, om)
        commit_particle(dF, s, J, p, F, V, sigma, work, tmp)
    return n_bad


@njit(parallel=PRANGE, cache=True)
def elastic_step(D, nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted):
    """dF from the nodal field w (times scale), the Jaumann linear-elastic stress and the commit
    of every particle in one pass (module docstring); a particle whose increment inverts it
    (flag 1) or is not finite (flag 2) keeps its state and is flagged in `inverted`, as
    kernels.transfer.commit_step does. Returns their count."""
    n = nodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _elastic(D, nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted,
                        np.int64(0), n)
    bad = np.zeros(nc, dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        bad[c] = _elastic(D, nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted, lo, hi)
    return bad.sum()


@njit(cache=True)
def _g2p_remap(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, lo, hi, mv_out):
    for p in range(lo, hi):
        g2p_particle(D, nodes, N, du, v_old, v_new, flip, x, v, u, p)
        scatter_weighted(D, nodes, N, mass, v, p, mv_out)


def g2p_remap(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, mv_out):
    """kernels.transfer.g2p, then mv_out_i += sum_p N_ip m_p v_p with the new velocities, in one
    pass (module docstring); mv_out is local (not yet summed over ranks)."""
    nc = n_chunks(len(nodes))
    _g2p_remap_chunks(nc, D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, mv_out,
                      scratch(0, nc - 1, mv_out))


@njit(parallel=PRANGE, cache=True)
def _g2p_remap_chunks(nc, D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, mv_out, buf):
    n = nodes.shape[0]
    if nc == 1:
        return _g2p_remap(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, np.int64(0), n,
                          mv_out)
    rng = np.zeros((nc, 2), dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        if c == 0:
            _g2p_remap(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, lo, hi, mv_out)
        else:
            a, b = node_range(nodes, lo, hi, rng[c])
            buf[c - 1, a:b] = 0.0
            _g2p_remap(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, lo, hi, buf[c - 1])
    add_chunks2(mv_out, buf, rng)
