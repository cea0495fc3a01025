"""GIMP shape functions (uGIMP and cpGIMP) on structured quadrilateral/hexahedral grids.

A particle p of half-widths l_p,k (one per axis) is a box; its weight at node i is the
average of the node's hat function N_i over the box, and its gradient the average of grad N_i
(Bardenhagen & Kober 2004):
    S_ip = (1/V_p) int_{Omega_p} N_i dx,      grad S_ip = (1/V_p) int_{Omega_p} grad N_i dx.
On a lattice of spacing L_k both are tensor products of 1D factors. With Phi the
antiderivative of the 1D hat N(s) = max(0, 1 - |s|/L), and the box [a, b] = [x_p - l_p, x_p + l_p]
along one axis,
    S(xi) = (Phi(b - x_i) - Phi(a - x_i)) / (b - a),  dS = (N(b - x_i) - N(a - x_i)) / (b - a),
which for l_p <= L/2 is exactly the piecewise weight of seeds 000 eq 2.48 / 002 eq 3.14 as
corrected in BENCHMARKS.md ("GIMP weight"), with xi = x_p - x_i:
    (L + l_p + xi)^2 / (4 L l_p)         -L - l_p < xi <= -L + l_p
    1 + xi / L                           -L + l_p < xi <= -l_p
    1 - (xi^2 + l_p^2) / (2 L l_p)        |xi| <= l_p
    1 - xi / L                            l_p < xi <= L - l_p
    (L + l_p - xi)^2 / (4 L l_p)          L - l_p < xi <= L + l_p,   0 beyond,
and stays valid for l_p > L/2 (stretched cpGIMP particles). A cpGIMP box never reaches past
the grid's boundary: its half-width is capped at the particle's distance to it (since
2026-12-06), so the weights still sum to 1, the gradients to 0, and the velocity a particle
takes from the grid vanishes at a held wall as with the standard family. Cutting the box at
the boundary instead (before; uGIMP boxes still are) left a particle at the wall with about
half the velocity of the node row above it: stretched particles of the softening slope
(problems.softening_slope, cpGIMP, H/32 and H/64) were carried out through its rough base.
The cap lives in `half_width`, which every user of the box shares: the shape evaluation, the
implicit stiffness pattern (half_widths) and DM-GC's cell integrals
(integrators.dmgc, half_widths).

uGIMP keeps l_p = l_p^0; cpGIMP (contiguous particle GIMP, Wallstedt & Guilkey 2008) uses
l_p,k = min(l_p,k^0 |F_kk|, L_k) (the box follows the stretch along each axis, up to one cell
each side: a box then reaches only the nodes of the cells next to the particle's, which one
ghost-cell ring holds on every rank, so an extreme stretch (a thinning granular front) gives
the same weights on any partition; past the cap the particle's mass is spread as a box of
one cell's half-width, as uGIMP does for a particle of that size).
"""
import numpy as np
from numba import njit, prange

from ..kernels.axisymmetric import meridian_area
from ..kernels.threads import PRANGE, chunk, particle_chunks
from ..kernels.transfer import pad_row


@njit(cache=True)
def _integral(a, b, L, inv_2L):
    """int_a^b max(0, 1 - |s|/L) ds for a <= b (inv_2L = 1 / 2L): the parts below and above
    s = 0, each from the antiderivative that vanishes at its end of the support ((L + s)^2 / 2L
    below, and -(L - s)^2 / 2L above), so a box overlapping the support by delta << L gets
    delta^2 / 2L and not a difference of two numbers near L (which rounds to 0 while the
    gradient does not, and the weight gradients stop summing to zero)."""
    lo, hi = max(a, -L), min(b, 0.0)
    below = ((L + hi) * (L + hi) - (L + lo) * (L + lo)) * inv_2L if hi > lo else 0.0
    lo, hi = max(a, 0.0), min(b, L)
    above = ((L - lo) * (L - lo) - (L - hi) * (L - hi)) * inv_2L if hi > lo else 0.0
    return below + above


@njit(cache=True)
def _hat(s, L, inv_L):
    return max(0.0, 1.0 - abs(s) * inv_L)


