"""Material-point splitting in zones of large deformation (seed 002 §3.4.1, eq 3.25).

Each particle carries its voxel: the current edge vectors E (columns, d x d, pushed forward
by every increment, E <- dF E) and the edges E_ref at its creation or last split. With
F_s = E E_ref^-1 (the seed's F^split) and C = F_s^T F_s, a particle splits in two when
    stretch  sqrt(C_kk) > alpha  or  sqrt(C_kk) < beta      (eq 3.25, F_kk)
    shear    |C_kl| > gamma, k != l                          (eq 3.25, F_kl)
with the seed's alpha = 2, beta = 1/2, gamma = 1. C is the seed's criterion made objective:
it equals the seed's F_kk and F_kl for the seed's pure stretch and simple shear from F_s = I,
but a rigid rotation does not trigger a split (the seed's F_11 < beta would, at 90 degrees).
The voxel is cut across its longest current edge E_k: the children sit at x +- E_k / 4 with
half the mass and volumes, the parent's F, stress and history, the velocity of the parent's
affine field v +- L E_k / 4 (L = sum_i v_i (x) grad N_i of the step just taken, so mass and
momentum are conserved exactly), E_k halved, each its half of the parent's particle domain
(cpGIMP box, CPDI corners or edges: halve_domains), and E_ref reset to the children's E (the seed
resets the triggering component of F^split; resetting all of them keeps F_s objective).
Under MPI new ids continue the global numbering (one exscan and one allreduce per check)."""
import numpy as np
from numba import njit

from .kernels import transfer as kt


@njit(cache=True)
def push_forward_voxels(dF, E):
    """E <- dF E for every particle (the voxel edges follow the deformation)."""
    d = E.shape[1]
    tmp = np.empty((d, d))
    for p in range(E.shape[0]):
        for i in range(d):
            for j in range(d):
                s = 0.0
                for k in range(d):
                    s += dF[p, i, k] * E[p, k, j]
                tmp[i, j] = s
        for i in range(d):
            for j in range(d):
                E[p, i, j] = tmp[i, j]


@njit(cache=True)
def split_directions(E, E_ref, alpha, beta, gamma, out):
    """out[p] = edge k to cut across (the longest), or -1 when eq 3.25 is not met."""
    d = E.shape[1]
    n_split = 0
    for p in range(E.shape[0]):
        Fs = E[p] @ np.linalg.inv(E_ref[p])
        C = Fs.T @ Fs
        hit = False
        for k in range(d):
            lam = np.sqrt(C[k, k])
            if lam > alpha or lam < beta:
                hit = True
            for m in range(d):
                if m != k and abs(C[k, m]) > gamma:
                    hit = True
        out[p] = -1
        if hit:
            best, kbest = -1.0, 0
            for k in range(d):
                length = 0.0
                for i in range(d):
                    length += E[p, i, k] * E[p, i, k]
                if length > best:
                    best, kbest = length, k
            out[p] = kbest
            n_split += 1
    return n_split


@njit(cache=True)
def place_children(parents, edge, x, v, L, E, E_ref, child):
    """Offsets of both children of each parent: parent row becomes child 1 (x + dx), row
    child[q] child 2 (x - dx), dx = E_k / 4, dv = L dx; voxel edge k halved, E_ref = E."""
    d = x.shape[1]
    for q in range(parents.shape[0]):
        p, c, k = parents[q], child[q], edge[q]
        for i in range(d):
            dx = 0.25 * E[p, i, k]
            dv = 0.0
            for j in range(d):
                dv += L[p, i, j] * 0.25 * E[p, j, k]
            x[c, i] = x[p, i] - dx
            v[c, i] = v[p, i] - dv
            x[p, i] += dx
            v[p, i] += dv
        for i in range(d):
            E[p, i, k] *= 0.5
        for i in range(d):
            for j in range(d):
                E[c, i, j] = E[p, i, j]
                E_ref[p, i, j] = E[p, i, j]
                E_ref[c, i, j] = E[p, i, j]


