"""CPDI shape functions (convected particle domain interpolation, 2D and 3D) on any P1/Q1 mesh.

A particle's domain Omega_p is a quadrilateral with corners x_1..x_4 (counter-clockwise).
With M_c the bilinear corner functions of the domain and S_i the grid's standard shape
functions evaluated at the corners (Sadeghirad et al. 2011, 2013; seed 004 §2.5):
    phi_ip      = (1/V_p) sum_c w_c S_i(x_c),      w_c = int_{Omega_p} M_c dx,
    grad phi_ip = (1/V_p) sum_c S_i(x_c) g_c,      g_c = int_{Omega_p} grad M_c dx
                = 1/2 R (x_{c+1} - x_{c-1}),       R (a, b) = (b, -a)  (the boundary integral
                  of M_c n over the two edges at corner c),  V_p = sum_c w_c.
CPDI1 (seed 004 eqs 2.24-2.25, corrected in BENCHMARKS.md "CPDI1"): the domain is the
parallelogram of edge vectors r1, r2 (r_k = F_p r_k^0),
    x1 = x_p - (r1 + r2)/2, x2 = x_p + (r1 - r2)/2, x3 = x_p + (r1 + r2)/2, x4 = x_p - (r1 - r2)/2,
so w_c = V_p / 4 and the gradient above is
    grad phi_ip = 1/(2 V_p) {[S_i(x1) - S_i(x3)] [r1y - r2y; r2x - r1x]
                             + [S_i(x2) - S_i(x4)] [r1y + r2y; -r1x - r2x]},  V_p = r1 x r2.
CPDI2 (Sadeghirad et al. 2013, quadrilateral domains): the corners are material points
themselves, moved with the grid velocity, x_c += dt sum_i S_i(x_c) v_i, so the domain can
take any quadrilateral shape; w_c is integrated exactly by 2 x 2 Gauss points.
3D (the same equations with 8 corners and trilinear M_c, corner c = b0 + 2 b1 + 4 b2 at
reference point (b0, b1, b2), s_k = 2 b_k - 1): CPDI1's domain is the parallelepiped of edges
r_k = F_p r_k^0, x_c = x_p + 1/2 sum_k s_k r_k, w_c = V_p / 8, V_p = r1 . (r2 x r3) and
    g_c = 1/4 [s_1 (r2 x r3) + s_2 (r3 x r1) + s_3 (r1 x r2)]
(grad M_c = J^-T grad_xi M_c with J = [r1 r2 r3], int over the unit cube of dM_c/dxi_k =
s_k / 4, and det J J^-T = cof J; in 2D the same gives the formula above). CPDI2's hexahedral
domains get w_c and g_c = int cof(J) grad_xi M_c dxi by 2 x 2 x 2 Gauss points (exact).
Both satisfy sum_i phi_ip = 1 and sum_i grad phi_ip = 0 and reproduce affine fields exactly
(S_i does at each corner).
"""
import numpy as np
from numba import njit, prange

from ..kernels.threads import PRANGE, chunk, particle_chunks
from ..kernels.transfer import pad_row
from .gimp import PaddedStencil

N_CORNERS = 4
_GP = (0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0))


@njit(cache=True)
def _cpdi1_corners(x, F, r0, corners_out, lo, hi):
    for p in range(lo, hi):
        r1x = F[p, 0, 0] * r0[p, 0, 0] + F[p, 0, 1] * r0[p, 0, 1]
        r1y = F[p, 1, 0] * r0[p, 0, 0] + F[p, 1, 1] * r0[p, 0, 1]
        r2x = F[p, 0, 0] * r0[p, 1, 0] + F[p, 0, 1] * r0[p, 1, 1]
        r2y = F[p, 1, 0] * r0[p, 1, 0] + F[p, 1, 1] * r0[p, 1, 1]
        corners_out[p, 0, 0] = x[p, 0] - 0.5 * (r1x + r2x)
        corners_out[p, 0, 1] = x[p, 1] - 0.5 * (r1y + r2y)
        corners_out[p, 1, 0] = x[p, 0] + 0.5 * (r1x - r2x)
        corners_out[p, 1, 1] = x[p, 1] + 0.5 * (r1y - r2y)
        corners_out[p, 2, 0] = x[p, 0] + 0.5 * (r1x + r2x)
        corners_out[p, 2, 1] = x[p, 1] + 0.5 * (r1y + r2y)
        corners_out[p, 3, 0] = x[p, 0] - 0.5 * (r1x - r2x)
        corners_out[p, 3, 1] = x[p, 1] - 0.5 * (r1y - r2y)