@njit(cache=True)
def _weight(a, b, inv_w, xi_node, L, inv_L, inv_2L):
    """1D GIMP weight S and gradient dS of the node at xi_node for the box [a, b], already
    clipped to the grid (module docstring; inv_w = 1 / (b - a), inv_L = 1 / L, inv_2L = 0.5 / L:
    reciprocals a particle's kernel computes once per axis). A box that overlaps the node's
    support by less than 1e-12 L gets exactly 0 (its weight, below 1e-24, is round-off of a
    box that ends on the support's edge)."""
    if b - xi_node <= -L * (1.0 - 1e-12) or a - xi_node >= L * (1.0 - 1e-12):
        return 0.0, 0.0
    S = _integral(a - xi_node, b - xi_node, L, inv_2L) * inv_w
    dS = (_hat(b - xi_node, L, inv_L) - _hat(a - xi_node, L, inv_L)) * inv_w
    return S, dS


@njit(cache=True)
def _closed_weight(dd, L, lp, inv_L, inv_Ll):
    """_weight of an unclipped box of half-width lp <= L / 2 centred at distance dd = x_p -
    x_node from the node, in closed form (Bardenhagen & Kober 2004, eq 40 and its
    derivative; inv_L = 1 / L, inv_Ll = 1 / (L lp)):
        S = 1 - (dd^2 + lp^2) / (2 L lp),  dS = -dd / (L lp)              |dd| < lp
        S = 1 - |dd| / L,                  dS = -sign(dd) / L             lp <= |dd| <= L - lp
        S = t^2 / (4 L lp),                dS = -sign(dd) t / (2 L lp)    t = L + lp - |dd| > 0
    with the same 1e-12 L cut-off of a vanishing overlap as _weight."""
    ad = abs(dd)
    if ad < lp:
        return 1.0 - (dd * dd + lp * lp) * 0.5 * inv_Ll, -dd * inv_Ll
    if ad <= L - lp:
        return 1.0 - ad * inv_L, -inv_L if dd > 0.0 else inv_L
    t = L + lp - ad
    if t <= 1e-12 * L:
        return 0.0, 0.0
    g = 0.5 * t * inv_Ll
    return 0.5 * t * g, -g if dd > 0.0 else g


@njit(cache=True)
def half_width(lp0, Fkk, L, contiguous, xk, lo, hi):
    """The box half-width along one axis at the particle coordinate xk on a grid [lo, hi]:
    lp0 for uGIMP; for cpGIMP (contiguous) min(lp0 |F_kk|, L), and the box stops at the grid
    boundary, min(., xk - lo, hi - xk), floored at 1e-9 L (module docstring)."""
    if not contiguous:
        return lp0
    return max(min(lp0 * abs(Fkk), L, xk - lo, hi - xk), 1e-9 * L)


@njit(cache=True)
def half_widths(lp0, F, x, spacing, lo, hi, contiguous):
    """(n, d) box half-widths of every particle (half_width per axis)."""
    n, d = lp0.shape
    out = np.empty((n, d))
    for p in range(n):
        for k in range(d):
            out[p, k] = half_width(lp0[p, k], F[p, k, k], spacing[k], contiguous, x[p, k],
                                   lo[k], hi[k])
    return out


@njit(cache=True)
def tensor_product(d, nsk, Sk, dSk, off, table, p, keep_gradients,
                   nodes_out, N_out, dN_out, count_out):
    """Write particle p's tensor-product weights into row p of the outputs (shared by the
    lattice families: gimp, bspline; d = 1, 2 or 3). nsk (d,): the lattice nodes looked at
    on each axis; Sk/dSk (d, >= nsk[k]): their 1D weights and derivatives; off: their flat
    lattice offsets (-1: outside the local lattice). Node (a, b, c) has the weight Sx_a Sy_b Sz_c and
    the gradient (dSx_a Sy_b Sz_c, dSy_b Sx_a Sz_c, dSz_c Sx_a Sy_b) (missing axes: factor 1),
    in nested loops, axis 0 fastest. A node of weight 0 is skipped, unless `keep_gradients`
    and one of its gradient components is not 0 (a node whose 1D weight vanishes at the
    particle with a nonzero slope, e.g. the boundary-modified B-spline at the grid boundary).
    Nonzero-weight nodes first (count_out[p] of them, only the first nodes_out.shape[1]
    written), then padding (kernels.transfer.pad_row; the first skipped node pads a row that
    has no other). Returns True when a node of nonzero weight is not a local node."""
    nv = nodes_out.shape[1]
    bad = False
    cnt = 0
    pad = -1
    for c in range(nsk[2] if d == 3 else 1):
        Sz = Sk[2, c] if d == 3 else 1.0
        dSz = dSk[2, c] if d == 3 else 0.0
        oz = off[2, c] if d == 3 else 0
        for b in range(nsk[1] if d >= 2 else 1):
            Sy = Sk[1, b] if d >= 2 else 1.0
            dSy = dSk[1, b] if d >= 2 else 0.0
            oy = off[1, b] if d >= 2 else 0
            oyz = oy + oz if oy >= 0 and oz >= 0 else -1
            for a in range(nsk[0]):
                w = Sk[0, a] * Sy * Sz
                node = table[off[0, a] + oyz] if off[0, a] >= 0 and oyz >= 0 else -1
                if w == 0.0 and not (keep_gradients and (dSk[0, a] * Sy * Sz != 0.0 or
                                                         dSy * Sk[0, a] * Sz != 0.0 or
                                                         dSz * Sk[0, a] * Sy != 0.0)):
                    if node >= 0 and pad < 0:
                        pad = node
                    continue
                if node < 0:
                    bad = True
                    continue
                if cnt < nv:
                    nodes_out[p, cnt] = node
                    N_out[p, cnt] = w
                    dN_out[p, cnt, 0] = dSk[0, a] * Sy * Sz
                    if d >= 2:
                        dN_out[p, cnt, 1] = dSy * Sk[0, a] * Sz
                    if d == 3:
                        dN_out[p, cnt, 2] = dSz * Sk[0, a] * Sy
                cnt += 1
    count_out[p] = cnt
    pad_row(d, p, cnt, pad, nodes_out, N_out, dN_out)
    return bad


