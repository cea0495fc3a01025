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
(tests/test_fused.py). Simulation.stress_update chooses it where it applies."""
import numpy as np
from numba import njit, prange

from ..materials.linear_elastic import jaumann_update
from ..materials.piola import det3
from .threads import PRANGE, chunk, particle_chunks
from .transfer import commit_particle, inversion_flag, particle_dF


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