def _corner_pairs(n_corners, d):
    """The ways to halve a CPDI domain of n_corners corners: per candidate, the corner pairs
    (i, j) whose midpoints the cut passes through. Simplices (d + 1 corners): each edge, one
    pair (the cut runs from its midpoint to the opposite vertices); quadrilaterals (corners
    counter-clockwise): the two pairs of opposite edges; hexahedra (corner b0 + 2 b1 + 4 b2):
    the four edges along each reference axis."""
    if n_corners == d + 1:
        return [[(i, j)] for i in range(n_corners) for j in range(i + 1, n_corners)]
    if d == 2:
        return [[(0, 1), (3, 2)], [(0, 3), (1, 2)]]
    return [[(c, c | (1 << m)) for c in range(8) if not c & (1 << m)] for m in range(3)]


def halve_domains(p, parents, child, cut):
    """Give the children of a split their half of the parent's particle domain (the voxel is
    cut across `cut`, (n_parents, d), the parent row keeping the + side as place_children
    does): cpGIMP/uGIMP half-widths `gimp_l0` halved along the grid axis closest to `cut`;
    CPDI2 corners `cpdi_corners` (and CPDI1's simplex offsets `cpdi_t0`, recentred) cut through
    the midpoints of the corner pairs most nearly along `cut` (_corner_pairs: a corner j moves
    to the pair's midpoint in the half of i, and the other way round); CPDI1's and
    Gauss-GIMP's edges `cpdi_r0`: the one most nearly along `cut` (after F) halved. Without
    this both children kept the parent's whole domain with half its mass."""
    if len(parents) == 0:
        return
    if hasattr(p, "gimp_l0"):
        axis = np.argmax(np.abs(cut), axis=1)
        p.gimp_l0[parents, axis] *= 0.5
        p.gimp_l0[child] = p.gimp_l0[parents]
    d = cut.shape[1]
    F = p.F[parents][:, :d, :d]
    if hasattr(p, "cpdi_corners"):                            # CPDI2: current corners
        _cut_corners(p.cpdi_corners, p.cpdi_corners[parents], parents, child, cut, False)
    if hasattr(p, "cpdi_t0"):                                 # CPDI1 simplices: offsets F t0
        _cut_corners(p.cpdi_t0, p.cpdi_t0[parents], parents, child, cut, True,
                     np.einsum("nij,nkj->nki", F, p.cpdi_t0[parents]))
    if hasattr(p, "cpdi_r0"):                                 # CPDI1 / Gauss-GIMP edges F r0_k
        e = np.einsum("nij,nkj->nki", F, p.cpdi_r0[parents])
        k = np.argmax(np.abs(np.einsum("nkd,nd->nk", e, cut)) / np.linalg.norm(e, axis=2), axis=1)
        p.cpdi_r0[parents, k] *= 0.5
        p.cpdi_r0[child] = p.cpdi_r0[parents]


def _cut_corners(field, c, parents, child, cut, recentre, current=None):
    """Cut the domains of corners c (n, k, d) in two (halve_domains) and write the + half to
    the parents' rows of `field`, the other to the children's; the cut is chosen on the
    `current` corners (default c). recentre: store each half as offsets from its centroid
    (CPDI1's cpdi_t0)."""
    cur = c if current is None else current
    cands = _corner_pairs(c.shape[1], c.shape[2])
    align = np.stack([sum(np.abs(np.einsum("nd,nd->n", cur[:, j] - cur[:, i], cut))
                          for i, j in pairs) /
                      sum(np.linalg.norm(cur[:, j] - cur[:, i], axis=1) for i, j in pairs)
                      for pairs in cands], axis=1)
    best = np.argmax(align, axis=1)
    lo, hi = c.copy(), c.copy()
    lo_c, hi_c = cur.copy(), cur.copy()
    for b, pairs in enumerate(cands):
        sel = best == b
        for i, j in pairs:
            lo[sel, j] = hi[sel, i] = 0.5 * (c[sel, i] + c[sel, j])     # lo: the half of i
            lo_c[sel, j] = hi_c[sel, i] = 0.5 * (cur[sel, i] + cur[sel, j])
    plus = np.einsum("nd,nd->n", hi_c.mean(axis=1) - lo_c.mean(axis=1), cut) > 0.0
    if recentre:
        lo -= lo.mean(axis=1, keepdims=True)
        hi -= hi.mean(axis=1, keepdims=True)
    field[parents] = np.where(plus[:, None, None], hi, lo)
    field[child] = np.where(plus[:, None, None], lo, hi)


