"""Numba kernels mapping between particles and grid nodes (P2G, G2P) and assembling the
particle-quadrature stiffness into a CSR array.

Shape data are padded arrays: nodes[p, a] (node index), N[p, a] (weight) and dN[p, a, :]
(gradient). A wide family's rows differ in length: each lists its nodes once, then repeats
the last one with N = dN = 0 (pad_row), and the passes stop at the padding (row_length), so
a particle whose box touches 4 of the 9 columns costs 4. `D` is a tuple of length gdim: its
length is a compile-time constant for numba, so the short loops over dimensions are
unrolled (about 2x faster than a runtime d).
Every grid integral is a particle sum with weight V_p (DESIGN.md):
  m_i = sum_p N_ip m_p,   (m v)_i = sum_p N_ip m_p v_p,
  f_i = sum_p N_ip m_p g - sum_p V_p sigma_p . grad N_ip      (seed 000 eq 2.22, no D: errata)

The particle passes run on numba's threads (kernels.threads): each public kernel cuts the
particles into chunks and runs a serial loop over a range [lo, hi) (the `_name` function
beside it) per chunk; P2G kernels give the chunks their own nodal arrays, added afterwards.
"""
import numpy as np
from numba import njit, prange

from ..materials.piola import det3, work_increment
from .threads import (PRANGE, add_chunks1, add_chunks2, chunk, n_chunks, node_range,
                      particle_chunks, scratch)


# ---------------------------------------------------------------------- padded rows
@njit(cache=True)
def row_length(nodes, p):
    """The columns of particle p's row before its padding. A row lists its nodes once each;
    a wide family pads it by repeating its last node with N = dN = 0 (pad_row), so the first
    column equal to the one before starts the padding. A pass over the row may stop there:
    the padding adds exact zeros (a row padded otherwise is just read to its end)."""
    nv = nodes.shape[1]
    for a in range(1, nv):
        if nodes[p, a] == nodes[p, a - 1]:
            return a
    return nv


@njit(cache=True)
def pad_row(d, p, cnt, fallback, nodes_out, N_out, dN_out):
    """Pad particle p's row after its cnt nodes (row_length): columns cnt.. repeat the last
    node (`fallback`, a valid node, when cnt = 0) with N = dN = 0."""
    pad = nodes_out[p, cnt - 1] if 0 < cnt <= nodes_out.shape[1] else fallback
    for a in range(cnt, nodes_out.shape[1]):
        nodes_out[p, a] = pad
        N_out[p, a] = 0.0
        for k in range(d):
            dN_out[p, a, k] = 0.0


# ---------------------------------------------------------------------- P2G
@njit(cache=True)
def _mass(nodes, N, mass, lo, hi, m_out):
    for p in range(lo, hi):
        for a in range(row_length(nodes, p)):
            m_out[nodes[p, a]] += N[p, a] * mass[p]


def p2g_mass(nodes, N, mass, m_out):
    """m_i += sum_p N_ip m_p."""
    nc = n_chunks(len(nodes))
    _p2g_mass_chunks(nc, nodes, N, mass, m_out, scratch(0, nc - 1, m_out))


