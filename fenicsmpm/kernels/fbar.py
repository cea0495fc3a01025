"""F-bar: the volume change of the incremental deformation gradient averaged over each cell
(issue 21, volumetric locking under isochoric plastic flow; de Souza Neto et al. 1996, for
MPM Coombs, Charlton, Cortis & Augarde 2018, eq 20 ff., and Zhao, Jiang & Liang for explicit
MPM). For the particles p of a cell c, with J_p = det dF_p and V_p their volumes,
    Jbar_c = sum_p V_p J_p / sum_p V_p,       dF_p <- (Jbar_c / J_p)^(1/n) dF_p,
n = 2 on the in-plane block in plane strain (dF_33 = 1 stays), 3 in 3D and on axisymmetric
grids (the hoop stretch is part of the volume change). The deviatoric part of every particle's
increment is kept; one volume change per cell instead of one constraint per particle."""
import numpy as np
from numba import njit, prange

from ..materials.piola import det3, inv3
from .threads import PRANGE, add_chunks1, chunk, n_chunks, particle_chunks, scratch
from .transfer import add_block, row_length, stiffness_stage


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


def fbar_stiffness(D, nodes, dN, V, A, dF0, cell, n_cells, n, plan, nodeptr, adj, constrained,
                   data):
    """The consistent (unsymmetric) tangent of the F-bar residual f_i = -sum_p V_p
    P(dFbar_p) grad N_ip, for every shape family, added to the CSR values `data` (pattern
    nodeptr/adj; skipping constrained rows and columns); dF0: the increments before
    averaging, A = dP/dF at dFbar. With J_q = det dF0_q, Jbar = sum_q V_q J_q / sum_q V_q
    over the particles q of p's cell, s_p = (Jbar / J_p)^(1/n) and h_qa = dF0_q^-T grad N_aq
    (so dJ_q = J_q sum_a du_a . h_qa),
        d dFbar_p = s_p [d dF0_p + (1/n) dF0_p (sum_b du_b . (Hbar_b - h_pb))],
        Hbar_b = sum_q V_q J_q h_qb / sum_q V_q J_q   (b: the nodes of any particle of the cell)
    (de Souza Neto et al. 1996 eq 24 in increment form). Particle p adds, for its nodes a,
        K_ab[r, c] += V_p s_p (grad N_ap,J A_p[r, J, c, L] grad N_bp,L - Q_ap,r h_pb,c)   (its nodes b)
        K_ab[r, c] += V_p s_p Q_ap,r Hbar_b,c / (sum_q V_q J_q)        (every node b of the cell)
    with Q_ap,r = (1/n) grad N_ap,J A_p[r, J, K, L] dF0_p[K, L], K, L < n (the in-plane block in
    plane strain); a particle whose J_p or Jbar is not positive is not averaged (fbar) and gets
    the plain block. With the standard family a cell's nodes are its particles' nodes; a wide
    family couples a node of p with the nodes of every particle of its cell, so the pattern
    needs one cell ring more (linear_system.stencil_rings). Returns -1, or the first local
    particle with a node pair outside the pattern (nothing is added for that pair).
    Threaded as assemble_stiffness is (kernels.threads): the cells, in order, are cut into
    one chunk per thread of about equal particle counts; chunk c >= 1 adds into its own copy
    of the CSR values over the rows its particles touch, summed into data afterwards."""
    nc = n_chunks(len(nodes))
    return _fbar_chunks(nc, D, nodes, dN, V, A, dF0, cell, n_cells, n, plan, nodeptr, adj,
                        constrained, data, scratch("fbar_stiffness", nc - 1, data))