class Splitting:
    """Splitting of `sim`'s particles by eq 3.25, checked every `every` steps (see module)."""

    def __init__(self, sim, alpha=2.0, beta=0.5, gamma=1.0, every=1):
        for name, val in (("alpha", alpha), ("beta", beta), ("gamma", gamma)):
            if not (isinstance(val, (int, float)) and np.isfinite(val) and val > 0):
                raise ValueError(f"enable_splitting: '{name}' must be a finite number > 0, got {val!r}")
        if not alpha > 1.0 > beta:
            raise ValueError(f"enable_splitting: need alpha > 1 > beta, got alpha={alpha}, beta={beta}")
        if not (isinstance(every, (int, np.integer)) and every >= 1):
            raise ValueError(f"enable_splitting: 'every' must be a positive integer, got {every!r}")
        self.alpha, self.beta, self.gamma, self.every = float(alpha), float(beta), float(gamma), int(every)
        p, d = sim.particles, sim.gdim
        fresh = not hasattr(p, "voxel")
        E = p.add_field("voxel", (d, d))
        E_ref = p.add_field("voxel_ref", (d, d))
        if fresh:                       # square voxels of the particle volume, axis-aligned
            side = p.V ** (1.0 / d)
            E[:] = side[:, None, None] * np.eye(d)
            E_ref[:] = E
        self.count = 0                  # particles split so far (global)
        self.sync_ids(sim)

    def sync_ids(self, sim):
        """New ids continue after the largest id present (collective; after a restore too)."""
        comm, top = sim.comm, int(sim.particles.id.max(initial=-1))
        self.next_id = (comm.allreduce(top, op=_max()) if comm.size > 1 else top) + 1

    def push_forward(self, sim, dF):
        push_forward_voxels(dF, sim.particles.voxel)

    def apply(self, sim):
        """Split the particles meeting eq 3.25 (collective); returns the global count."""
        if sim.step_count % self.every:
            return 0
        p, comm = sim.particles, sim.comm
        edge = np.empty(len(p), dtype=np.int64)
        n_local = split_directions(p.voxel, p.voxel_ref, self.alpha, self.beta, self.gamma, edge)
        start, total = 0, n_local
        if comm.size > 1:
            start = comm.exscan(n_local) or 0
            total = comm.allreduce(n_local)
        if total == 0:
            return 0
        parents = np.flatnonzero(edge >= 0)
        n = len(p)
        child = np.arange(n, n + len(parents), dtype=np.int64)
        L = np.empty((n, 3, 3))
        kt.incremental_F(sim.grid.D, sim.nodes, sim.dN, sim.nodal["velocity"], 1.0, L)
        L -= np.eye(3)
        for name in p.field_names():                  # children start as copies of parents
            a = getattr(p, name)
            setattr(p, name, np.ascontiguousarray(np.concatenate([a, a[parents]])))
        for name in ("mass", "V", "V0", "work"):
            a = getattr(p, name)
            a[parents] *= 0.5
            a[child] = a[parents]
        L = np.concatenate([L, L[parents]])
        cut = p.voxel[parents, :, edge[parents]]              # the voxel edge cut across
        place_children(parents, edge[parents], p.x, p.v, L, p.voxel, p.voxel_ref, child)
        halve_domains(p, parents, child, cut)
        p.id[child] = self.next_id + start + np.arange(len(parents))
        self.next_id += total
        self.count += total
        p.version += 1
        sim._n_alloc = -1
        return total


def _max():
    from mpi4py import MPI
    return MPI.MAX