@njit(cache=True)
def _gimp(D, x, lp0, F, contiguous, origin, spacing, lo, hi, ilo, nlat, table, ns, p0, p1,
          nodes_out, N_out, dN_out, count_out):
    d = len(D)
    Sk = np.empty((d, ns))
    dSk = np.empty((d, ns))
    off = np.empty((d, ns), dtype=np.int64)     # flat lattice offset of node q on axis k, -1 outside
    nsk = np.empty(d, dtype=np.int64)           # nodes looked at on axis k
    inv_L = 1.0 / spacing
    inv_2L = 0.5 / spacing
    bad = -1
    for p in range(p0, p1):
        stride = 1
        for k in range(d):
            L = spacing[k]
            lp = half_width(lp0[p, k], F[p, k, k], L, contiguous, x[p, k], lo[k], hi[k])
            a = max(x[p, k] - lp, lo[k])
            b = min(x[p, k] + lp, hi[k])
            j0 = int(np.floor((a - origin[k]) / L))     # the last node at or below a ...
            nsk[k] = int(np.ceil((b - origin[k]) / L)) - j0 + 1   # ... to the first at or above b
            if nsk[k] > ns:
                nsk[k] = ns
                bad = p
            closed = lp <= 0.5 * L and a == x[p, k] - lp and b == x[p, k] + lp
            inv_w = 1.0 / (b - a)
            inv_Ll = 1.0 / (L * lp) if closed else 0.0
            for q in range(nsk[k]):
                j = j0 + q
                jl = j - ilo[k]
                off[k, q] = jl * stride if 0 <= jl < nlat[k] else -1
                if closed:
                    S, dS = _closed_weight(x[p, k] - (origin[k] + j * L), L, lp, inv_L[k],
                                           inv_Ll)
                else:
                    S, dS = _weight(a, b, inv_w, origin[k] + j * L, L, inv_L[k], inv_2L[k])
                Sk[k, q] = S
                dSk[k, q] = dS
            stride *= nlat[k]
        if tensor_product(d, nsk, Sk, dSk, off, table, p, False,
                          nodes_out, N_out, dN_out, count_out):
            bad = p
    return bad


@njit(parallel=PRANGE, cache=True)
def gimp_shape(D, x, lp0, F, contiguous, origin, spacing, lo, hi, ilo, nlat, table, ns,
               nodes_out, N_out, dN_out, count_out):
    """GIMP weights of every particle on the lattice nodes its box overlaps.

    x (n, d) positions; lp0 (n, d) initial half-widths; F (n, 3, 3): with `contiguous` the
    half-widths are min(lp0_k |F_kk|, L_k) (cpGIMP), else lp0 (uGIMP). origin/spacing: global lattice
    origin and cell size per axis; lo/hi: the grid's extent (boxes are clipped to it);
    table: local node index of lattice point ilo + j (j < nlat, flat, axis 0 fastest), or
    -1 where the point is not a local node. ns: at least the lattice nodes any box touches
    per axis, ceil(2 l / L) + 2 for the widest box l (a particle looks at the nodes from the
    last one at or below its box's lower end to the first one at or above its upper end).
    Output per particle: the nonzero-weight nodes first (count_out of them), then padding
    (a valid node with N = dN = 0); a particle with more nonzero-weight nodes than the
    outputs have columns gets only the first ones written (count_out says how many it has:
    the caller evaluates again with wider outputs). Returns -1, or the index of a particle
    whose box reaches a node that is not local (the caller raises)."""
    n = x.shape[0]
    nc = particle_chunks(n)
    if nc == 1:
        return _gimp(D, x, lp0, F, contiguous, origin, spacing, lo, hi, ilo, nlat, table, ns,
                     np.int64(0), n, nodes_out, N_out, dN_out, count_out)
    bad = np.empty(nc, dtype=np.int64)
    for c in prange(nc):
        p0, p1 = chunk(n, nc, c)
        bad[c] = _gimp(D, x, lp0, F, contiguous, origin, spacing, lo, hi, ilo, nlat, table, ns,
                       p0, p1, nodes_out, N_out, dN_out, count_out)
    return bad.max()


