"""Penalty node-to-segment contact between bodies (seed 004 §2.6.4-2.6.8, eqs 2.40-2.53), the
`algorithm="penalty"` of fm.ExplicitContact (2D).

Polylines. Each body has one or more boundary polylines (`ExplicitContact.add_polyline`;
`circle`, `rectangle` and `line` below build common ones). Orientation: the body lies on the
LEFT of each segment x1 -> x2 (closed polylines are made counter-clockwise automatically), so
with e_t = (x2 - x1)/|x2 - x1| the outward unit normal is e_n = (e_t,y, -e_t,x). The vertices
move with their body's grid velocity like particles, x_v += dt v_v, with
    v_v = sum_i N_i(x_v) m_i^b v_i^b / W_v,   W_v = sum_i N_i(x_v) m_i^b
(standard shape functions weighted by the body's nodal mass, over the nodes where the body is
present; a rigid body's vertices move with its prescribed velocity). A vertex with W_v = 0
(no mass of its body around it, or outside the mesh) stays where it is and takes no part.

Detection (seed 004 §2.6.7, in three steps): (1) only vertices whose cell has a node where two
or more bodies are present are slaves; (2) a bucket search (bins of size h + l_max/2) gives
the segments of the other bodies within reach; (3) the slave s and segment (x1, x2) form a
pair when
    xi  = (x_s - x1) . e_t / l in [0, 1]     (eq 2.43),
    g_n = (x_s - x1) . e_n < 0               (eq 2.42, 2.51: gap g_n < 0 is penetration),
for the segment of least |g_n| among those with |g_n| <= h (deeper penetrations are not
searched) that face the slave, e_n . n_s < -1/2 (n_s the slave's mean outward normal; this
removes the ambiguity at the master's corners, where a side face can be nearer than the
face that was penetrated). Every body's vertices are slaves against every other body's
segments (two-pass, each pass with weight w = 1/2, so no master/slave choice is needed).

Forces (eqs 2.45-2.48 with the g_n/l terms of C_n, C_t dropped: penetrations are small).
With l_s the slave's tributary length (half its two segments) and k_n, k_t in force per unit
length per unit penetration or slip (Pa/m per unit thickness):
    normal:      f_n = w k_n (-g_n) l_s >= 0                     (compressive),
    tangential:  f_t* = f_t^old - w k_t l_s dg_t,  dg_t = (du_s - (1 - xi) du_1 - xi du_2) . e_t
                 (the elastic slip spring: du the vertices' displacements over the last step),
    Coulomb cap: |f_t| <= mu f_n:  f_t = f_t* if |f_t*| <= mu f_n (stick), else
                 mu f_n sign(f_t*) (slip); f_t is stored per slave vertex (0 out of contact),
    F_s = f_n e_n + f_t e_t on the slave, -(1 - xi) F_s and -xi F_s on the segment's ends,
so the forces on the bodies are equal and opposite (momentum is conserved exactly).

Normal damping. f_n above also carries a dashpot on the normal approach over the last step,
    f_n = max(w l_s (k_n (-g_n) - c_n dg_n / dt), 0),  dg_n = (du_s - (1 - xi) du_1 - xi du_2) . e_n,
    c_n = 2 zeta sqrt(k_n rho_min h / 2),
zeta the ratio to the critical damping of the spring against the surface layer's mass
(rho h / 2 per unit length) (`penalty=dict(damping=zeta)`, default DAMPING = 0.1). Without
it a stress wave rings in the springs and, with friction, grows: every dip of f_n below
|f_t| / mu lets the face slip a step, the slip feeds the ringing, and a block that must stick
on a 30 deg rigid incline (mu = 0.7, geostatic start, h = 0.05 m, MUSL) rang from 0 to 5x its
weight and slid 40 mm in 0.5 s (6.5 % of the frictionless slide). With MUSL the vertices
must also move with the re-mapped velocity, the one the bodies' stress update sees
(fm.ExplicitContact): with the dashpot alone the block slid 27 mm, with the re-mapped
motion alone 88 mm, with both 1.0 mm (0.17 %). Measured with
`fenicsmpm.problems.friction.block_on_rigid_body(..., algorithm="penalty")` and both:
zeta = 0.02 still slides 65 mm, zeta = 0.05 1.3 mm, 0.1 1.0 mm; mu = 0.3 and mu = 0 then
slide within 0.05 % of a t^2 / 2 at h = 0.05 and 0.1 m.

Each
vertex force goes to its body's nodes (eq 2.52) with the weights N_i m_i^b / W_v (they sum
to one; mass weighting gives every node the same acceleration, so nodes with little mass at
the body's edge do not blow up) as external nodal force, F^cont of eq 2.53.

Initial state (PenaltyContact.preload, at the first step). A penalty spring carries force
only once it is compressed, so a body that starts with a stress in equilibrium with a
contact traction (e.g. a geostatic block on a base) would find its contact face unsupported
at t = 0: the face falls into the springs, the release sends a stress wave of the size of
the static stress through the body, the normal force oscillates by tens of per cent and
every dip below |f_t|/mu lets the face slip a little, always down the slope (a block that
must stick on a 30 deg rigid incline with mu = 0.7 crept 13.7 mm in 0.5 s, 2.2 % of the
frictionless slide; with a gravity ramp from a stress-free state, 0.04 %). So the springs
start in equilibrium with the stress: the traction t = sigma n at each vertex of a
deformable body is taken from its particles' stress (a least-squares linear fit over those
within 1.5 h, extrapolated to the vertex, so a linear stress is exact on the boundary); for
each vertex s touching a facing segment of another body (g_n < 1e-6 h), with t_s the
traction on the slave's body (minus the master's, interpolated at xi, when the slave is
rigid), p = t_s . e_n > 0 and tau = t_s . e_t,
    f_t^old = w l_s tau (capped at mu w l_s p),
    x_s -= (p / k_n + g_n) e_n   (deformable slave; half of it when the master is deformable),
i.e. the vertices start at the penetration g_n = -p / k_n whose penalty force carries p (in
both passes, as the other body's vertices then see the same penetration) and the slip spring
holds the shear. A shift of p / k_n is the penetration the penalty allows anyway (here
0.06 mm against h = 0.1 m). Stress-free bodies, and bodies that do not touch at the start,
are unchanged (t = 0 or no pair).

MPI. The polylines are replicated on every rank (O(surface) memory and work per rank). Each
vertex is owned by one rank (the highest rank that has it in an owned cell); the owner
interpolates W_v and v_v and evaluates the pairs of its slave vertices; allreduces sum W_v,
the vertex forces and the vertex displacements, and each rank maps the forces of its own
vertices, so nothing is counted twice (grid.accumulate then sums the nodal forces).

Stability. The springs of the vertices along a cell edge give a surface node k ~ k_n h
against a (reduced) surface mass m ~ rho h^2 / 4 per unit thickness, so
    dt <= 2 sqrt(m / k) = sqrt(rho_min h / k_n);
k_n = (K + 4G/3)/h of the stiffer body makes this the elastic wave limit h / c_p. A step
above it is warned about (RuntimeWarning).

Axisymmetric grids (x = (r, z)): nodal forces are per radian, so each vertex stands for the
ring of area l_s r_s per radian: l_s is replaced by l_s r_s in every force above (normal,
tangential, dashpot, preload); a vertex on the axis carries none, and no vertex crosses it
(r = max(r, 0) after every move: one that drifted to r = -7e-9 left the grid, lost its weight
and froze, and its segment dropped out of the detection; demos/pile_driving.py --contact
penalty).

Checkpoints keep the polyline state (positions, last displacements, tangential forces:
ExplicitContact.checkpoint_state). Not yet: 3D (surfaces)."""
import math
import warnings

