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

In 2D (plane strain) the out-of-plane rows and columns of dF and F are those of I and the
shear stresses sigma_xz, sigma_yz are 0, so every product with them in the 3x3 formulas
adds an exact zero: _elastic_plane evaluates only the in-plane block and sigma_zz, in the
same order (the same bits on plane-strain states; the 1.04e6-particle throughput scene's
stress update: 100 -> 41 ms on one thread, `python -m fenicsmpm.bench fused`)."""
import numpy as np
from numba import njit, prange

from ..materials.linear_elastic import jaumann_update
from ..materials.piola import det3, work_increment
from .threads import PRANGE, chunk, particle_chunks
from .transfer import commit_particle, inversion_flag, particle_dF, row_length


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


@njit(cache=True)
def _elastic_plane(nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted, lo, hi):
    """_elastic for plane strain (module docstring): the terms of particle_dF, det3,
    jaumann_update, work_increment and commit_particle that are not products with an exact
    zero, in their order (the in-plane blocks, m = 2)."""
    n_bad = 0
    dF = np.eye(3)
    eps = np.empty((3, 3))
    om = np.empty((3, 3))
    s = np.empty((3, 3))
    for p in range(lo, hi):
        dF[0, 0], dF[0, 1], dF[1, 0], dF[1, 1] = 1.0, 0.0, 0.0, 1.0
        for a in range(row_length(nodes, p)):
            n = nodes[p, a]
            for i in range(2):
                wi = scale * w[n, i]
                for j in range(2):
                    dF[i, j] += wi * dN[p, a, j]
        J = dF[0, 0] * dF[1, 1] - dF[0, 1] * dF[1, 0]
        flag = inversion_flag(J)
        if flag:
            inverted[p] = flag
            n_bad += 1
            continue
        sp = sigma[p]
        tr = jaumann_update(dF, sp, lam, mu, s, eps, om, 2)
        s22 = sp[2, 2] + lam * tr
        V_new = J * V[p]
        work[p] += work_increment(dF, sp, s, V[p], V_new, 2)
        V[p] = V_new
        Fp = F[p]
        f00 = dF[0, 0] * Fp[0, 0] + dF[0, 1] * Fp[1, 0]
        f01 = dF[0, 0] * Fp[0, 1] + dF[0, 1] * Fp[1, 1]
        f10 = dF[1, 0] * Fp[0, 0] + dF[1, 1] * Fp[1, 0]
        f11 = dF[1, 0] * Fp[0, 1] + dF[1, 1] * Fp[1, 1]
        Fp[0, 0], Fp[0, 1], Fp[1, 0], Fp[1, 1] = f00, f01, f10, f11
        for i in range(2):
            for j in range(2):
                sp[i, j] = s[i, j]
        sp[2, 2] = s22
    return n_bad


def elastic_step(D, nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted):
    """dF from the nodal field w (times scale), the Jaumann linear-elastic stress and the commit
    of every particle in one pass (module docstring); a particle whose increment inverts it
    (flag 1) or is not finite (flag 2) keeps its state and is flagged in `inverted`, as
    kernels.transfer.commit_step does. Returns their count. 2D: plane strain (_elastic_plane).
    The two dimensions are two compiled passes, so a 2D run compiles only its own."""
    if len(D) == 2:
        return _plane_step(nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted)
    return _step_3d(D, nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted)


@njit(parallel=PRANGE, cache=True)
def _plane_step(nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted):
    n = nodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _elastic_plane(nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted,
                              np.int64(0), n)
    bad = np.zeros(nc, dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        bad[c] = _elastic_plane(nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted,
                                lo, hi)
    return bad.sum()


@njit(parallel=PRANGE, cache=True)
def _step_3d(D, nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted):
    n = nodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _elastic(D, nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted,
                        np.int64(0), n)
    bad = np.zeros(nc, dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        bad[c] = _elastic(D, nodes, dN, w, scale, lam, mu, F, V, sigma, work, inverted,
                          lo, hi)
    return bad.sum()