def lattice(grid, name="GIMP"):
    """Global lattice data of a structured quadrilateral/hexahedral grid for gimp_shape:
    dict(origin, spacing, lo, hi, ilo, nlat, table). Collective (MPI reductions). `name`: the
    family named in the error message.

    Raises ValueError if the grid is not a lattice of equal axis-aligned boxes, one cell each."""
    from mpi4py import MPI
    from . import standard as ks
    comm = grid.comm
    s = grid._structured
    ok = grid.kind == ks.TENSOR and s is not None and s["table"].shape[1] == 1
    spacing = s["spacing"] if ok else np.full(grid.gdim, np.nan)
    if comm.size > 1:
        ok = comm.allreduce(ok, op=MPI.LAND)
        if ok:
            all_sp = comm.allgather(spacing)
            ok = all(np.allclose(sp, spacing, rtol=1e-9, atol=0.0) for sp in all_sp)
    if not ok:
        raise ValueError(f"{name} shape functions need a structured grid of equal axis-aligned "
                         "quadrilaterals/hexahedra (dolfinx create_rectangle/create_box with "
                         "CellType.quadrilateral/hexahedron)")
    lo = grid.node_x.min(axis=0)
    hi = grid.node_x.max(axis=0)
    if comm.size > 1:
        lo = np.min(comm.allgather(lo), axis=0)
        hi = np.max(comm.allgather(hi), axis=0)
    # the spacing over the whole lattice, the same on every rank: one cell's extent carries its
    # coordinates' round-off, which grows with the node index j in origin + j L until a box
    # ending on the grid's edge gets a weight above round-off from the node beyond it
    # (seen: 40 x 160 cells on 2 ranks, L off by 2e-16, a corner particle failed)
    spacing = (hi - lo) / np.maximum(np.round((hi - lo) / spacing), 1.0)
    ij = np.round((grid.node_x - lo) / spacing).astype(np.int64)
    ilo = ij.min(axis=0)
    nlat = ij.max(axis=0) - ilo + 1
    strides = np.cumprod(np.concatenate([[1], nlat[:-1]]))
    table = np.full(int(np.prod(nlat)), -1, dtype=np.int32)
    table[(ij - ilo) @ strides] = np.arange(grid.n_nodes, dtype=np.int32)
    return dict(origin=np.ascontiguousarray(lo), spacing=np.ascontiguousarray(spacing, dtype=float),
                lo=np.ascontiguousarray(lo), hi=np.ascontiguousarray(hi), ilo=ilo,
                nlat=nlat, table=table)


def initial_half_widths(grid, particles, lat):
    """l_p^0 per axis from the particle volume: a box of the cell's aspect ratio and volume
    V0_p, l_k = (L_k / 2) (V0_p / prod L)^(1/d); for Particles.fill with n per direction this
    is L_k / (2 n), the fill spacing. Axisymmetric grids use the meridian area V0 / r0."""
    L = lat["spacing"]
    s = (meridian_area(grid, particles.x - particles.u, particles.V0) / np.prod(L)) ** (1.0 / grid.gdim)
    return np.ascontiguousarray(0.5 * s[:, None] * L[None, :])