@njit(parallel=PRANGE, cache=True)
def _p2g_mass_chunks(nc, nodes, N, mass, m_out, mb):
    n = nodes.shape[0]
    if nc == 1:
        return _mass(nodes, N, mass, np.int64(0), n, m_out)
    rng = np.zeros((nc, 2), dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        if c == 0:
            _mass(nodes, N, mass, lo, hi, m_out)
        else:
            a, b = node_range(nodes, lo, hi, rng[c])
            mb[c - 1, a:b] = 0.0
            _mass(nodes, N, mass, lo, hi, mb[c - 1])
    add_chunks1(m_out, mb, rng)


@njit(cache=True)
def _mass_momentum(D, nodes, N, mass, v, lo, hi, m_out, mv_out):
    d = len(D)
    for p in range(lo, hi):
        mp = mass[p]
        for a in range(row_length(nodes, p)):
            w = N[p, a] * mp
            i = nodes[p, a]
            m_out[i] += w
            for k in range(d):
                mv_out[i, k] += w * v[p, k]


def p2g_mass_momentum(D, nodes, N, mass, v, m_out, mv_out):
    """m_i += sum_p N_ip m_p and (m v)_i += sum_p N_ip m_p v_p in one pass."""
    nc = n_chunks(len(nodes))
    _p2g_mass_momentum_chunks(nc, D, nodes, N, mass, v, m_out, mv_out, scratch(0, nc - 1, m_out),
                              scratch(1, nc - 1, mv_out))


@njit(parallel=PRANGE, cache=True)
def _p2g_mass_momentum_chunks(nc, D, nodes, N, mass, v, m_out, mv_out, mb, mvb):
    n = nodes.shape[0]
    if nc == 1:
        return _mass_momentum(D, nodes, N, mass, v, np.int64(0), n, m_out, mv_out)
    rng = np.zeros((nc, 2), dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        if c == 0:
            _mass_momentum(D, nodes, N, mass, v, lo, hi, m_out, mv_out)
        else:
            a, b = node_range(nodes, lo, hi, rng[c])
            mb[c - 1, a:b] = 0.0
            mvb[c - 1, a:b] = 0.0
            _mass_momentum(D, nodes, N, mass, v, lo, hi, mb[c - 1], mvb[c - 1])
    add_chunks1(m_out, mb, rng)
    add_chunks2(mv_out, mvb, rng)


@njit(cache=True)
def _weighted(D, nodes, N, mass, q, lo, hi, out):
    d = len(D)
    for p in range(lo, hi):
        for a in range(row_length(nodes, p)):
            w = N[p, a] * mass[p]
            i = nodes[p, a]
            for k in range(d):
                out[i, k] += w * q[p, k]


def p2g_weighted(D, nodes, N, mass, q, out):
    """out_i += sum_p N_ip m_p q_p (momentum for q = v, mass-weighted acceleration for q = a)."""
    nc = n_chunks(len(nodes))
    _p2g_weighted_chunks(nc, D, nodes, N, mass, q, out, scratch(0, nc - 1, out))


@njit(parallel=PRANGE, cache=True)
def _p2g_weighted_chunks(nc, D, nodes, N, mass, q, out, buf):
    n = nodes.shape[0]
    if nc == 1:
        return _weighted(D, nodes, N, mass, q, np.int64(0), n, out)
    rng = np.zeros((nc, 2), dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        if c == 0:
            _weighted(D, nodes, N, mass, q, lo, hi, out)
        else:
            a, b = node_range(nodes, lo, hi, rng[c])
            buf[c - 1, a:b] = 0.0
            _weighted(D, nodes, N, mass, q, lo, hi, buf[c - 1])
    add_chunks2(out, buf, rng)


@njit(cache=True)
def _force(D, nodes, N, dN, mass, V, stress, g, active, lo, hi, out):
    restrict = active.shape[0] > 0
    s3 = np.empty(len(D))
    if len(D) == 3:
        for p in range(lo, hi):
            if restrict and not row_active(nodes, active, 0, p):
                restrict_row(D, nodes, N, dN, active, 0, p, s3)
            for a in range(row_length(nodes, p)):
                i = nodes[p, a]
                for k in range(3):
                    s = 0.0
                    for l in range(3):
                        s += stress[p, k, l] * dN[p, a, l]
                    out[i, k] += N[p, a] * mass[p] * g[k] - V[p] * s
        return
    g0, g1 = g[0], g[1]
    for p in range(lo, hi):        # 2D: the in-plane stress in scalars (1.5x, the same sums)
        if restrict and not row_active(nodes, active, 0, p):
            restrict_row(D, nodes, N, dN, active, 0, p, s3)
        s00, s01, s10, s11 = stress[p, 0, 0], stress[p, 0, 1], stress[p, 1, 0], stress[p, 1, 1]
        mp, vp = mass[p], V[p]
        for a in range(row_length(nodes, p)):
            i = nodes[p, a]
            w = N[p, a] * mp
            b0, b1 = dN[p, a, 0], dN[p, a, 1]
            out[i, 0] += w * g0 - vp * (s00 * b0 + s01 * b1)
            out[i, 1] += w * g1 - vp * (s10 * b0 + s11 * b1)


def p2g_force(D, nodes, N, dN, mass, V, stress, g, out, active=None):
    """out_i += sum_p (N_ip m_p g - V_p stress_p . grad N_ip).

    `stress` is (n, 3, 3); only the in-plane block is used. With the first Piola stress of
    the step and start-of-step gradients and volumes this is the updated-Lagrangian force.
    active: None, or the (n_nodes, 1) active-node mask whose gradient restriction
    (restrict_gradients) this pass applies to dN first, particle by particle (one read of
    the rows less than a separate pass)."""
    nc = n_chunks(len(nodes))
    active = np.zeros((0, 1), dtype=np.bool_) if active is None else active
    _p2g_force_chunks(nc, D, nodes, N, dN, mass, V, stress, g, active, out,
                      scratch(0, nc - 1, out))


@njit(parallel=PRANGE, cache=True)
def _p2g_force_chunks(nc, D, nodes, N, dN, mass, V, stress, g, active, out, buf):
    n = nodes.shape[0]
    if nc == 1:
        return _force(D, nodes, N, dN, mass, V, stress, g, active, np.int64(0), n, out)
    rng = np.zeros((nc, 2), dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        if c == 0:
            _force(D, nodes, N, dN, mass, V, stress, g, active, lo, hi, out)
        else:
            a, b = node_range(nodes, lo, hi, rng[c])
            buf[c - 1, a:b] = 0.0
            _force(D, nodes, N, dN, mass, V, stress, g, active, lo, hi, buf[c - 1])
    add_chunks2(out, buf, rng)


@njit(cache=True, inline="always")
def _affine_momentum(D, nodes, N, mass, v, C, xp, node_x, p, mv_out):
    """(m v)_i += N_ip m_p (v_p + C_p (x_i - xp)) over particle p's nodes (xp: its position
    at the start of the step)."""
    d = len(D)
    if d == 2:                     # the 2D sums in scalars, in the same order
        v0, v1, x0, x1 = v[p, 0], v[p, 1], xp[0], xp[1]
        c00, c01, c10, c11 = C[p, 0, 0], C[p, 0, 1], C[p, 1, 0], C[p, 1, 1]
        for a in range(row_length(nodes, p)):
            w = N[p, a] * mass[p]
            i = nodes[p, a]
            r0, r1 = node_x[i, 0] - x0, node_x[i, 1] - x1
            mv_out[i, 0] += w * (v0 + c00 * r0 + c01 * r1)
            mv_out[i, 1] += w * (v1 + c10 * r0 + c11 * r1)
        return
    for a in range(row_length(nodes, p)):
        w = N[p, a] * mass[p]
        i = nodes[p, a]
        for k in range(d):
            s = v[p, k]
            for l in range(d):
                s += C[p, k, l] * (node_x[i, l] - xp[l])
            mv_out[i, k] += w * s


@njit(cache=True)
def _affine(D, nodes, N, mass, v, C, x, node_x, lo, hi, m_out, mv_out):
    for p in range(lo, hi):
        for a in range(row_length(nodes, p)):
            m_out[nodes[p, a]] += N[p, a] * mass[p]
        _affine_momentum(D, nodes, N, mass, v, C, x[p], node_x, p, mv_out)


def p2g_affine(D, nodes, N, mass, v, C, x, node_x, m_out, mv_out):
    """APIC momentum (Jiang et al. 2015, eq 10 with C_p in place of B_p D_p^-1):
        (m v)_i += sum_p N_ip m_p (v_p + C_p (x_i - x_p)),   m_i += sum_p N_ip m_p.
    With C_p the velocity gradient of the last G2P (g2p_affine) an affine velocity field is
    carried to the nodes exactly (partition of unity and linear reproduction)."""
    nc = n_chunks(len(nodes))
    _p2g_affine_chunks(nc, D, nodes, N, mass, v, C, x, node_x, m_out, mv_out,
                       scratch(0, nc - 1, m_out), scratch(1, nc - 1, mv_out))


@njit(parallel=PRANGE, cache=True)
def _p2g_affine_chunks(nc, D, nodes, N, mass, v, C, x, node_x, m_out, mv_out, mb,
                       mvb):
    n = nodes.shape[0]
    if nc == 1:
        return _affine(D, nodes, N, mass, v, C, x, node_x, np.int64(0), n, m_out, mv_out)
    rng = np.zeros((nc, 2), dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        if c == 0:
            _affine(D, nodes, N, mass, v, C, x, node_x, lo, hi, m_out, mv_out)
        else:
            a, b = node_range(nodes, lo, hi, rng[c])
            mb[c - 1, a:b] = 0.0
            mvb[c - 1, a:b] = 0.0
            _affine(D, nodes, N, mass, v, C, x, node_x, lo, hi, mb[c - 1], mvb[c - 1])
    add_chunks1(m_out, mb, rng)
    add_chunks2(mv_out, mvb, rng)


# ---------------------------------------------------------------------- per-particle passes
@njit(cache=True)
def row_active(nodes, active, f, p):
    """Whether every node of particle p's row is active in column f."""
    for a in range(row_length(nodes, p)):
        if not active[nodes[p, a], f]:
            return False
    return True


@njit(cache=True)
def restrict_row(D, nodes, N, dN, active, f, p, s):
    """Particle p's gradients restricted to the nodes active in column f (restrict_gradients;
    callers skip the rows whose nodes are all active, row_active); s: scratch of length d."""
    d = len(D)
    m = row_length(nodes, p)
    for k in range(d):
        s[k] = 0.0
    for a in range(m):
        if active[nodes[p, a], f]:
            for k in range(d):
                s[k] += dN[p, a, k]
    for a in range(m):
        if active[nodes[p, a], f]:
            for k in range(d):
                dN[p, a, k] -= N[p, a] * s[k]
        else:
            for k in range(d):
                dN[p, a, k] = 0.0


@njit(cache=True)
def _restrict(D, nodes, N, dN, active, field, lo, hi):
    s = np.empty(len(D))
    for p in range(lo, hi):
        if not row_active(nodes, active, field[p], p):
            restrict_row(D, nodes, N, dN, active, field[p], p, s)


@njit(parallel=PRANGE, cache=True)
def restrict_gradients(D, nodes, N, dN, active, field):
    """Gradients restricted to active nodes, keeping sum_i G_ip = 0 exactly:
        G_ip = grad N_ip - N_ip sum_{a active} grad N_ap  (active i),   G_ip = 0 (inactive i).
    Inactive nodes carry no mass, so N_ip ~ 0 there while grad N_ip is not: without this, a
    particle on a cell face (or next to an empty cell) sees a zero velocity at such a node and
    gets a spurious velocity gradient. G = grad N whenever all of a particle's nodes are
    active. `active` is (n_nodes, n_fields): particle p sees column field[p] (one column for
    single-field MPM; one per body in multi-velocity contact). Applied in place to dN."""
    n = nodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _restrict(D, nodes, N, dN, active, field, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _restrict(D, nodes, N, dN, active, field, lo, hi)


@njit(cache=True)
def _flip_blend(D, nodes, N, old, new, flip, q, lo, hi):
    d = len(D)
    for p in range(lo, hi):
        m = row_length(nodes, p)
        for k in range(d):
            dq = 0.0
            qn = 0.0
            for a in range(m):
                i = nodes[p, a]
                dq += N[p, a] * (new[i, k] - old[i, k])
                qn += N[p, a] * new[i, k]
            q[p, k] = flip * (q[p, k] + dq) + (1.0 - flip) * qn


@njit(parallel=PRANGE, cache=True)
def flip_blend(D, nodes, N, old, new, flip, q):
    """q_p = flip (q_p + sum N (new - old)_i) + (1 - flip) sum N new_i (FLIP/PIC blend of a
    nodal field's change; the acceleration update of implicit runs)."""
    n = nodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _flip_blend(D, nodes, N, old, new, flip, q, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _flip_blend(D, nodes, N, old, new, flip, q, lo, hi)


@njit(cache=True, inline="always")
def particle_dF(D, nodes, dN, w, scale, p, out):
    """out = I + scale * sum_a w_(nodes[p, a]) (x) grad N_a(x_p) for particle p (3x3 out; plane
    strain in 2D). Inlined into its passes; in 2D the in-plane block is summed in scalars
    (the same sums)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = 1.0 if i == j else 0.0
    if len(D) == 3:
        for a in range(row_length(nodes, p)):
            n = nodes[p, a]
            for i in range(3):
                wi = scale * w[n, i]
                for j in range(3):
                    out[i, j] += wi * dN[p, a, j]
        return
    f00, f01, f10, f11 = 1.0, 0.0, 0.0, 1.0
    for a in range(row_length(nodes, p)):
        n = nodes[p, a]
        b0, b1 = dN[p, a, 0], dN[p, a, 1]
        w0, w1 = scale * w[n, 0], scale * w[n, 1]
        f00 += w0 * b0
        f01 += w0 * b1
        f10 += w1 * b0
        f11 += w1 * b1
    out[0, 0], out[0, 1], out[1, 0], out[1, 1] = f00, f01, f10, f11


@njit(cache=True)
def _incremental_F(D, nodes, dN, w, scale, lo, hi, dF_out):
    for p in range(lo, hi):
        particle_dF(D, nodes, dN, w, scale, p, dF_out[p])


@njit(parallel=PRANGE, cache=True)
def incremental_F(D, nodes, dN, w, scale, dF_out):
    """dF_p = I + scale * sum_i w_i (x) grad N_ip, as 3x3 (plane strain in 2D).

    For w = grid velocity and scale = dt this is I + dt L (explicit); for w = the step's
    displacement increment and scale = 1 it is the incremental deformation gradient."""
    n = nodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _incremental_F(D, nodes, dN, w, scale, np.int64(0), n, dF_out)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _incremental_F(D, nodes, dN, w, scale, lo, hi, dF_out)


@njit(cache=True, inline="always")
def g2p_particle(D, nodes, N, du, v_old, v_new, flip, x, v, u, p):
    """Particle p's update of g2p (2D or 3D). One sweep over the row with the components in
    scalars: about 2x faster than a sweep per component on the throughput scene, the same
    sums."""
    if len(D) == 3:
        _g2p_particle3(nodes, N, du, v_old, v_new, flip, x, v, u, p)
        return
    dx0 = dx1 = dv0 = dv1 = vp0 = vp1 = 0.0
    for a in range(row_length(nodes, p)):
        i = nodes[p, a]
        w = N[p, a]
        n0 = v_new[i, 0]
        n1 = v_new[i, 1]
        dx0 += w * du[i, 0]
        dx1 += w * du[i, 1]
        vp0 += w * n0
        vp1 += w * n1
        dv0 += w * (n0 - v_old[i, 0])
        dv1 += w * (n1 - v_old[i, 1])
    x[p, 0] += dx0
    x[p, 1] += dx1
    u[p, 0] += dx0
    u[p, 1] += dx1
    v[p, 0] = flip * (v[p, 0] + dv0) + (1.0 - flip) * vp0
    v[p, 1] = flip * (v[p, 1] + dv1) + (1.0 - flip) * vp1


@njit(cache=True)
def _g2p_particle3(nodes, N, du, v_old, v_new, flip, x, v, u, p):
    """g2p_particle in 3D."""
    dx0 = dx1 = dx2 = dv0 = dv1 = dv2 = vp0 = vp1 = vp2 = 0.0
    for a in range(row_length(nodes, p)):
        i = nodes[p, a]
        w = N[p, a]
        n0 = v_new[i, 0]
        n1 = v_new[i, 1]
        n2 = v_new[i, 2]
        dx0 += w * du[i, 0]
        dx1 += w * du[i, 1]
        dx2 += w * du[i, 2]
        vp0 += w * n0
        vp1 += w * n1
        vp2 += w * n2
        dv0 += w * (n0 - v_old[i, 0])
        dv1 += w * (n1 - v_old[i, 1])
        dv2 += w * (n2 - v_old[i, 2])
    x[p, 0] += dx0
    x[p, 1] += dx1
    x[p, 2] += dx2
    u[p, 0] += dx0
    u[p, 1] += dx1
    u[p, 2] += dx2
    v[p, 0] = flip * (v[p, 0] + dv0) + (1.0 - flip) * vp0
    v[p, 1] = flip * (v[p, 1] + dv1) + (1.0 - flip) * vp1
    v[p, 2] = flip * (v[p, 2] + dv2) + (1.0 - flip) * vp2


@njit(cache=True)
def _g2p(D, nodes, N, du, v_old, v_new, flip, x, v, u, lo, hi):
    for p in range(lo, hi):
        g2p_particle(D, nodes, N, du, v_old, v_new, flip, x, v, u, p)


@njit(parallel=PRANGE, cache=True)
def g2p(D, nodes, N, du, v_old, v_new, flip, x, v, u):
    """Particle update from grid results (seed 002 §2; FLIP/PIC blend).

    x_p += sum N du_i; u_p likewise;
    v_p = flip (v_p + sum N (v_new - v_old)_i) + (1 - flip) sum N v_new_i."""
    n = nodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _g2p(D, nodes, N, du, v_old, v_new, flip, x, v, u, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _g2p(D, nodes, N, du, v_old, v_new, flip, x, v, u, lo, hi)


@njit(cache=True)
def _g2p_momentum(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, lo, hi, mv_out):
    d = len(D)
    for p in range(lo, hi):
        g2p_particle(D, nodes, N, du, v_old, v_new, flip, x, v, u, p)
        for a in range(row_length(nodes, p)):
            w = N[p, a] * mass[p]
            i = nodes[p, a]
            for k in range(d):
                mv_out[i, k] += w * v[p, k]


def g2p_momentum(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, mv_out):
    """g2p, and in the same particle pass the momentum of the updated velocities with the
    step's weights, (m v)_i += sum_p N_ip m_p v_p (MUSL's second P2G, seed 002 §2): one read
    of the shape data instead of two. mv_out is local (not yet summed over ranks)."""
    nc = n_chunks(len(nodes))
    _g2p_momentum_chunks(nc, D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, mv_out,
                         scratch(0, nc - 1, mv_out))


@njit(parallel=PRANGE, cache=True)
def _g2p_momentum_chunks(nc, D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, mv_out, buf):
    n = nodes.shape[0]
    if nc == 1:
        return _g2p_momentum(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, np.int64(0),
                             n, mv_out)
    rng = np.zeros((nc, 2), dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        if c == 0:
            _g2p_momentum(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, lo, hi, mv_out)
        else:
            a, b = node_range(nodes, lo, hi, rng[c])
            buf[c - 1, a:b] = 0.0
            _g2p_momentum(D, nodes, N, du, v_old, v_new, flip, x, v, u, mass, lo, hi,
                          buf[c - 1])
    add_chunks2(mv_out, buf, rng)


@njit(cache=True, inline="always")
def _affine_matrix(D, nodes, N, dN, node_x, v_new, x, p, C):
    """C_p = B_p D_p^-1 of g2p_affine for particle p (closed-form inverse, no allocation),
    or sum v_i (x) grad N_ip where D_p is singular."""
    d = len(D)
    b00 = b01 = b02 = b10 = b11 = b12 = b20 = b21 = b22 = 0.0
    d00 = d01 = d02 = d11 = d12 = d22 = 0.0
    m = row_length(nodes, p)
    for a in range(m):
        i = nodes[p, a]
        w = N[p, a]
        r0 = node_x[i, 0] - x[p, 0]
        r1 = node_x[i, 1] - x[p, 1]
        w0 = w * v_new[i, 0]
        w1 = w * v_new[i, 1]
        b00 += w0 * r0
        b01 += w0 * r1
        b10 += w1 * r0
        b11 += w1 * r1
        d00 += w * r0 * r0
        d01 += w * r0 * r1
        d11 += w * r1 * r1
        if d == 3:
            r2 = node_x[i, 2] - x[p, 2]
            w2 = w * v_new[i, 2]
            b02 += w0 * r2
            b12 += w1 * r2
            b20 += w2 * r0
            b21 += w2 * r1
            b22 += w2 * r2
            d02 += w * r0 * r2
            d12 += w * r1 * r2
            d22 += w * r2 * r2
    if d == 2:
        det = d00 * d11 - d01 * d01
        ok = abs(det) > 1e-8 * (d00 + d11) ** 2
        if ok:
            i00, i01, i11 = d11 / det, -d01 / det, d00 / det
            C[p, 0, 0] = b00 * i00 + b01 * i01
            C[p, 0, 1] = b00 * i01 + b01 * i11
            C[p, 1, 0] = b10 * i00 + b11 * i01
            C[p, 1, 1] = b10 * i01 + b11 * i11
    else:
        c00 = d11 * d22 - d12 * d12             # cofactors of the symmetric D_p
        c01 = d02 * d12 - d01 * d22
        c02 = d01 * d12 - d02 * d11
        c11 = d00 * d22 - d02 * d02
        c12 = d01 * d02 - d00 * d12
        c22 = d00 * d11 - d01 * d01
        det = d00 * c00 + d01 * c01 + d02 * c02
        ok = abs(det) > 1e-8 * (d00 + d22) ** 3
        if ok:
            i00, i01, i02 = c00 / det, c01 / det, c02 / det
            i11, i12, i22 = c11 / det, c12 / det, c22 / det
            C[p, 0, 0] = b00 * i00 + b01 * i01 + b02 * i02
            C[p, 0, 1] = b00 * i01 + b01 * i11 + b02 * i12
            C[p, 0, 2] = b00 * i02 + b01 * i12 + b02 * i22
            C[p, 1, 0] = b10 * i00 + b11 * i01 + b12 * i02
            C[p, 1, 1] = b10 * i01 + b11 * i11 + b12 * i12
            C[p, 1, 2] = b10 * i02 + b11 * i12 + b12 * i22
            C[p, 2, 0] = b20 * i00 + b21 * i01 + b22 * i02
            C[p, 2, 1] = b20 * i01 + b21 * i11 + b22 * i12
            C[p, 2, 2] = b20 * i02 + b21 * i12 + b22 * i22
    if not ok:
        for k in range(d):
            for l in range(d):
                c = 0.0
                for a in range(m):
                    c += v_new[nodes[p, a], k] * dN[p, a, l]
                C[p, k, l] = c


@njit(cache=True)
def _g2p_affine(D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u, C, lo, hi):
    for p in range(lo, hi):
        _affine_matrix(D, nodes, N, dN, node_x, v_new, x, p, C)
        g2p_particle(D, nodes, N, du, v_old, v_new, flip, x, v, u, p)


@njit(parallel=PRANGE, cache=True)
def g2p_affine(D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u, C):
    """Affine particle update. C_p as in APIC (Jiang et al. 2015, eqs 8-9),
        C_p = B_p D_p^-1,  B_p = sum_i N_ip v_i (x_i - x_p)^T,  D_p = sum_i N_ip (x_i - x_p)(x_i - x_p)^T,
    with v_i = v_new and x_p the start-of-step position; where D_p is singular (a particle on a
    node of a multilinear cell) C_p = sum v_i (x) grad N_ip. The velocity
        v_p = flip (v_p + sum N (v_new - v_old)_i) + (1 - flip) sum N v_new_i:
    flip = 0 is APIC (angular momentum conserved exactly), flip > 0 the affine FLIP of Fei et
    al. 2021 (AFLIP: FLIP's velocity increment with APIC's C_p). Then x_p += sum N du_i."""
    n = nodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _g2p_affine(D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u, C,
                           np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _g2p_affine(D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u, C, lo, hi)


@njit(cache=True)
def _g2p_affine_momentum(D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u, C, mass,
                         lo, hi, mv_out):
    d = len(D)
    xs = np.empty(d)
    for p in range(lo, hi):
        _affine_matrix(D, nodes, N, dN, node_x, v_new, x, p, C)
        for k in range(d):
            xs[k] = x[p, k]
        g2p_particle(D, nodes, N, du, v_old, v_new, flip, x, v, u, p)
        _affine_momentum(D, nodes, N, mass, v, C, xs, node_x, p, mv_out)


def g2p_affine_momentum(D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u, C, mass,
                        mv_out):
    """g2p_affine, and in the same particle pass the affine momentum of the updated particles
    with the step's weights and start positions (p2g_affine without mass: MUSL's second P2G).
    mv_out is local (not yet summed over ranks)."""
    nc = n_chunks(len(nodes))
    _g2p_affine_momentum_chunks(nc, D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u,
                                C, mass, mv_out, scratch(0, nc - 1, mv_out))


@njit(parallel=PRANGE, cache=True)
def _g2p_affine_momentum_chunks(nc, D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u,
                                C, mass, mv_out, buf):
    n = nodes.shape[0]
    if nc == 1:
        return _g2p_affine_momentum(D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u,
                                    C, mass, np.int64(0), n, mv_out)
    rng = np.zeros((nc, 2), dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        if c == 0:
            _g2p_affine_momentum(D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u, C,
                                 mass, lo, hi, mv_out)
        else:
            a, b = node_range(nodes, lo, hi, rng[c])
            buf[c - 1, a:b] = 0.0
            _g2p_affine_momentum(D, nodes, N, dN, node_x, du, v_old, v_new, flip, x, v, u, C,
                                 mass, lo, hi, buf[c - 1])
    add_chunks2(mv_out, buf, rng)


@njit(cache=True)
def inversion_flag(J):
    """0 for an admissible volume ratio J = det dF, 1 where the increment inverts the particle
    (J <= 0), 2 where it is not finite."""
    if J > 0.0 and np.isfinite(J):
        return 0
    return 1 if np.isfinite(J) else 2


@njit(cache=True, inline="always")
def commit_particle(dF, sigma_new, J, p, F, V, sigma, work, tmp):
    """Accept particle p's step (dF, its stress sigma_new, J = det dF > 0): work += the
    trapezoidal stress work, V <- J V, F <- dF F, sigma <- sigma_new (tmp: 3x3 scratch)."""
    V_new = J * V[p]
    work[p] += work_increment(dF, sigma[p], sigma_new, V[p], V_new)
    V[p] = V_new
    for i in range(3):
        for j in range(3):
            tmp[i, j] = dF[i, 0] * F[p, 0, j] + dF[i, 1] * F[p, 1, j] + dF[i, 2] * F[p, 2, j]
    for i in range(3):
        for j in range(3):
            F[p, i, j] = tmp[i, j]
            sigma[p, i, j] = sigma_new[i, j]


@njit(cache=True)
def _commit(dF, F, V, sigma, sigma_new, work, inverted, lo, hi):
    tmp = np.empty((3, 3))
    n_bad = 0
    for p in range(lo, hi):
        J = det3(dF[p])
        flag = inversion_flag(J)
        if flag:
            inverted[p] = flag
            n_bad += 1
            continue
        commit_particle(dF[p], sigma_new[p], J, p, F, V, sigma, work, tmp)
    return n_bad


@njit(parallel=PRANGE, cache=True)
def commit_step(dF, F, V, sigma, sigma_new, work, inverted):
    """Accept a step for every particle, in one pass: work += trapezoidal stress work,
    V <- det(dF) V, F <- dF F, sigma <- sigma_new. A particle whose increment inverts it
    (det dF <= 0: flag 1) or whose increment is not finite (flag 2) keeps its state and is
    flagged in `inverted` for the guards, so no NaN stress of an inverted material point is
    ever committed. Returns their count."""
    n = dF.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _commit(dF, F, V, sigma, sigma_new, work, inverted, np.int64(0), n)
    bad = np.zeros(nc, dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        bad[c] = _commit(dF, F, V, sigma, sigma_new, work, inverted, lo, hi)
    return bad.sum()


# ---------------------------------------------------------------------- CSR assembly
@njit(cache=True)
def scalar_csr(nodeptr, adj, bs):
    """Scalar CSR (indptr, indices) of a blocked pattern given node adjacency (nodeptr, adj).

    Row i*bs+a lists columns j*bs+b for j in adj(i) (sorted) and b < bs."""
    n = nodeptr.shape[0] - 1
    indptr = np.zeros(n * bs + 1, dtype=np.int32)
    for i in range(n):
        deg = nodeptr[i + 1] - nodeptr[i]
        for a in range(bs):
            indptr[i * bs + a + 1] = indptr[i * bs + a] + deg * bs
    indices = np.empty(indptr[-1], dtype=np.int32)
    for i in range(n):
        for a in range(bs):
            pos = indptr[i * bs + a]
            for q in range(nodeptr[i], nodeptr[i + 1]):
                for b in range(bs):
                    indices[pos] = adj[q] * bs + b
                    pos += 1
    return indptr, indices


@njit(cache=True)
def _find(adj, lo, hi, j):
    while lo < hi:
        mid = (lo + hi) // 2
        if adj[mid] < j:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def _plan(nodes, nodeptr, adj, bs, lo, hi, plan_out, old_nodes):
    nv = nodes.shape[1]
    for p in range(lo, hi):
        if old_nodes.shape[0] > p:          # a row is a function of its nodes: keep it
            same = True
            for a in range(nv):
                if nodes[p, a] != old_nodes[p, a]:
                    same = False
                    break
            if same:
                continue
        for a in range(nv):
            i = nodes[p, a]
            for b in range(nv):
                j = nodes[p, b]
                pos = _find(adj, nodeptr[i], nodeptr[i + 1], j)
                if pos >= nodeptr[i + 1] or adj[pos] != j:
                    return (p * nv + a) * nv + b
                plan_out[p, a, b] = nodeptr[i] * bs * bs + (pos - nodeptr[i]) * bs
    return -1


@njit(parallel=PRANGE, cache=True)
def stiffness_plan(nodes, nodeptr, adj, bs, plan_out, old_nodes):
    """plan[p, a, b] = CSR offset of block (nodes[p,a], nodes[p,b]) (row component 0, col 0);
    entry (component r, component c) of that block sits at plan + r*deg(i)*bs + c. Returns -1,
    or the first pair missing from the pattern (flat index p * nv * nv + a * nv + b), whose
    offset is not written. Rows p < len(old_nodes) whose nodes equal old_nodes[p] are left
    as they are (plan_out then holds the plan of old_nodes on the same pattern: the last
    step's; an empty old_nodes computes every row). Threaded over particle chunks
    (per-particle output)."""
    n = nodes.shape[0]
    nc = particle_chunks(n)
    miss = np.full(nc, -1, dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        miss[c] = _plan(nodes, nodeptr, adj, bs, lo, hi, plan_out, old_nodes)
    for c in range(nc):
        if miss[c] >= 0:
            return miss[c]
    return -1


@njit(cache=True)
def diagonal_slots(nodeptr, adj, bs):
    """CSR offset of each diagonal entry (dof i*bs+r)."""
    n = nodeptr.shape[0] - 1
    out = np.empty(n * bs, dtype=np.int64)
    for i in range(n):
        deg = nodeptr[i + 1] - nodeptr[i]
        pos = _find(adj, nodeptr[i], nodeptr[i + 1], i) - nodeptr[i]
        for r in range(bs):
            out[i * bs + r] = nodeptr[i] * bs * bs + r * deg * bs + pos * bs + r
    return out


@njit(cache=True)
def add_block(data, base, deg, i, j, d, constrained, block):
    """Add the d x d block for node pair (i, j) at CSR offset `base` (see stiffness_plan),
    skipping constrained rows and columns."""
    for r in range(d):
        if constrained[i * d + r]:
            continue
        for c in range(d):
            if not constrained[j * d + c]:
                data[base + r * deg * d + c] += block[r, c]


@njit(cache=True, inline="always")
def stiffness_stage(dN, A, p, m, scale, G):
    """G[a, r, c, L] = scale sum_J grad N_ap,J A_p[r, J, c, L] for the first m nodes a of
    particle p: the first stage of a particle's stiffness blocks (block (a, b)[r, c] =
    sum_L G[a, r, c, L] grad N_bp,L)."""
    d = G.shape[1]
    for a in range(m):
        for r in range(d):
            for c in range(d):
                for L in range(d):
                    s = 0.0
                    for J in range(d):
                        s += dN[p, a, J] * A[p, r, J, c, L]
                    G[a, r, c, L] = scale * s


@njit(cache=True)
def _stiffness(D, nodes, dN, V, A, plan, nodeptr, constrained, lo, hi, data):
    """data += the particle terms of particles lo..hi-1 (assemble_stiffness), in two stages
    per particle: G_a[r, c, L] = V_p sum_J grad N_a,J A[r, J, c, L], then block (a, b)
    [r, c] = sum_L G_a[r, c, L] grad N_b,L (n d^4 + n^2 d^3 products instead of n^2 d^4)."""
    d = len(D)
    n = nodes.shape[1]
    G = np.empty((n, d, d, d))
    block = np.empty((d, d))
    for p in range(lo, hi):
        m = row_length(nodes, p)             # the padding's blocks are zero
        stiffness_stage(dN, A, p, m, V[p], G)
        for a in range(m):
            i = nodes[p, a]
            deg = nodeptr[i + 1] - nodeptr[i]
            for b in range(m):
                for r in range(d):
                    for c in range(d):
                        s = 0.0
                        for L in range(d):
                            s += G[a, r, c, L] * dN[p, b, L]
                        block[r, c] = s
                add_block(data, plan[p, a, b], deg, i, nodes[p, b], d, constrained, block)


def assemble_stiffness(D, nodes, dN, V, A, plan, nodeptr, constrained, data):
    """data += sum_p V_p grad N_ia,J A_p[r, J, c, L] grad N_jb,L (particle quadrature of the
    updated-Lagrangian tangent), skipping constrained rows and columns. Threaded as P2G is
    (kernels.threads): chunk c >= 1 adds into its own copy of the CSR values over the rows
    its particles touch, summed into data afterwards."""
    nc = n_chunks(len(nodes))
    _stiffness_chunks(nc, D, nodes, dN, V, A, plan, nodeptr, constrained, data,
                      scratch("stiffness", nc - 1, data))


@njit(parallel=PRANGE, cache=True)
def _stiffness_chunks(nc, D, nodes, dN, V, A, plan, nodeptr, constrained, data, buf):
    n = nodes.shape[0]
    if nc == 1:
        return _stiffness(D, nodes, dN, V, A, plan, nodeptr, constrained, np.int64(0), n, data)
    bs2 = len(D) * len(D)
    rng = np.zeros((nc, 2), dtype=np.int64)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        if c == 0:
            _stiffness(D, nodes, dN, V, A, plan, nodeptr, constrained, lo, hi, data)
        else:
            a, b = node_range(nodes, lo, hi, rng[c])
            rng[c, 0], rng[c, 1] = nodeptr[a] * bs2, nodeptr[b] * bs2     # their CSR values
            buf[c - 1, rng[c, 0]:rng[c, 1]] = 0.0
            _stiffness(D, nodes, dN, V, A, plan, nodeptr, constrained, lo, hi, buf[c - 1])
    add_chunks1(data, buf, rng)
