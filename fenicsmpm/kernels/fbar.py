"""F-bar: the volume change of the incremental deformation gradient averaged over each cell
(issue 21, volumetric locking under isochoric plastic flow; de Souza Neto et al. 1996, for
MPM Coombs, Charlton, Cortis & Augarde 2018, eq 20 ff., and Zhao, Jiang & Liang for explicit
MPM). For the particles p of a cell c, with J_p = det dF_p and V_p their volumes,
    Jbar_c = sum_p V_p J_p / sum_p V_p,       dF_p <- (Jbar_c / J_p)^(1/n) dF_p,
n = 2 on the in-plane block in plane strain (dF_33 = 1 stays), 3 in 3D and on axisymmetric
grids (the hoop stretch is part of the volume change). The deviatoric part of every particle's
increment is kept; one volume change per cell instead of one constraint per particle."""
import numpy as np
from numba import njit

from ..materials.piola import det3, inv3
from .transfer import add_block, stiffness_entry


@njit(cache=True)
def fbar(cell, V, dF, n_cells, n):
    """dF (particles, 3, 3) in place, as in the module docstring; cell: each particle's group
    (its local cell, or cell and body), < n_cells (all of a cell's particles are on the rank
    that owns it, so no communication)."""
    sv = np.zeros(n_cells)
    sj = np.zeros(n_cells)
    for p in range(len(cell)):
        c = cell[p]
        sv[c] += V[p]
        sj[c] += V[p] * det3(dF[p])
    for p in range(len(cell)):
        c = cell[p]
        J = det3(dF[p])
        Jb = sj[c] / sv[c]
        if J > 0.0 and Jb > 0.0:
            s = (Jb / J) ** (1.0 / n)
            for i in range(n):
                for j in range(n):
                    dF[p, i, j] *= s


@njit(cache=True)
def fbar_stiffness(D, nodes, dN, V, A, dF0, cell, n_cells, n, plan, nodeptr, constrained, data):
    """The consistent (unsymmetric) tangent of the F-bar residual f_i = -sum_p V_p
    P(dFbar_p) grad N_ip for the standard family (every particle of a cell has the cell's
    nodes in the same order), added to the CSR values `data` (skipping constrained rows and
    columns); dF0: the increments before averaging, A = dP/dF at dFbar. With
    J_q = det dF0_q, Jbar = sum_q V_q J_q / sum_q V_q, s_p = (Jbar / J_p)^(1/n) and
    h_qa = dF0_q^-T grad N_aq (so dJ_q = J_q sum_a du_a . h_qa),
        d dFbar_p = s_p [d dF0_p + (1/n) dF0_p (sum_b du_b . (Hbar_b - h_pb))],
        Hbar_b = sum_q V_q J_q h_qb / sum_q V_q J_q,
    (de Souza Neto et al. 1996 eq 24 in increment form) and the block of nodes (a, b)
        K_ab[r, c] = V_p grad N_ap,J A_p[r, J, K, L] d dFbar_p[K, L] / d u_b,c
    with K, L < n in the averaging term (the in-plane block in plane strain); a particle
    whose J_p or Jbar is not positive is not averaged (fbar) and gets the plain block."""
    d = len(D)
    nv = nodes.shape[1]
    sv = np.zeros(n_cells)
    sj = np.zeros(n_cells)
    Hb = np.zeros((n_cells, nv, d))
    inv = np.empty((3, 3))
    J = np.empty(nodes.shape[0])
    for q in range(nodes.shape[0]):
        c = cell[q]
        J[q] = inv3(dF0[q], inv)
        w = V[q] * J[q]
        sv[c] += V[q]
        sj[c] += w
        for a in range(nv):
            for k in range(d):
                h = 0.0
                for l in range(d):
                    h += inv[l, k] * dN[q, a, l]
                Hb[c, a, k] += w * h
    block = np.empty((d, d))
    Q = np.empty((d, d))
    hp = np.empty((nv, d))
    for p in range(nodes.shape[0]):
        c = cell[p]
        avg = J[p] > 0.0 and sj[c] > 0.0             # as fbar(): no averaging otherwise
        s = (sj[c] / sv[c] / J[p]) ** (1.0 / n) if avg else 1.0
        inv3(dF0[p], inv)
        for a in range(nv):
            for k in range(d):
                h = 0.0
                for l in range(d):
                    h += inv[l, k] * dN[p, a, l]
                hp[a, k] = h
        for r in range(d):
            for Jx in range(d):
                v = 0.0
                for K in range(n):
                    for L in range(n):
                        v += A[p, r, Jx, K, L] * dF0[p, K, L]
                Q[r, Jx] = v / n
        for a in range(nv):
            i = nodes[p, a]
            deg = nodeptr[i + 1] - nodeptr[i]
            for b in range(nv):
                for r in range(d):
                    qa = 0.0
                    for Jx in range(d):
                        qa += dN[p, a, Jx] * Q[r, Jx]
                    for cc in range(d):
                        v = stiffness_entry(dN, A, p, a, b, r, cc, d)
                        if avg:
                            v += qa * (Hb[c, b, cc] / sj[c] - hp[b, cc])
                        block[r, cc] = V[p] * s * v
                add_block(data, plan[p, a, b], deg, i, nodes[p, b], d, constrained, block)