@njit(parallel=PRANGE, cache=True)
def cpdi1_corners(x, F, r0, corners_out):
    """Corners of the CPDI1 parallelograms: r_k = F_p r_k^0 (in-plane block of F), corners
    x_p -(r1+r2)/2, x_p +(r1-r2)/2, x_p +(r1+r2)/2, x_p -(r1-r2)/2. r0: (n, 2, 2), r0[p, k]
    is the initial edge vector k."""
    n = x.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _cpdi1_corners(x, F, r0, corners_out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _cpdi1_corners(x, F, r0, corners_out, lo, hi)


@njit(cache=True)
def _corner_weights(corners, w_out, g_out, lo, hi):
    vmin = np.inf
    # reference corners (0,0), (1,0), (1,1), (0,1) in the counter-clockwise order
    rx = (0.0, 1.0, 1.0, 0.0)
    ry = (0.0, 0.0, 1.0, 1.0)
    M = np.empty(4)
    for p in range(lo, hi):
        for c in range(4):
            w_out[p, c] = 0.0
            nxt = corners[p, (c + 1) % 4]
            prv = corners[p, (c + 3) % 4]
            g_out[p, c, 0] = 0.5 * (nxt[1] - prv[1])
            g_out[p, c, 1] = -0.5 * (nxt[0] - prv[0])
        for gi in range(2):
            for gj in range(2):
                s, t = _GP[gi], _GP[gj]
                J00 = J01 = J10 = J11 = 0.0
                for c in range(4):
                    fs = s if rx[c] == 1.0 else 1.0 - s
                    ft = t if ry[c] == 1.0 else 1.0 - t
                    M[c] = fs * ft
                    ds = (1.0 if rx[c] == 1.0 else -1.0) * ft
                    dt = (1.0 if ry[c] == 1.0 else -1.0) * fs
                    J00 += corners[p, c, 0] * ds
                    J01 += corners[p, c, 0] * dt
                    J10 += corners[p, c, 1] * ds
                    J11 += corners[p, c, 1] * dt
                det = J00 * J11 - J01 * J10
                for c in range(4):
                    w_out[p, c] += 0.25 * M[c] * det
        V = w_out[p, 0] + w_out[p, 1] + w_out[p, 2] + w_out[p, 3]
        vmin = min(vmin, V)
    return vmin


@njit(parallel=PRANGE, cache=True)
def corner_weights(corners, w_out, g_out):
    """w_c = int M_c dx (2 x 2 Gauss on the bilinear map of the quadrilateral, exact) and
    g_c = 1/2 R (x_{c+1} - x_{c-1}) for each particle's domain (corners counter-clockwise).
    Returns the smallest domain area (<= 0: a domain turned inside out)."""
    n = corners.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _corner_weights(corners, w_out, g_out, np.int64(0), n)
    vmin = np.empty(nc)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        vmin[c] = _corner_weights(corners, w_out, g_out, lo, hi)
    return vmin.min()


# ---------------------------------------------------------------------------------- 3D
# Corners of a hexahedral domain in the tensor (dolfinx) order: corner c = b0 + 2 b1 + 4 b2
# sits at reference point (b0, b1, b2) of the trilinear map, M_c = prod_k (b_k ? s_k : 1 - s_k).
N_CORNERS_3D = 8


@njit(cache=True)
def _cpdi1_corners3(x, F, r0, corners_out, lo, hi):
    r = np.empty((3, 3))
    for p in range(lo, hi):
        for k in range(3):
            for i in range(3):
                r[k, i] = F[p, i, 0] * r0[p, k, 0] + F[p, i, 1] * r0[p, k, 1] + F[p, i, 2] * r0[p, k, 2]
        for c in range(8):
            for i in range(3):
                v = x[p, i]
                for k in range(3):
                    v += (0.5 if (c >> k) & 1 else -0.5) * r[k, i]
                corners_out[p, c, i] = v


@njit(parallel=PRANGE, cache=True)
def cpdi1_corners3(x, F, r0, corners_out):
    """Corners of the 3D CPDI1 parallelepipeds: r_k = F_p r_k^0, x_c = x_p + 1/2 sum_k s_k r_k,
    s_k = +1 where bit k of c is set, else -1 (c = 0..7). r0: (n, 3, 3), r0[p, k] is edge k."""
    n = x.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _cpdi1_corners3(x, F, r0, corners_out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _cpdi1_corners3(x, F, r0, corners_out, lo, hi)


@njit(cache=True)
def _parallelepiped_weights(corners, w_out, g_out, lo, hi):
    vmin = np.inf
    r = np.empty((3, 3))
    a = np.empty((3, 3))
    for p in range(lo, hi):
        for k in range(3):                          # r_k = x_(2^k) - x_0
            for i in range(3):
                r[k, i] = corners[p, 1 << k, i] - corners[p, 0, i]
        for k in range(3):                          # a_k = r_(k+1) x r_(k+2)
            u, v = r[(k + 1) % 3], r[(k + 2) % 3]
            a[k, 0] = u[1] * v[2] - u[2] * v[1]
            a[k, 1] = u[2] * v[0] - u[0] * v[2]
            a[k, 2] = u[0] * v[1] - u[1] * v[0]
        V = r[0, 0] * a[0, 0] + r[0, 1] * a[0, 1] + r[0, 2] * a[0, 2]
        for c in range(8):
            w_out[p, c] = 0.125 * V
            for i in range(3):
                v = 0.0
                for k in range(3):
                    v += (0.25 if (c >> k) & 1 else -0.25) * a[k, i]
                g_out[p, c, i] = v
        vmin = min(vmin, V)
    return vmin


@njit(parallel=PRANGE, cache=True)
def parallelepiped_weights(corners, w_out, g_out):
    """CPDI1 in 3D: w_c = V_p / 8 and g_c = int grad M_c dx = 1/4 sum_k s_k (r_(k+1) x r_(k+2))
    (k cyclic; the cofactor matrix of [r1 r2 r3] times the integral s_k / 4 of dM_c/dxi_k over
    the unit cube), V_p = r1 . (r2 x r3); r_k = x_(2^k) - x_0 from the corners (n, 8, 3) of
    cpdi1_corners3. Returns the smallest V_p (<= 0: inside out)."""
    n = corners.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _parallelepiped_weights(corners, w_out, g_out, np.int64(0), n)
    vmin = np.empty(nc)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        vmin[c] = _parallelepiped_weights(corners, w_out, g_out, lo, hi)
    return vmin.min()


@njit(cache=True)
def _corner_weights3(corners, w_out, g_out, lo, hi):
    vmin = np.inf
    M = np.empty(8)
    dM = np.empty((8, 3))
    J = np.empty((3, 3))                            # J[k] = dx/dxi_k (rows)
    cof = np.empty((3, 3))                          # cof[k] = J[k+1] x J[k+2]
    s = np.empty(3)
    for p in range(lo, hi):
        for c in range(8):
            w_out[p, c] = 0.0
            for i in range(3):
                g_out[p, c, i] = 0.0
        for q in range(8):
            for k in range(3):
                s[k] = _GP[(q >> k) & 1]
            for c in range(8):
                f0 = s[0] if c & 1 else 1.0 - s[0]
                f1 = s[1] if c & 2 else 1.0 - s[1]
                f2 = s[2] if c & 4 else 1.0 - s[2]
                M[c] = f0 * f1 * f2
                dM[c, 0] = (1.0 if c & 1 else -1.0) * f1 * f2
                dM[c, 1] = (1.0 if c & 2 else -1.0) * f0 * f2
                dM[c, 2] = (1.0 if c & 4 else -1.0) * f0 * f1
            for k in range(3):
                for i in range(3):
                    v = 0.0
                    for c in range(8):
                        v += corners[p, c, i] * dM[c, k]
                    J[k, i] = v
            for k in range(3):
                u, v = J[(k + 1) % 3], J[(k + 2) % 3]
                cof[k, 0] = u[1] * v[2] - u[2] * v[1]
                cof[k, 1] = u[2] * v[0] - u[0] * v[2]
                cof[k, 2] = u[0] * v[1] - u[1] * v[0]
            det = J[0, 0] * cof[0, 0] + J[0, 1] * cof[0, 1] + J[0, 2] * cof[0, 2]
            for c in range(8):
                w_out[p, c] += 0.125 * M[c] * det
                for i in range(3):
                    g_out[p, c, i] += 0.125 * (dM[c, 0] * cof[0, i] + dM[c, 1] * cof[1, i]
                                               + dM[c, 2] * cof[2, i])
        V = 0.0
        for c in range(8):
            V += w_out[p, c]
        vmin = min(vmin, V)
    return vmin


@njit(parallel=PRANGE, cache=True)
def corner_weights3(corners, w_out, g_out):
    """3D CPDI2 (hexahedral domains, corners (n, 8, 3) in tensor order): w_c = int M_c dx and
    g_c = int grad M_c dx = int cof(J) grad_xi M_c dxi (cof(J) = det J J^-T, rows
    J_(k+1) x J_(k+2)), both by 2 x 2 x 2 Gauss points, exact for the trilinear map (the
    integrands are at most cubic per reference direction). Returns the smallest volume."""
    n = corners.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _corner_weights3(corners, w_out, g_out, np.int64(0), n)
    vmin = np.empty(nc)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        vmin[c] = _corner_weights3(corners, w_out, g_out, lo, hi)
    return vmin.min()


@njit(cache=True)
def _simplex_corners(x, F, r0, corners_out, lo, hi):
    d = x.shape[1]
    for p in range(lo, hi):
        for c in range(r0.shape[1]):
            for i in range(d):
                s = x[p, i]
                for j in range(d):
                    s += F[p, i, j] * r0[p, c, j]
                corners_out[p, c, i] = s


@njit(parallel=PRANGE, cache=True)
def simplex_corners(x, F, r0, corners_out):
    """Corners of triangular / tetrahedral CPDI1 domains: x_c = x_p + F_p r_c^0 (r0 (n, d + 1,
    d), the initial corner offsets from the centroid, sum_c r_c^0 = 0)."""
    n = x.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _simplex_corners(x, F, r0, corners_out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _simplex_corners(x, F, r0, corners_out, lo, hi)


@njit(cache=True)
def _tri_weights(corners, w_out, g_out, lo, hi):
    vmin = np.inf
    for p in range(lo, hi):
        e1x = corners[p, 1, 0] - corners[p, 0, 0]
        e1y = corners[p, 1, 1] - corners[p, 0, 1]
        e2x = corners[p, 2, 0] - corners[p, 0, 0]
        e2y = corners[p, 2, 1] - corners[p, 0, 1]
        g_out[p, 1, 0] = 0.5 * e2y
        g_out[p, 1, 1] = -0.5 * e2x
        g_out[p, 2, 0] = -0.5 * e1y
        g_out[p, 2, 1] = 0.5 * e1x
        g_out[p, 0, 0] = -(g_out[p, 1, 0] + g_out[p, 2, 0])
        g_out[p, 0, 1] = -(g_out[p, 1, 1] + g_out[p, 2, 1])
        A = 0.5 * (e1x * e2y - e1y * e2x)
        for c in range(3):
            w_out[p, c] = A / 3.0
        vmin = min(vmin, A)
    return vmin


@njit(parallel=PRANGE, cache=True)
def tri_weights(corners, w_out, g_out):
    """Triangular domains (corners (n, 3, 2), positively oriented), linear M_c: w_c = A_p / 3,
    g_c = A_p grad M_c: g_1 = (e2_y, -e2_x) / 2, g_2 = (-e1_y, e1_x) / 2 (e_k = x_k - x_0),
    g_0 = -(g_1 + g_2), A_p = (e1 x e2) / 2 (the 2D case of tet_weights). Returns the
    smallest A_p."""
    n = corners.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _tri_weights(corners, w_out, g_out, np.int64(0), n)
    vmin = np.empty(nc)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        vmin[c] = _tri_weights(corners, w_out, g_out, lo, hi)
    return vmin.min()


@njit(cache=True)
def _tet_weights(corners, w_out, g_out, lo, hi):
    vmin = np.inf
    e = np.empty((3, 3))
    for p in range(lo, hi):
        for k in range(3):
            for i in range(3):
                e[k, i] = corners[p, k + 1, i] - corners[p, 0, i]
        for k in range(3):                          # g_(k+1) = (e_(k+1) x e_(k+2)) / 6
            u, v = e[(k + 1) % 3], e[(k + 2) % 3]
            g_out[p, k + 1, 0] = (u[1] * v[2] - u[2] * v[1]) / 6.0
            g_out[p, k + 1, 1] = (u[2] * v[0] - u[0] * v[2]) / 6.0
            g_out[p, k + 1, 2] = (u[0] * v[1] - u[1] * v[0]) / 6.0
        for i in range(3):
            g_out[p, 0, i] = -(g_out[p, 1, i] + g_out[p, 2, i] + g_out[p, 3, i])
        V = e[0, 0] * g_out[p, 1, 0] + e[0, 1] * g_out[p, 1, 1] + e[0, 2] * g_out[p, 1, 2]
        for c in range(4):
            w_out[p, c] = 0.25 * V
        vmin = min(vmin, V)
    return vmin


@njit(parallel=PRANGE, cache=True)
def tet_weights(corners, w_out, g_out):
    """Tetrahedral domains (corners (n, 4, 3), positively oriented), linear M_c:
    w_c = V_p / 4, g_c = V_p grad M_c: g_k = (e_(k+1) x e_(k+2)) / 6 for k = 1..3 (e_k =
    x_k - x_0, cyclic), g_0 = -(g_1 + g_2 + g_3), V_p = e_1 . (e_2 x e_3) / 6 (Sadeghirad et
    al. 2013, tetrahedral CPDI2 domains). Returns the smallest V_p."""
    n = corners.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _tet_weights(corners, w_out, g_out, np.int64(0), n)
    vmin = np.empty(nc)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        vmin[c] = _tet_weights(corners, w_out, g_out, lo, hi)
    return vmin.min()


def initial_simplices(grid, particles):
    """Initial triangular / tetrahedral domains (n, d + 1, d) as offsets from x_p, vertices 1
    and 2 swapped where a domain is negatively oriented. A particle of
    Particles.fill(per_cell=k) (measure V_cell / k^d, at the centroid of sub-simplex j of
    particles.simplex_subdivision(d, k) in its cell) gets that sub-simplex: the domains tile
    the body (with k = 1 they are the cells). Any other particle gets its cell shrunk about
    its centroid to its measure V0_p, r_c^0 = (V0_p / V_cell)^(1/d) (X_c - X_centroid)."""
    from ..particles import simplex_subdivision
    p, d = particles, grid.gdim
    X = grid.node_x[grid.cell_nodes[p.cell]][:, :, :d]        # (n, d + 1, d)
    e = X[:, 1:] - X[:, :1]
    det = np.linalg.det(e) if len(X) else np.zeros(0)
    ref = 0.5 if d == 2 else 1.0 / 6.0                        # reference measure
    s = (p.V0 / (np.abs(det) * ref)) ** (1.0 / d)
    out = (X - X.mean(axis=1, keepdims=True)) * s[:, None, None]
    k = np.rint(1.0 / s).astype(int) if len(X) else np.zeros(0, int)
    fits = (k > 1) & (np.abs(k * s - 1.0) < 1e-8)
    for kk in np.unique(k[fits]):
        sub = simplex_subdivision(d, int(kk))                 # (kk^d, d + 1, d) reference
        cen = sub.mean(axis=1)
        sel = np.flatnonzero(fits & (k == kk))
        dist = np.linalg.norm(p.xi[sel, None, :d] - cen[None], axis=2)
        j = np.argmin(dist, axis=1)
        hit = dist[np.arange(len(sel)), j] < 1e-8
        sel, j = sel[hit], j[hit]
        Xs = X[sel, :1] + np.einsum("pcr,prk->pck", sub[j], e[sel])   # x = X_0 + e^T xi
        out[sel] = Xs - Xs.mean(axis=1, keepdims=True)
    flip = (np.linalg.det(out[:, 1:] - out[:, :1]) < 0) if len(X) else np.zeros(0, bool)
    out[flip, 1], out[flip, 2] = out[flip, 2].copy(), out[flip, 1].copy()
    return out


@njit(cache=True)
def _cpdi_combine(D, cnodes, cN, w, g, nodes_out, N_out, dN_out, count_out, lo, hi):
    d = len(D)
    nv = nodes_out.shape[1]
    ncor = w.shape[1]
    for p in range(lo, hi):
        V = 0.0
        for c in range(ncor):
            V += w[p, c]
        cnt = 0
        for c in range(ncor):
            for a in range(cnodes.shape[2]):
                s = cN[p, c, a]
                if s == 0.0:
                    continue
                i = cnodes[p, c, a]
                slot = cnt
                for b in range(min(cnt, nv)):
                    if nodes_out[p, b] == i:
                        slot = b
                        break
                if slot == cnt:
                    cnt += 1
                    if slot >= nv:      # no column left: counted only (evaluated again wider)
                        continue
                    nodes_out[p, slot] = i
                    N_out[p, slot] = 0.0
                    for k in range(d):
                        dN_out[p, slot, k] = 0.0
                N_out[p, slot] += w[p, c] * s / V
                for k in range(d):
                    dN_out[p, slot, k] += g[p, c, k] * s / V
        count_out[p] = cnt
        pad_row(d, p, cnt, nodes_out[p, 0], nodes_out, N_out, dN_out)


@njit(parallel=PRANGE, cache=True)
def cpdi_combine(D, cnodes, cN, w, g, nodes_out, N_out, dN_out, count_out):
    """phi_ip and grad phi_ip from the corner shape functions (see the module docstring).

    cnodes, cN: (n, nc, nvc) grid nodes and standard shape values at each of the nc corners
    (4 in 2D, 8 in 3D); w (n, nc), g (n, nc, gdim) from corner_weights/corner_weights3. Nodes shared by several corners are merged: each node
    appears once (count_out[p] of them), then padding (kernels.transfer.pad_row); a
    particle with more nodes than the outputs have columns gets only the first ones written
    and a count above the columns (the caller evaluates again with all ncor nvc columns)."""
    n = cnodes.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _cpdi_combine(D, cnodes, cN, w, g, nodes_out, N_out, dN_out, count_out, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _cpdi_combine(D, cnodes, cN, w, g, nodes_out, N_out, dN_out, count_out, lo, hi)


@njit(cache=True)
def _move_corners(D, cnodes, cN, body, rigid, du_rigid, du, corners, lo, hi):
    d = len(D)
    for p in range(lo, hi):
        b = body[p]
        for c in range(corners.shape[1]):
            for k in range(d):
                if rigid[b]:
                    corners[p, c, k] += du_rigid[b, k]
                    continue
                for a in range(cnodes.shape[2]):
                    corners[p, c, k] += cN[p, c, a] * du[cnodes[p, c, a], b, k]


@njit(parallel=PRANGE, cache=True)
def move_corners(D, cnodes, cN, body, rigid, du_rigid, du, corners):
    """CPDI2 corner update x_c += sum_i S_i(x_c) du_i[b] with the step's nodal displacement
    du (n_nodes, bodies, gdim) of the particle's body b = body[p] (one body: all zeros;
    contact.multi_velocity: each its own field); corners of rigid bodies (rigid[b]) move by
    du_rigid[b], as their particles do."""
    n = corners.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _move_corners(D, cnodes, cN, body, rigid, du_rigid, du, corners, np.int64(0), n)
    for c in prange(nc):
        lo, hi = chunk(n, nc, c)
        _move_corners(D, cnodes, cN, body, rigid, du_rigid, du, corners, lo, hi)


def initial_edges(grid, particles):
    """CPDI1 edge vectors r_k^0 (n, d, d) of volume V0_p: on quadrilaterals/hexahedra the
    particle's cell edges e_k = x_(vertex 2^k) - x_(vertex 0) scaled by (V0_p / |det e|)^(1/d)
    (for Particles.fill with n per direction: e_k / n on parallelogram/parallelepiped cells),
    with e1, e2 swapped where det e < 0; on triangles/tetrahedra (shapes.gauss_gimp; CPDI uses
    initial_simplices there) an axis-aligned square/cube of side V0_p^(1/d)."""
    from . import standard as ks
    n, d = len(particles), grid.gdim
    r0 = np.zeros((n, d, d))
    if grid.kind == ks.SIMPLEX:
        s = particles.V0 ** (1.0 / d)
        for k in range(d):
            r0[:, k, k] = s
        return r0
    cn = grid.cell_nodes[particles.cell]
    e = np.stack([grid.node_x[cn[:, 1 << k]] - grid.node_x[cn[:, 0]] for k in range(d)], axis=1)
    det = np.linalg.det(e) if n else np.zeros(0)
    s = (particles.V0 / np.abs(det)) ** (1.0 / d)
    flip = det < 0                            # keep det [r1 .. rd] > 0 (positive orientation)
    r0[:, 0] = np.where(flip[:, None], e[:, 1], e[:, 0]) * s[:, None]
    r0[:, 1] = np.where(flip[:, None], e[:, 0], e[:, 1]) * s[:, None]
    if d == 3:
        r0[:, 2] = e[:, 2] * s[:, None]
    return r0


def has_edge_domains(grid, particles):
    """Whether `particles` carry the quadrilateral domains of Particles.fill_edges on a
    triangle mesh (4 corners in `cpdi_corners`; fill's sub-triangles have 3)."""
    from . import standard as ks
    c = getattr(particles, "cpdi_corners", None)
    return grid.kind == ks.SIMPLEX and c is not None and c.shape[1:] == (N_CORNERS, 2)


class CpdiShape(PaddedStencil):
    """CPDI1 (version 1) or CPDI2 (version 2) for a 2D or 3D Simulation: parallelogram /
    parallelepiped domains (CPDI1), quadrilateral / hexahedral domains (CPDI2); on triangle and
    tetrahedron meshes triangular / tetrahedral domains (the sub-simplices of
    Particles.fill, initial_simplices), moved affinely with F (CPDI1) or corner by corner
    (CPDI2; Sadeghirad et al. 2013); on triangles, particles that bring 4 corners in
    `cpdi_corners` (the edge diamonds of Particles.fill_edges) keep quadrilateral domains
    (CPDI2 only).

    Adds the particle field `cpdi_r0` (n, d, d), the initial edge vectors (initial_edges), or on
    simplex meshes `cpdi_t0` (n, d + 1, d), the initial corner offsets, and for CPDI2
    `cpdi_corners` (n, 4, 2), (n, 8, 3) or (n, d + 1, d), started as the CPDI1 domains. A corner
    outside the mesh (a particle at the boundary) uses the basis of the particle's own cell,
    extended linearly: the weights still sum to 1 and reproduce affine fields."""

    def __init__(self, sim, version):
        from .gimp import _RING_MESSAGE
        grid, p = sim.grid, sim.particles
        d = grid.gdim
        if d not in (2, 3):
            raise NotImplementedError(f"CPDI shape functions are implemented in 2D and 3D, "
                                      f"got gdim = {d}")
        if not grid.has_vertex_ring():
            raise ValueError(_RING_MESSAGE.format(name="CPDI"))
        from . import standard as ks
        self.version = int(version)
        self.d = d
        # quadrilateral domains on triangles: the edge diamonds of Particles.fill_edges
        diamonds = has_edge_domains(grid, p)
        if diamonds and self.version != 2:
            raise ValueError("shape='cpdi1': the edge domains of Particles.fill_edges are "
                             "quadrilaterals that only CPDI2 moves (shape='cpdi2' or 'auto')")
        self.simplex = grid.kind == ks.SIMPLEX and not diamonds
        self.n_corners = d + 1 if self.simplex else N_CORNERS if d == 2 else N_CORNERS_3D
        if self.simplex and not hasattr(p, "cpdi_t0"):
            p.add_field("cpdi_t0", (d + 1, d))[:] = initial_simplices(grid, p)
        if not self.simplex and not diamonds and not hasattr(p, "cpdi_r0"):
            p.add_field("cpdi_r0", (d, d))[:] = initial_edges(grid, p)
        if self.version == 2 and not hasattr(p, "cpdi_corners"):
            self._cpdi1_corners(p, p.add_field("cpdi_corners", (self.n_corners, d)))
        self._corner_shape = None
        self._corner_cells, self._corner_key = None, None     # last step's corner cells
        self._corner_buffers = {}                               # shape_at_points' outputs
        self._init_buffers()

    def _cpdi1_corners(self, p, out):
        if self.simplex:
            simplex_corners(p.x, p.F, p.cpdi_t0, out)
        elif self.d == 2:
            cpdi1_corners(p.x, p.F, p.cpdi_r0, out)
        else:
            cpdi1_corners3(p.x, p.F, p.cpdi_r0, out)

    def after_step(self, sim, dt):
        """CPDI2: move the corners with the step's grid displacement u_i, x_c += sum_i S_i(x_c)
        u_i, with the corner shape functions of that step (particles not yet migrated): the
        increment the particles moved by, which every integrator leaves in
        sim.nodal["displacement"] (explicit MUSL/AVG: dt times the updated grid velocity, not
        the remapped one the stress sees), or per body in sim.nodal["body_displacement"]
        (fm.ExplicitContact: each particle's own body's field; rigid bodies their prescribed
        motion). Called by Simulation once a step of dt is accepted, so a checkpoint holds the
        moved corners, a changed or halved dt moves them by the step's own dt, and shapes
        evaluated between steps (output, probes) do not move them again."""
        cs, self._corner_shape = self._corner_shape, None
        if self.version != 2 or cs is None:
            return
        corners = sim.particles.cpdi_corners
        if "body_displacement" in sim.nodal:
            body, rigid, du_rigid, du = sim.nodal["body_displacement"]
        else:                                        # one body
            du = sim.nodal["displacement"][:, None, :]
            body, rigid = np.zeros(len(corners), dtype=np.int32), np.zeros(1, dtype=np.bool_)
            du_rigid = np.zeros((1, du.shape[2]))
        move_corners(sim.grid.D, cs[0], cs[1], body, rigid, du_rigid, du, corners)

    def evaluate(self, sim):
        """(nodes, N, dN) of the local particles; nv = the largest number of distinct nodes a
        particle's corners reach (padded)."""
        p, g = sim.particles, sim.grid
        n, nvc, d, ncor = len(p), g.cell_nodes.shape[1], self.d, self.n_corners
        if self.version == 2:
            corners = p.cpdi_corners
        else:
            corners = np.empty((n, ncor, d))
            self._cpdi1_corners(p, corners)
        key = (p.version, n)
        hint = self._corner_cells if self._corner_key == key else None
        cnodes, cN, _, self._corner_cells = shape_at_points(g, corners, p.cell, hint,
                                                            self._corner_buffers, False)
        self._corner_key = key
        cnodes = cnodes.reshape(n, ncor, nvc)
        cN = cN.reshape(n, ncor, nvc)
        w = np.empty((n, ncor))
        gc = np.empty((n, ncor, d))
        weights = ((tri_weights if d == 2 else tet_weights) if self.simplex else
                   corner_weights if d == 2 else
                   parallelepiped_weights if self.version == 1 else corner_weights3)
        if n and weights(corners, w, gc) <= 0.0:
            bad = int(np.argmin(w.sum(axis=1)))
            raise RuntimeError(f"CPDI: the domain of particle {int(p.id[bad])} at "
                               f"{np.round(p.x[bad], 6).tolist()} has turned inside out "
                               f"({'area' if d == 2 else 'volume'} {w[bad].sum():.3g})")
        self._corner_shape = (cnodes, cN)

        def combine(nodes, N, dN, count):
            cpdi_combine(g.D, cnodes, cN, w, gc, nodes, N, dN, count)
            return -1

        return self._fill(n, d, ncor * nvc, combine)[0]


def shape_at_points(g, points, cells_hint, point_cells=None, buffers=None, gradients=True):
    """Standard-MPM (nodes, N, dN, cells) at points (n, k, gdim) of n particles, flattened to
    n k rows, with each point's cell (n k,; -1 where it is in no local cell). A point outside
    the local mesh uses its particle's cell (`cells_hint`), extended linearly. The search
    starts at `point_cells` (the cells this returned for the same particles last step: a
    CPDI corner rarely leaves its cell in a step, and on unstructured meshes only the points
    that left it are searched again; about 58 % of the corners of triangular CPDI2 domains lie
    outside their particle's cell) or, without it, at the particle's cell. `buffers`: a dict
    the caller keeps between calls, holding the output arrays (no fresh allocation of the n k
    rows per step, whose first touch costs as much as filling them). gradients=False: dN is
    None (CPDI needs the corner values only)."""
    from . import standard as ks
    n, k, d = points.shape
    nvc = g.cell_nodes.shape[1]
    flat = np.ascontiguousarray(points.reshape(-1, d))
    hint = np.repeat(cells_hint, k)
    start = hint if point_cells is None else np.where(point_cells >= 0, point_cells, hint)
    cells, xi = g.locate(flat, start)
    found = cells.copy()
    lost = np.flatnonzero(cells < 0)
    if len(lost):
        cells[lost] = hint[lost]
        xl = np.empty((len(lost), d))
        ks.pull_back(g.kind, np.ascontiguousarray(flat[lost]), cells[lost], g.cell_nodes,
                     g.node_x, g.affine_Jinv, xl, np.empty(len(lost), dtype=np.bool_))
        xi[lost] = xl
    buf = {} if buffers is None else buffers
    if buf.get("shape") != (n * k, nvc, d, gradients):
        buf.update(shape=(n * k, nvc, d, gradients), nodes=np.empty((n * k, nvc), dtype=np.int32),
                   N=np.empty((n * k, nvc)), dN=np.empty((n * k, nvc, d)) if gradients else None)
    nodes, N, dN = buf["nodes"], buf["N"], buf["dN"]
    if gradients:
        ks.mpm_shape(g.D, g.kind, cells, xi, g.cell_nodes, g.node_x, g.simplex_grad,
                     g.affine_Jinv, nodes, N, dN)
    else:
        ks.mpm_values(g.D, g.kind, cells, xi, g.cell_nodes, nodes, N)
    return nodes, N, dN, found


def trim_stencil(nodes, N, dN, count):
    """The combined stencil cut to the largest distinct-node count over particles (>= 1)."""
    nv = max(int(count.max()) if len(count) else 1, 1)
    return (np.ascontiguousarray(nodes[:, :nv]), np.ascontiguousarray(N[:, :nv]),
            np.ascontiguousarray(dN[:, :nv]))