import numpy as np
from numba import njit

from ..shapes import standard as ks

__all__ = ["circle", "rectangle", "line", "PenaltyContact", "DAMPING"]

DAMPING = 0.1     # default ratio of the normal dashpot to critical (module docstring)


# ---------------------------------------------------------------------------- polylines
def circle(centre, radius, n):
    """n vertices on a circle, counter-clockwise (a closed polyline of a disc)."""
    if not (isinstance(n, (int, np.integer)) and n >= 3 and radius > 0):
        raise ValueError(f"circle: need n >= 3 and radius > 0, got n={n!r}, radius={radius!r}")
    a = 2.0 * np.pi * np.arange(n) / n
    return np.asarray(centre, dtype=np.float64) + radius * np.column_stack([np.cos(a), np.sin(a)])


def line(a, b, n):
    """n + 1 equally spaced vertices from a to b (an open polyline; the body lies on the left
    of a -> b)."""
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise ValueError(f"line: 'n' must be an integer >= 1, got {n!r}")
    s = np.linspace(0.0, 1.0, n + 1)[:, None]
    return (1.0 - s) * np.asarray(a, dtype=np.float64) + s * np.asarray(b, dtype=np.float64)


def rectangle(lo, hi, spacing):
    """The boundary of the box [lo, hi], counter-clockwise, vertices about `spacing` apart
    (a closed polyline)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if not (np.all(hi > lo) and spacing > 0):
        raise ValueError(f"rectangle: need hi > lo and spacing > 0, got {lo}, {hi}, {spacing!r}")
    nx, ny = (max(1, int(math.ceil(v / spacing))) for v in hi - lo)
    c = [lo, (hi[0], lo[1]), hi, (lo[0], hi[1]), lo]
    n = [nx, ny, nx, ny]
    return np.concatenate([line(c[k], c[k + 1], n[k])[:-1] for k in range(4)])


def check_polyline(vertices, closed):
    """Validated float64 (n, 2) vertices (closed ones counter-clockwise)."""
    x = np.array(vertices, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 2:
        raise ValueError(f"add_polyline: vertices must be an (n, 2) array (2D meshes), got shape "
                         f"{x.shape}")
    if len(x) < (3 if closed else 2) or not np.all(np.isfinite(x)):
        raise ValueError(f"add_polyline: need {3 if closed else 2} or more finite vertices")
    seg = np.diff(np.vstack([x, x[:1]]) if closed else x, axis=0)
    if np.any(np.linalg.norm(seg, axis=1) == 0):
        raise ValueError("add_polyline: repeated vertices (zero-length segment)")
    if closed:
        area = 0.5 * np.sum(x[:, 0] * np.roll(x[:, 1], -1) - np.roll(x[:, 0], -1) * x[:, 1])
        if area == 0:
            raise ValueError("add_polyline: a closed polyline must enclose an area")
        if area < 0:
            x = x[::-1].copy()
    return x


# ---------------------------------------------------------------------------- kernels
@njit(cache=True)
def tributary(x, seg, out, nrm):
    """out[v] = half the length of the segments at v, nrm[v] = the unit mean outward normal
    of those segments; returns the largest segment length."""
    lmax = 0.0
    for s in range(seg.shape[0]):
        i, j = seg[s, 0], seg[s, 1]
        tx, ty = x[j, 0] - x[i, 0], x[j, 1] - x[i, 1]
        L = np.sqrt(tx * tx + ty * ty)
        for v in (i, j):
            out[v] += 0.5 * L
            nrm[v, 0] += ty / L
            nrm[v, 1] -= tx / L
        lmax = max(lmax, L)
    for v in range(x.shape[0]):
        n = np.sqrt(nrm[v, 0] ** 2 + nrm[v, 1] ** 2)
        if n > 0.0:
            nrm[v, 0] /= n
            nrm[v, 1] /= n
    return lmax


@njit(cache=True)
def bin_segments(x, seg, lo, w, nbx, nby):
    """Segments sorted into bins of size w by their midpoints (CSR: start, items)."""
    ns = seg.shape[0]
    key = np.empty(ns, dtype=np.int64)
    start = np.zeros(nbx * nby + 1, dtype=np.int64)
    for s in range(ns):
        i, j = seg[s, 0], seg[s, 1]
        bx = int((0.5 * (x[i, 0] + x[j, 0]) - lo[0]) / w)
        by = int((0.5 * (x[i, 1] + x[j, 1]) - lo[1]) / w)
        key[s] = bx * nby + by
        start[key[s] + 1] += 1
    for k in range(nbx * nby):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    items = np.empty(ns, dtype=np.int64)
    for s in range(ns):
        items[fill[key[s]]] = s
        fill[key[s]] += 1
    return start, items


@njit(cache=True)
def vertex_weights(own, nodes, N, vbody, present, m_b, W):
    """W[v] = sum_i N_i(x_v) m_i^b over the nodes where body b = vbody[v] is present."""
    for r in range(own.shape[0]):
        v = own[r]
        b = vbody[v]
        w = 0.0
        for a in range(nodes.shape[1]):
            i = nodes[r, a]
            if present[i, b]:
                w += N[r, a] * m_b[i, b]
        W[v] = w


@njit(cache=True)
def vertex_velocity(own, nodes, N, vbody, present, m_b, W, v_b, out):
    """out[v] = sum_i N_i m_i^b v_i^b / W_v (module docstring)."""
    d = out.shape[1]
    for r in range(own.shape[0]):
        v = own[r]
        b = vbody[v]
        if W[v] <= 0.0:
            continue
        for a in range(nodes.shape[1]):
            i = nodes[r, a]
            if present[i, b]:
                c = N[r, a] * m_b[i, b] / W[v]
                for k in range(d):
                    out[v, k] += c * v_b[i, b, k]


@njit(cache=True)
def map_vertex_forces(own, nodes, N, vbody, present, m_b, W, rigid, F, out):
    """out[i, b] += N_i m_i^b F_v / W_v for the owned vertices v of deformable bodies (eq 2.52)."""
    d = F.shape[1]
    for r in range(own.shape[0]):
        v = own[r]
        b = vbody[v]
        if rigid[b] or W[v] <= 0.0:
            continue
        for a in range(nodes.shape[1]):
            i = nodes[r, a]
            if present[i, b]:
                c = N[r, a] * m_b[i, b] / W[v]
                for k in range(d):
                    out[i, b, k] += c * F[v, k]


@njit(cache=True)
def nearest_segment(s, x, vbody, seg, sbody, vn, W, rigid, lo, w, nbx, nby, start, items, depth):
    """Steps 2-3 of the detection (module docstring) for vertex s: (segment, g_n, xi) of the
    other bodies' segment of least |g_n| <= depth that faces s, with xi in [0, 1]; segment -1
    if none."""
    a = vbody[s]
    bx = int((x[s, 0] - lo[0]) / w)
    by = int((x[s, 1] - lo[1]) / w)
    best, gbest, xbest = -1, 0.0, 0.0
    for ix in range(max(bx - 1, 0), min(bx + 2, nbx)):      # step 2: nearby segments
        for iy in range(max(by - 1, 0), min(by + 2, nby)):
            key = ix * nby + iy
            for e in range(start[key], start[key + 1]):
                sg = items[e]
                b = sbody[sg]
                if b == a:
                    continue
                i1, i2 = seg[sg, 0], seg[sg, 1]
                if not rigid[b] and (W[i1] <= 0.0 or W[i2] <= 0.0):
                    continue
                tx, ty = x[i2, 0] - x[i1, 0], x[i2, 1] - x[i1, 1]
                L = np.sqrt(tx * tx + ty * ty)
                tx /= L
                ty /= L
                rx, ry = x[s, 0] - x[i1, 0], x[s, 1] - x[i1, 1]
                xi = (rx * tx + ry * ty) / L          # eq 2.43
                g = rx * ty - ry * tx                 # eq 2.42, e_n = (t_y, -t_x)
                if (xi < 0.0 or xi > 1.0 or abs(g) > depth
                        or ty * vn[s, 0] - tx * vn[s, 1] > -0.5):  # not facing the slave
                    continue
                if best < 0 or abs(g) < abs(gbest):
                    best, gbest, xbest = sg, g, xi
    return best, gbest, xbest


@njit(cache=True)
def penalty_pairs(own, nodes, present, x, du, vbody, seg, sbody, ltrib, vn, W, rigid, lo, w, nbx,
                  nby, start, items, k_n, k_t, mu, depth, ft_old, F, ft_new, stats, c_n, dt):
    """Detection and forces of the module docstring for the owned slave vertices `own`
    (nodes: their cells' nodes; c_n the normal dashpot, dt the step of du): F (vertex forces, slave and segment ends) and ft_new (the
    slaves' tangential force) are added to; stats[0] += pairs, stats[1] = max penetration,
    stats[2] += slipping pairs."""
    nb = present.shape[1]
    wt = 0.5                                          # two-pass weight
    for r in range(own.shape[0]):
        s = own[r]
        a = vbody[s]
        if W[s] <= 0.0 and not rigid[a]:
            continue
        shared = False                                # step 1: a node with >= 2 bodies
        for q in range(nodes.shape[1]):
            cnt = 0
            for b in range(nb):
                if present[nodes[r, q], b]:
                    cnt += 1
            if cnt >= 2:
                shared = True
                break
        if not shared:
            continue
        best, gbest, xbest = nearest_segment(s, x, vbody, seg, sbody, vn, W, rigid, lo, w, nbx,
                                             nby, start, items, depth)
        if best < 0 or gbest >= 0.0:                  # step 3: eq 2.51
            continue
        b = sbody[best]
        i1, i2 = seg[best, 0], seg[best, 1]
        tx, ty = x[i2, 0] - x[i1, 0], x[i2, 1] - x[i1, 1]
        L = np.sqrt(tx * tx + ty * ty)
        tx /= L
        ty /= L
        nx, ny = ty, -tx
        xi = xbest
        dx = du[s, 0] - (1.0 - xi) * du[i1, 0] - xi * du[i2, 0]   # relative displacement
        dy = du[s, 1] - (1.0 - xi) * du[i1, 1] - xi * du[i2, 1]   # over the last step
        fn = max(wt * ltrib[s] * (k_n * (-gbest) - c_n * (dx * nx + dy * ny) / dt), 0.0)
        dgt = dx * tx + dy * ty
        ft = ft_old[s] - wt * k_t * ltrib[s] * dgt
        cap = mu[a, b] * fn
        if abs(ft) > cap:
            ft = cap if ft > 0.0 else -cap
            stats[2] += 1.0
        ft_new[s] = ft
        fx, fy = fn * nx + ft * tx, fn * ny + ft * ty
        F[s, 0] += fx
        F[s, 1] += fy
        F[i1, 0] -= (1.0 - xi) * fx
        F[i1, 1] -= (1.0 - xi) * fy
        F[i2, 0] -= xi * fx
        F[i2, 1] -= xi * fy
        stats[0] += 1.0
        stats[1] = max(stats[1], -gbest)


# ---------------------------------------------------------------------------- driver
class PenaltyContact:
    """State and per-step work of penalty contact for fm.ExplicitContact: the replicated
    polylines (vertices x, bodies, segments), the vertices' last displacement du and the
    slaves' tangential force ft (module docstring)."""

    def __init__(self, k_n, k_t, polylines, damping=DAMPING):
        self.k_n, self.k_t, self.damping = k_n, k_t, damping
        xs, vb, segs, off = [], [], [], 0
        for body, x, closed in polylines:
            n = len(x)
            i = np.arange(off, off + n)
            segs.append(np.column_stack([i, np.roll(i, -1)]) if closed else
                        np.column_stack([i[:-1], i[1:]]))
            xs.append(x)
            vb.append(np.full(n, body, dtype=np.int32))
            off += n
        self.x = np.ascontiguousarray(np.concatenate(xs))
        self.vbody = np.concatenate(vb)
        self.seg = np.ascontiguousarray(np.concatenate(segs).astype(np.int64))
        self.sbody = np.ascontiguousarray(self.vbody[self.seg[:, 0]])
        self.du = np.zeros_like(self.x)
        self.ft = np.zeros(len(self.x))
        self.stats = dict(pairs=0, max_penetration=0.0, slipping=0, idle_vertices=0)
        self._warned_dt = False
        self._preloaded = False

    def c_n(self, sim):
        """The normal dashpot c_n = 2 zeta sqrt(k_n rho_min h / 2) (module docstring,
        "Normal damping"), in force per unit length per unit approach speed."""
        rho = min(m.density for m in sim.particles.materials)
        return 2.0 * self.damping * math.sqrt(self.k_n * rho * sim.grid.h / 2.0)

    def _allreduce(self, comm, a, op=None):
        if comm.size == 1:
            return a
        from mpi4py import MPI
        out = np.empty_like(a)
        comm.Allreduce(a, out, op=op or MPI.SUM)
        return out

    def check_dt(self, sim):
        """Warn once when dt exceeds sqrt(rho_min h / k_n) (module docstring)."""
        rho = min(m.density for m in sim.particles.materials)
        self.dt_penalty = math.sqrt(rho * sim.grid.h / self.k_n)
        if sim.dt > self.dt_penalty and not self._warned_dt:
            self._warned_dt = True
            if sim.comm.rank == 0:
                warnings.warn(f"ExplicitContact(penalty): dt = {sim.dt:.4g} s exceeds the penalty "
                              f"spring's stable step sqrt(rho h / k_n) = {self.dt_penalty:.4g} s; "
                              f"lower k_n (about (K + 4G/3)/h) or dt", RuntimeWarning, stacklevel=3)

    def boundary_traction(self, sim, rigid, vn):
        """t_v = sigma(x_v) n_v (n_v the vertex's outward normal) at the vertices of the
        deformable bodies, sigma the body's particle stress (the one the internal force sees)
        extrapolated to x_v by a least-squares linear fit over its particles within 1.5 h
        (the mean where they are too few for a fit); 0 at rigid vertices and where no particle
        of the body is near. Summed over ranks."""
        from scipy.spatial import cKDTree
        from .multi_velocity import body_ids
        p, h = sim.particles, sim.grid.h
        nvx = len(self.x)
        acc = np.zeros((nvx, 3, 6))                   # sum w [1 dx dy]^T [1 dx dy | sxx syy sxy]
        sig = sim.dynamic_stress(p.stress)
        for b in np.unique(self.vbody):
            if rigid[b]:
                continue
            sel = np.flatnonzero(body_ids(p) == b)
            verts = np.flatnonzero(self.vbody == b)
            if len(sel) == 0:
                continue
            tree = cKDTree(p.x[sel, :2])
            for v, near in zip(verts, tree.query_ball_point(self.x[verts], 1.5 * h)):
                if not near:
                    continue
                q = sel[near]
                P = np.column_stack([np.ones(len(q)), (p.x[q, :2] - self.x[v]) / h])
                S = np.column_stack([sig[q, 0, 0], sig[q, 1, 1], sig[q, 0, 1]])
                acc[v, :, :3] = P.T @ P
                acc[v, :, 3:] = P.T @ S
        acc = self._allreduce(sim.comm, acc)
        t = np.zeros_like(self.x)
        for v in np.flatnonzero(acc[:, 0, 0] > 0):
            A, B = acc[v, :, :3], acc[v, :, 3:]
            if np.linalg.cond(A) < 1e6:
                c = np.linalg.solve(A, B)[0]          # the fit's value at x_v
            else:
                c = B[0] / A[0, 0]                    # the mean
            s2 = np.array([[c[0], c[2]], [c[2], c[1]]])
            t[v] = s2 @ vn[v]
        return t

    def preload(self, sim, rigid, mu, ltrib, vn, W, lo, w, nbx, nby, start, items, depth):
        """Start the penalty springs in equilibrium with the bodies' initial stress (module
        docstring, "Initial state"): for each vertex s touching a facing segment of another
        body (g_n < 1e-6 h), with t the traction on the slave's body there (its own
        boundary_traction, or minus the master's interpolated when the slave is rigid),
        p = t . e_n and tau = t . e_t: f_t^old = w l_s tau (capped at mu p), and the
        deformable vertices are moved along -e_n so that g_n = -p / k_n (half each when both
        bodies are deformable), the penetration whose penalty force carries p. Every rank does
        the same work on the replicated polylines."""
        t = self.boundary_traction(sim, rigid, vn)
        wt = 0.5
        shift = np.zeros_like(self.x)
        ft0 = np.zeros(len(self.x))
        for s in range(len(self.x)):
            best, g, xi = nearest_segment(s, self.x, self.vbody, self.seg, self.sbody, vn, W, rigid,
                                          lo, w, nbx, nby, start, items, depth)
            if best < 0 or g >= 1e-6 * sim.grid.h:
                continue
            a, b = self.vbody[s], self.sbody[best]
            i1, i2 = self.seg[best]
            et = self.x[i2] - self.x[i1]
            et /= np.linalg.norm(et)
            en = np.array([et[1], -et[0]])
            if rigid[a] and rigid[b]:
                continue
            ts = -((1.0 - xi) * t[i1] + xi * t[i2]) if rigid[a] else t[s]
            pn, tau = float(ts @ en), float(ts @ et)
            if pn <= 0.0:
                continue
            cap = mu[a, b] * pn
            ft0[s] = wt * ltrib[s] * float(np.clip(tau, -cap, cap))
            if not rigid[a]:
                shift[s] -= (pn / self.k_n + g) * (1.0 if rigid[b] else 0.5) * en
        self.x += shift
        self._clamp_at_axis(sim)
        self.ft = ft0

    def forces(self, sim, present, m_b, rigid, mu, dt):
        """Locate the vertices, find the pairs and return the nodal contact forces
        (n_nodes, nb, 2), summed over ranks; sets self.body_force (nb, 2)."""
        grid, comm = sim.grid, sim.comm
        self.check_dt(sim)
        cells, xi = grid.locate(self.x)
        mine = (cells >= 0) & (cells < grid.n_owned_cells)
        if comm.size > 1:
            from mpi4py import MPI
            claim = self._allreduce(comm, np.where(mine, comm.rank, -1).astype(np.int32), MPI.MAX)
            mine = claim == comm.rank
        own = np.flatnonzero(mine)
        nv = grid.cell_nodes.shape[1]
        self._own = own
        self._nodes = np.empty((len(own), nv), dtype=np.int32)
        self._N = np.empty((len(own), nv))
        ks.mpm_shape(grid.D, grid.kind, cells[own], np.ascontiguousarray(xi[own]), grid.cell_nodes,
                     grid.node_x, grid.simplex_grad, grid.affine_Jinv, self._nodes, self._N,
                     np.empty((len(own), nv, grid.gdim)))
        W = np.zeros(len(self.x))
        vertex_weights(own, self._nodes, self._N, self.vbody, present, m_b, W)
        self.W = W = self._allreduce(comm, W)
        for rep in range(1 if self._preloaded else 2):
            ltrib = np.zeros(len(self.x))
            vn = np.zeros_like(self.x)
            lmax = tributary(self.x, self.seg, ltrib, vn)
            if grid.axisymmetric:                     # per radian: the ring's area l_s r_s
                ltrib *= np.abs(self.x[:, 0])
            depth = grid.h
            w = depth + 0.5 * lmax
            lo = self.x.min(axis=0) - w
            nbx, nby = (int(v) for v in (self.x.max(axis=0) - lo) // w + 2)
            start, items = bin_segments(self.x, self.seg, lo, w, nbx, nby)
            if not self._preloaded:           # the springs in equilibrium with the stress
                self._preloaded = True
                self.preload(sim, rigid, mu, ltrib, vn, W, lo, w, nbx, nby, start, items, depth)
        nvx = len(self.x)
        buf = np.zeros(3 * nvx + 3)                   # F (nv, 2), ft, stats
        F, ft, stats = buf[: 2 * nvx].reshape(nvx, 2), buf[2 * nvx: 3 * nvx], buf[3 * nvx:]
        penalty_pairs(own, self._nodes, present, self.x, self.du, self.vbody, self.seg, self.sbody,
                      ltrib, vn, W, rigid, lo, w, nbx, nby, start, items, self.k_n, self.k_t, mu,
                      depth, self.ft, F, ft, stats, self.c_n(sim), dt)
        pen = stats[1]
        buf = self._allreduce(comm, buf)
        F, self.ft = buf[: 2 * nvx].reshape(nvx, 2), buf[2 * nvx: 3 * nvx].copy()
        if comm.size > 1:
            from mpi4py import MPI
            pen = comm.allreduce(pen, op=MPI.MAX)
        self.stats = dict(pairs=int(buf[-3]), max_penetration=pen, slipping=int(buf[-1]),
                          idle_vertices=int(np.count_nonzero(W <= 0.0)))
        nb = m_b.shape[1]
        self.body_force = np.stack([np.bincount(self.vbody, F[:, k], minlength=nb)
                                    for k in range(2)], axis=1)
        out = np.zeros((grid.n_nodes, nb, 2))
        map_vertex_forces(own, self._nodes, self._N, self.vbody, present, m_b, W, rigid,
                          np.ascontiguousarray(F), out)
        grid.accumulate(out.reshape(grid.n_nodes, -1))
        return out

    def move(self, sim, present, m_b, v_b, rigid, v_rigid, dt):
        """x_v += dt v_v with the end-of-step nodal velocities v_b (rigid bodies: v_rigid)."""
        v = np.zeros_like(self.x)
        vertex_velocity(self._own, self._nodes, self._N, self.vbody, present, m_b, self.W, v_b, v)
        v = self._allreduce(sim.comm, v)
        r = rigid[self.vbody]
        v[r] = v_rigid[self.vbody[r]]
        self.du = dt * v
        self.x += self.du
        self._clamp_at_axis(sim)

    def _clamp_at_axis(self, sim):
        """On an axisymmetric grid no vertex crosses the axis: r = max(r, 0) (a vertex on the
        axis moves with a radial velocity of round-off size, and at r < 0 it would leave the
        grid, lose its weight W_v and stop moving)."""
        if sim.grid.axisymmetric:
            np.maximum(self.x[:, 0], 0.0, out=self.x[:, 0])