@njit(parallel=PRANGE, cache=True)
def _fbar_chunks(nc, D, nodes, dN, V, A, dF0, cell, n_cells, n, plan, nodeptr, adj,
                 constrained, data, buf):
    d = len(D)
    nv = nodes.shape[1]
    npart = nodes.shape[0]
    first = np.zeros(n_cells + 1, dtype=np.int64)      # particles by cell (counting sort)
    for p in range(npart):
        first[cell[p] + 1] += 1
    most = 0
    for c in range(n_cells):
        most = max(most, first[c + 1])
        first[c + 1] += first[c]
    order = np.empty(npart, dtype=np.int64)
    fill = first[:n_cells].copy()
    for p in range(npart):
        order[fill[cell[p]]] = p
        fill[cell[p]] += 1
    J = np.empty(npart)
    h = np.empty((npart, nv, d))
    npc = particle_chunks(npart)
    for c in prange(npc):
        lo, hi = chunk(npart, npc, c)
        _inverse_gradients(dF0, dN, lo, hi, J, h)
    if nc == 1:
        return _fbar_cells(0, n_cells, first, order, most, J, h, nodes, dN, V, A, dF0, n,
                           plan, nodeptr, adj, constrained, data)
    bs2 = d * d
    rng = np.zeros((nc, 2), dtype=np.int64)
    bad = np.full(nc, -1, dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(npart, nc, c)                   # cells whose particles start in [lo, hi)
        c0 = np.searchsorted(first[:n_cells], lo)
        c1 = np.searchsorted(first[:n_cells], hi)
        if c == 0:
            bad[c] = _fbar_cells(c0, c1, first, order, most, J, h, nodes, dN, V, A, dF0, n,
                                 plan, nodeptr, adj, constrained, data)
        elif first[c1] > first[c0]:
            a, b = 1 << 62, -1
            for t in range(first[c0], first[c1]):
                for k in range(nv):
                    a = min(a, nodes[order[t], k])
                    b = max(b, nodes[order[t], k])
            rng[c, 0], rng[c, 1] = nodeptr[a] * bs2, nodeptr[b + 1] * bs2   # their CSR values
            buf[c - 1, rng[c, 0]:rng[c, 1]] = 0.0
            bad[c] = _fbar_cells(c0, c1, first, order, most, J, h, nodes, dN, V, A, dF0, n,
                                 plan, nodeptr, adj, constrained, buf[c - 1])
    add_chunks1(data, buf, rng)
    for c in range(nc):
        if bad[c] >= 0:
            return bad[c]
    return -1


@njit(cache=True)
def _inverse_gradients(dF0, dN, lo, hi, J, h):
    """J_q = det dF0_q and h_qa = dF0_q^-T grad N_aq for the particles lo..hi-1."""
    d = h.shape[2]
    inv = np.empty((3, 3))
    for q in range(lo, hi):
        J[q] = inv3(dF0[q], inv)
        for a in range(h.shape[1]):
            for k in range(d):
                v = 0.0
                for l in range(d):
                    v += inv[l, k] * dN[q, a, l]
                h[q, a, k] = v


@njit(cache=True)
def _fbar_cells(c0, c1, first, order, most, J, h, nodes, dN, V, A, dF0, n, plan, nodeptr,
                adj, constrained, data):
    """fbar_stiffness's terms of the particles of cells c0..c1-1 added to data; returns -1 or
    a particle of the first cell with a node pair outside the pattern. Per particle the plain
    block in two stages (transfer.stiffness_stage with V_p s_p); the cell term
    sum_p V_p s_p Q_ap,r Hbar_b,c / sum_q V_q J_q is gathered per cell node first (W[i, r] =
    the sum over the particles' nodes a at i of V_p s_p Q_ap,r) and added once per cell node
    pair (i, b): W[i] (x) Hbar_b / sum_q V_q J_q."""
    d = h.shape[2]
    nv = nodes.shape[1]
    U = np.empty(most * nv, dtype=np.int64)             # the nodes of a cell's particles
    Hb = np.empty((most * nv, d))
    W = np.empty((most * nv, d))
    G = np.empty((nv, d, d, d))
    block = np.empty((d, d))
    Q = np.empty((d, d))
    qa = np.empty((nv, d))
    bad = -1
    for c in range(c0, c1):
        if first[c + 1] == first[c]:
            continue
        nu = 0
        sv = 0.0
        sj = 0.0
        for t in range(first[c], first[c + 1]):
            q = order[t]
            w = V[q] * J[q]
            sv += V[q]
            sj += w
            for a in range(row_length(nodes, q)):       # the padding adds zeros
                g = nodes[q, a]
                u = 0
                while u < nu and U[u] != g:
                    u += 1
                if u == nu:
                    U[nu] = g
                    for k in range(d):
                        Hb[nu, k] = 0.0
                        W[nu, k] = 0.0
                    nu += 1
                for k in range(d):
                    Hb[u, k] += w * h[q, a, k]
        any_avg = False
        for t in range(first[c], first[c + 1]):
            p = order[t]
            avg = J[p] > 0.0 and sj > 0.0              # as fbar(): no averaging otherwise
            any_avg = any_avg or avg
            s = (sj / sv / J[p]) ** (1.0 / n) if avg else 1.0
            vs = V[p] * s
            for r in range(d):
                for Jx in range(d):
                    v = 0.0
                    for K in range(n):
                        for L in range(n):
                            v += A[p, r, Jx, K, L] * dF0[p, K, L]
                    Q[r, Jx] = v / n
            m = row_length(nodes, p)
            stiffness_stage(dN, A, p, m, vs, G)
            for a in range(m):
                for r in range(d):
                    v = 0.0
                    for Jx in range(d):
                        v += dN[p, a, Jx] * Q[r, Jx]
                    qa[a, r] = vs * v if avg else 0.0
                if avg:
                    u = 0
                    while U[u] != nodes[p, a]:
                        u += 1
                    for r in range(d):
                        W[u, r] += qa[a, r]
            for a in range(m):
                i = nodes[p, a]
                deg = nodeptr[i + 1] - nodeptr[i]
                for b in range(m):
                    for r in range(d):
                        for cc in range(d):
                            v = 0.0
                            for L in range(d):
                                v += G[a, r, cc, L] * dN[p, b, L]
                            block[r, cc] = v - qa[a, r] * h[p, b, cc]
                    add_block(data, plan[p, a, b], deg, i, nodes[p, b], d, constrained, block)
        if not any_avg:
            continue
        for x in range(nu):                             # the cell term, once per node pair
            i = U[x]
            lo, hi = nodeptr[i], nodeptr[i + 1]
            for u in range(nu):
                j = U[u]
                k = np.searchsorted(adj[lo:hi], j)
                if k >= hi - lo or adj[lo + k] != j:
                    if bad < 0:
                        bad = order[first[c]]
                    continue
                for r in range(d):
                    for cc in range(d):
                        block[r, cc] = W[x, r] * Hb[u, cc] / sj
                add_block(data, lo * d * d + k * d, hi - lo, i, j, d, constrained, block)
    return bad