class PaddedStencil:
    """Output buffers (nodes, N, dN, count) of a wide shape family, kept between steps with
    the last step's node columns: a family whose particles touch a varying number of nodes
    (GIMP, B-splines, CPDI) writes its padded rows into them without a fresh allocation or a
    compacting copy per step, and evaluates again at full width when a particle touches more
    nodes than last step."""

    def after_step(self, sim, dt):
        """Called by Simulation once a step of dt is accepted: nothing to do unless a family
        moves particle-domain data with the grid (CPDI2's corners)."""

    def _init_buffers(self):
        self._buf = None
        self._nv = 0            # the node columns of the last evaluation (0: none yet)

    def _fill(self, n, d, width, kernel, first=None):
        """kernel(nodes, N, dN, count) -> bad writes n padded rows (at most nodes.shape[1]
        nodes each, count[p] = how many particle p has); columns: the last step's node count
        (usually still right; `first`, if given, on the first call), at most `width`; when a
        particle has more nodes, once more with exactly as many columns as the largest count
        (the kernel counts past its columns). Returns ((nodes, N, dN) cut to the largest
        count, bad)."""
        cap = min(self._nv or first or width, width)
        for _ in range(2):
            if self._buf is None or self._buf[0].shape != (n, cap):
                self._buf = (np.empty((n, cap), dtype=np.int32), np.empty((n, cap)),
                             np.empty((n, cap, d)), np.empty(n, dtype=np.int64))
            nodes, N, dN, count = self._buf
            bad = kernel(nodes, N, dN, count)
            nv = max(int(count.max()) if n else 1, 1)
            if nv <= cap:
                break
            cap = min(nv, width)         # a particle touches more nodes than last step
        self._nv = nv
        if nv == cap:
            return (nodes, N, dN), bad
        return (np.ascontiguousarray(nodes[:, :nv]), np.ascontiguousarray(N[:, :nv]),
                np.ascontiguousarray(dN[:, :nv])), bad


class LatticeShape(PaddedStencil):
    """Shared driver of the lattice families (GimpShape, bspline.BsplineShape). Subclasses set
    `name` and define _window(sim) -> ns (lattice nodes looked at per axis) and
    _kernel(sim, ns, nodes, N, dN, count) -> -1 or the index of a particle reaching a node
    that is not local."""
    name = "lattice"

    def evaluate(self, sim):
        """(nodes, N, dN) of the local particles, nv = the largest number of nodes a particle
        touches (padded)."""
        p, d = sim.particles, sim.gdim
        ns = self._window(sim)
        out, bad = self._fill(len(p), d, ns ** d,
                              lambda nodes, N, dN, count: self._kernel(sim, ns, nodes, N, dN,
                                                                       count),
                              first=(ns - 1) ** d)
        if bad >= 0:
            raise RuntimeError(f"{self.name}: the domain of particle {int(p.id[bad])} at "
                               f"{np.round(p.x[bad], 6).tolist()} reaches grid nodes that are "
                               f"not on this rank; " + _RING_MESSAGE.format(name=self.name))
        return out


class GimpShape(LatticeShape):
    """uGIMP (contiguous=False) or cpGIMP (contiguous=True) shape functions for a Simulation.

    Adds the particle field `gimp_l0` (n, gdim), the initial half-widths (initial_half_widths,
    unless the particles already carry it). Collective at construction."""
    name = "GIMP"

    def __init__(self, sim, contiguous):
        grid, p = sim.grid, sim.particles
        self.lat = lattice(grid)
        if not grid.has_vertex_ring():
            raise ValueError(_RING_MESSAGE.format(name="GIMP"))
        self.contiguous = bool(contiguous)
        if not hasattr(p, "gimp_l0"):
            p.add_field("gimp_l0", (grid.gdim,))[:] = initial_half_widths(grid, p, self.lat)
        self._init_buffers()

    def _window(self, sim):
        """ns of gimp_shape: cpGIMP boxes are at most a cell wide each side (half_width),
        so 4 without a pass over the particles; uGIMP from the widest initial box."""
        p = sim.particles
        ratio = 1.0 if self.contiguous or not len(p) else float(
            (p.gimp_l0 / self.lat["spacing"]).max())
        return int(np.ceil(2.0 * ratio)) + 2

    def _kernel(self, sim, ns, nodes, N, dN, count):
        p, lat = sim.particles, self.lat
        return gimp_shape(sim.grid.D, p.x, p.gimp_l0, p.F, self.contiguous, lat["origin"],
                          lat["spacing"], lat["lo"], lat["hi"], lat["ilo"], lat["nlat"],
                          lat["table"], ns, nodes, N, dN, count)


_RING_MESSAGE = ("{name} shape functions span neighbouring cells, whose nodes must be local: "
                 "in parallel, create the mesh with partitioner="
                 "fenicsmpm.grid.vertex_ghost_partitioner() (the shared-vertex ghost layer; "
                 "dolfinx 0.5 disables GhostMode.shared_vertex) and keep uGIMP particle domains no "
                 "larger than a cell")
