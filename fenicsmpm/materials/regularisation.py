"""Nonlocal regularisation of the softening variable of MohrCoulomb and VonMises (issue 19).

Without a length scale a softening law localises into one cell: the band width, the
dissipated energy and the post-peak response depend on h.  Here the variable that drives
softening, the accumulated plastic (deviatoric) strain kappa (VonMises: eps_p, MohrCoulomb:
eps_d^p, state column 0, still the local value), is replaced in the strength law by the
over-nonlocal value

    kappa_bar_p = (1 - m) kappa_p + m <kappa>_p,
    <kappa>_p   = sum_q w(r_pq) V_q kappa_q / sum_q w(r_pq) V_q,
    w(r)        = r / l^2 exp(-(r / l)^2),                       r_pq = |x_p - x_q| < 3 l,

over the particles q of the same material: the weight of Galavi & Schweiger (2010, Int. J.
Geomech. 10(1)), which vanishes at r = 0, and the over-nonlocal combination (Vermeer &
Brinkgreve 1994) that they use, with m > 1 (`nonlocal_m`, default 2) and the internal length
l (`nonlocal_length`).  Why this form and not the plain nonlocal average (m = 1) of the
plastic strain that Burghardt, Brannon & Guilkey (2012) use in MPM: with m = 1 the averaged
variable is smooth but the local plastic strain feeding it can still concentrate in one row
of points (Jirasek & Rolshoven 2003 discuss this for integral nonlocal plasticity), while
with m > 1 a point that has strained more than its neighbourhood becomes relatively
stronger, so plastic flow spreads over a zone of width ~ l; and the local part (1 - m) kappa_p
gives the step a hardening local tangent (below).  kappa_bar is not clipped: where a point
has strained much more than its neighbourhood it is < 0 and the strength exceeds the peak
(VonMises: c = c_u + H kappa_bar; MohrCoulomb caps phi and c at their peaks, where its
exponential law would otherwise pass phi = 90 degrees).  The sums use the current volumes.

Time discretisation: `regularise` (called by Simulation._advance at the start of every step
and of every retried half step) stores the neighbourhood average <kappa>_p from the committed
local kappa in the material's last state column (nonlocal_column), and the return mapping of
the step (over_nonlocal) uses
    kappa_bar = A_p + (1 - m) dkappa_p,     A_p = (1 - m) kappa_p,n + m <kappa>_p,
dkappa_p the particle's own plastic increment: the neighbourhood average is lagged (explicit
in time), the local part is implicit.  With H <= 0 (eta >= 0) and m > 1 the strength then
grows with the particle's own increment, slope (1 - m) H >= 0, so the return has one solution
and the Newton tangent is the exact consistent tangent of this local return (VonMises: the
radial return tangent with H_t = (1 - m) H; MohrCoulomb: its return with eta' = (1 - m) eta);
it is local (no coupling between particles), symmetric for VonMises, and positive where the
local softening tangent was negative, so Newton converges as for a hardening material.
Without softening (H = 0, eta = 0) the strength does not depend on kappa and the results are
the local ones.
When the average is refreshed: implicit integrators every step (few, large steps).  Explicit
steps are many and short, and the average cannot change faster than plastic flow spreads
over l: it is refreshed at the first step starting at or after each multiple of
    tau = REFRESH * l / c_p        (c_p: the material's initial P-wave speed),
four times the time a P wave takes to cross l (REFRESH = 4), while the local part
(1 - m) kappa_p,n is current at every step.  Chosen by measurement on the softening slope of
bench localisation (h = H/32, l = 4 h, about 40 steps per refresh): the run-out is 23.82 /
23.78 / 23.70 / 23.64 m refreshing every step / with REFRESH = 1 / 2 / 4, and the averaging
takes 90 / 51 / 35 / 21 % of the step time (docs/guide/materials.md).  The schedule depends only on (t, dt), so a restart from a
checkpoint (the average travels as a state column) repeats it exactly.

Neighbour search: the points are binned into a uniform lattice of cell size h (the grid's
smallest cell size) anchored at the mesh's lower corner, so on structured grids the bins are
the grid's cells; a point scans the bins that meet the disc (sphere) of radius 3 l around it
(row by row: about pi/4 (pi/6) of the square (cube) of ceil(3 l / h) rings), reading the
points from copies sorted by bin, so the bins of one row are one contiguous run; O(n k) for
k neighbours; it gets <kappa> = 0 when no point with kappa != 0 lies in those bins, and a
point whose bin is more than the cutoff (plus a bin) from every such bin is not scanned at
all (the bins holding kappa != 0 dilated by the cutoff). The scanned points are averaged in
parallel chunks that each take every nc-th of them (kernels.threads' RETURN_CHUNK sets nc),
so a plastic zone that is one block of the particle order still spreads over the threads;
the same bits on any number of threads.  Under
MPI every rank receives the particles of the other ranks within 3 l of its particles'
bounding box (ghost particles, one alltoall), so the average is the serial one up to the
summation order; the plastic zone, where averages are computed, usually lies on one rank,
so a rank with more than its share of points to scan hands the excess, with the points
within 3 l of them, to ranks with fewer, which average them with the same bits and send the
averages back (_share_scans, two more alltoalls).  The time spent is in sim.timers["nonlocal"].
"""
import math

import numba
import numpy as np

from ..kernels.threads import PRANGE, RETURN_CHUNK, particle_chunks
from .validation import check_positive, check_real

__all__ = ["NonlocalSoftening", "nonlocal_average", "regularise", "refresh_due",
           "over_nonlocal", "CUTOFF", "REFRESH"]

CUTOFF = 3.0        # neighbours within CUTOFF * l (w(3 l) / max w < 1e-3)
REFRESH = 4.0       # explicit runs refresh the average every REFRESH * l / c_p


@numba.njit(cache=True)
def over_nonlocal(state, p, nl, m):
    """A_p = (1 - m) kappa_p,n + m <kappa>_p: the over-nonlocal variable at the start of the
    step from the local kappa (column 0) and the neighbourhood average (column nl)."""
    return (1.0 - m) * state[p, 0] + m * state[p, nl]


def nonlocal_average(x, vol, kap, n_own, origin, hb, length, out):
    """out[p] = <kap>_p = sum_q w_pq V_q kap_q / sum_q w_pq V_q for the first
    n_own points p of x (the rest are ghosts), w = r / l^2 exp(-(r/l)^2) for r < 3 l
    (Galavi & Schweiger 2010), neighbours found in bins of size hb from `origin`. The points
    are binned serially; only the points whose bin lies within the cutoff of a bin holding
    kap != 0 are averaged (the others get 0 without a neighbour scan: _scanned_points), in
    parallel chunks that take every nc-th of those points, so a plastic zone in one corner
    of the particle order is spread over the threads (the same bits on any number of
    threads)."""
    out[:n_own] = 0.0
    act, bins = _scanned_points(x, kap, n_own, origin, hb, length)
    out[act] = _average_at(x, vol, kap, act, origin, hb, length, bins)


def _scanned_points(x, kap, n_own, origin, hb, length):
    """(act, bins): the indices p < n_own whose average nonlocal_average computes (the points
    whose bin lies within the cutoff (plus a bin) of a bin holding kap != 0, _near_hot; every
    other point's average is 0) and the binning of x (_bins), for _average_at."""
    bins = _bins(x, kap, origin, hb)
    nb, _, _, hot, lin = bins
    near = _near_hot(hot, nb, int(math.ceil(CUTOFF * length / hb)) + 1, x.shape[1])
    return np.flatnonzero(near[lin[:n_own]]), bins


def _average_at(x, vol, kap, pts, origin, hb, length, bins=None):
    """<kap> of nonlocal_average at the points pts (indices into x) over all the points of x
    (bins: _bins(x, kap, origin, hb) when the caller has it). The sums visit the bins in a
    fixed geometric order and the points of a bin in their order in x, so any subset of x
    that keeps the order and holds every point within the cutoff of pts gives the same bits
    (_share_scans)."""
    nb, start, order, hot, _ = _bins(x, kap, origin, hb) if bins is None else bins
    nr = int(math.ceil(CUTOFF * length / hb))
    out = np.zeros(len(x))
    _average(x, kap, x[order], vol[order], kap[order], np.asarray(pts, dtype=np.int64), nb,
             start, hot, (CUTOFF * length) ** 2, 1.0 / (length * length), nr,
             particle_chunks(len(pts), RETURN_CHUNK),
             np.ascontiguousarray(origin, dtype=np.float64), float(hb), out)
    return out[pts]


def _share_plan(counts, min_share=RETURN_CHUNK):
    """Moves (source, destination, k) that bring every rank's count of points to scan towards
    the mean: ranks above ceil(mean) hand their excess to ranks below it, in rank order; no
    move of fewer than min_share points. The same on every rank (from the allgathered
    counts)."""
    target = -(-int(sum(counts)) // len(counts))
    load = [int(c) for c in counts]
    moves = []
    for s in range(len(load)):
        for d in range(len(load)):
            k = min(load[s] - target, target - load[d])
            if k >= min_share:
                moves.append((s, d, k))
                load[s] -= k
                load[d] += k
    return moves


def _share_scans(comm, x, vol, kap, n_own, origin, hb, length, out):
    """nonlocal_average under MPI with the scanning shared between the ranks: the plastic
    zone, where the averages are computed, usually lies on one rank. A rank with more than
    its share of points to scan (_share_plan) sends the last of them with every point of x
    within the cutoff of their bounding box (in x's order) to a rank with fewer, which
    averages them (_average_at: the same bits) and sends the averages back (two
    alltoalls). Returns the number of points this rank handed to others."""
    out[:n_own] = 0.0
    act, bins = _scanned_points(x, kap, n_own, origin, hb, length)
    moves = _share_plan(comm.allgather(len(act)))
    send, given, r = [None] * comm.size, [], comm.rank
    for s, d, k in moves:
        if s == r:
            pts, act = act[len(act) - k:], act[:len(act) - k]
            reach = CUTOFF * length * (1.0 + 1e-9) + 1e-9 * hb
            sel = np.flatnonzero(_in_box(x, x[pts].min(axis=0), x[pts].max(axis=0), reach))
            send[d] = (x[sel], vol[sel], kap[sel], np.searchsorted(sel, pts))
            given.append((d, pts))
    back = [None] * comm.size
    for src, job in enumerate(comm.alltoall(send)):
        if job is not None:
            back[src] = _average_at(np.ascontiguousarray(job[0]), job[1], job[2], job[3],
                                   origin, hb, length)
    out[act] = _average_at(x, vol, kap, act, origin, hb, length, bins)
    got = comm.alltoall(back)
    for d, pts in given:
        out[pts] = got[d]
    return sum(len(pts) for _, pts in given)


@numba.njit(cache=True)
def _bins(x, kap, origin, hb):
    """Bin counts nb per axis, the points sorted by bin (start, order), the bins holding
    a point with kap != 0 (hot) and each point's bin (lin)."""
    n, d = x.shape
    b = np.zeros((n, 3), dtype=np.int64)
    nb = np.ones(3, dtype=np.int64)
    for j in range(n):
        for k in range(d):
            c = max(0, int(math.floor((x[j, k] - origin[k]) / hb)))
            b[j, k] = c
            nb[k] = max(nb[k], c + 1)
    start = np.zeros(nb[0] * nb[1] * nb[2] + 1, dtype=np.int64)
    lin = np.empty(n, dtype=np.int64)
    for j in range(n):
        lin[j] = (b[j, 0] * nb[1] + b[j, 1]) * nb[2] + b[j, 2]
        start[lin[j] + 1] += 1
    for c in range(len(start) - 1):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    hot = np.zeros(len(start) - 1, dtype=np.bool_)
    for j in range(n):
        order[fill[lin[j]]] = j
        fill[lin[j]] += 1
        if kap[j] != 0.0:
            hot[lin[j]] = True
    return nb, start, order, hot, lin


@numba.njit(cache=True)
def _near_hot(hot, nb, r, d):
    """The bins within r bins of a hot bin along every axis (hot dilated by a (2 r + 1)^d
    box, one axis at a time): with r = ceil(cutoff / hb) + 1 a superset of the bins whose
    points have a hot bin among the bins they scan (_near_rows)."""
    near = hot.copy()
    for k in range(d):
        stride = 1
        for j in range(k + 1, 3):
            stride *= nb[j]
        grown = np.zeros_like(near)
        for c in range(len(near)):
            if near[c]:
                ck = (c // stride) % nb[k]
                for e in range(max(0, ck - r), min(nb[k], ck + r + 1)):
                    grown[c + (e - ck) * stride] = True
        near = grown
    return near


@numba.njit(cache=True, parallel=PRANGE)
def _average(x, kap, xs, vs, ks, act, nb, start, hot, rad2, il2, nr, nc, origin, hb, out):
    """The averages of _average_at at the points act, chunk c of nc (the points act[c],
    act[c + nc], ...) on a thread each; xs, vs, ks: the points' positions, volumes and
    kappa sorted by bin (contiguous reads)."""
    d = x.shape[1]
    room = (2 * nr + 3) ** (d - 1)
    for c in numba.prange(nc):
        rows = np.empty((room, 2), dtype=np.int64)
        for i in range(c, len(act), nc):
            p = act[i]
            k = _near_rows(x, p, origin, hb, rad2, nb, rows)
            out[p] = _average_one(x[p], kap[p], xs, vs, ks, start, hot, rad2, il2, rows, k)


@numba.njit(cache=True)
def _span(xc, o, hb, half, n):
    """The bins [lo, hi) of one axis that the interval (xc - half, xc + half) touches (widened
    by round-off margins, so no point within half is missed)."""
    m = half * (1.0 + 1e-12) + 1e-9 * hb
    return (max(0, int(math.floor((xc - m - o) / hb))),
            min(n, int(math.floor((xc + m - o) / hb)) + 1))


@numba.njit(cache=True)
def _gap2(xc, o, hb, c):
    """Squared distance from xc to the slab of bin c on one axis (bin 0 reaches down to -inf,
    as _bins clamps to it), less a round-off margin."""
    lo = o + c * hb - 1e-9 * hb
    hi = o + (c + 1) * hb + 1e-9 * hb
    if xc > hi:
        return (xc - hi) ** 2
    if c > 0 and xc < lo:
        return (lo - xc) ** 2
    return 0.0


@numba.njit(cache=True)
def _near_rows(x, p, origin, hb, rad2, nb, rows):
    """Writes to `rows` the bins that can hold a point within sqrt(rad2) of x_p as runs
    [first, last] of consecutive linear indices (one per row of the last axis), in the order
    of their linear index, and returns their count: the rows of the disc (sphere) only, not
    the square (cube) of bins around it, so about pi/4 (pi/6) of the bins."""
    d = x.shape[1]
    k = 0
    lo0, hi0 = _span(x[p, 0], origin[0], hb, math.sqrt(rad2), nb[0])
    for b0 in range(lo0, hi0):
        g0 = _gap2(x[p, 0], origin[0], hb, b0)
        if g0 >= rad2:
            continue
        if d == 1:
            rows[k, 0] = b0 * nb[1] * nb[2]
            rows[k, 1] = rows[k, 0]
            k += 1
            continue
        lo1, hi1 = _span(x[p, 1], origin[1], hb, math.sqrt(rad2 - g0), nb[1])
        if d == 2:
            if hi1 > lo1:
                rows[k, 0] = b0 * nb[1] + lo1
                rows[k, 1] = b0 * nb[1] + hi1 - 1
                k += 1
            continue
        for b1 in range(lo1, hi1):
            g1 = g0 + _gap2(x[p, 1], origin[1], hb, b1)
            if g1 >= rad2:
                continue
            lo2, hi2 = _span(x[p, 2], origin[2], hb, math.sqrt(rad2 - g1), nb[2])
            if hi2 > lo2:
                rows[k, 0] = (b0 * nb[1] + b1) * nb[2] + lo2
                rows[k, 1] = (b0 * nb[1] + b1) * nb[2] + hi2 - 1
                k += 1
    return k


@numba.njit(cache=True)
def _average_one(xp, kp, xs, vs, ks, start, hot, rad2, il2, rows, k):
    """<kap>_p of nonlocal_average (xp = x_p, kp = kap_p: the result where no point has a
    weight) over the sorted points of the bin runs
    rows[:k] (a run's points are contiguous in xs): 0 when none of them has kap != 0."""
    d = xs.shape[1]
    near = False
    for i in range(k):
        for c in range(rows[i, 0], rows[i, 1] + 1):
            if hot[c]:
                near = True
                break
        if near:
            break
    if not near:
        return 0.0
    num = 0.0
    den = 0.0
    for i in range(k):
        for q in range(start[rows[i, 0]], start[rows[i, 1] + 1]):
            r2 = 0.0
            for j in range(d):
                r2 += (xp[j] - xs[q, j]) ** 2
            if r2 < rad2:
                w = math.sqrt(r2) * il2 * math.exp(-r2 * il2) * vs[q]
                num += w * ks[q]
                den += w
    return num / den if den > 0.0 else kp


def _in_box(x, lo, hi, radius):
    """Mask of the points x strictly within `radius` of the box [lo, hi]."""
    return np.all((x > lo - radius) & (x < hi + radius), axis=1)


def _with_ghosts(comm, x, vol, kap, radius):
    """(x, V, kappa) of the local points followed by the other ranks' points within `radius`
    of the local bounding box (one alltoall); the local points come first."""
    if comm.size == 1:
        return x, vol, kap
    d = x.shape[1]
    box = (x.min(axis=0), x.max(axis=0)) if len(x) else (np.full(d, np.inf), np.full(d, -np.inf))
    boxes = comm.allgather(box)
    send = []
    for r, (lo, hi) in enumerate(boxes):
        if r == comm.rank or not len(x):
            send.append(None)
            continue
        sel = _in_box(x, lo, hi, radius)
        send.append((x[sel], vol[sel], kap[sel]) if np.any(sel) else None)
    got = [g for g in comm.alltoall(send) if g is not None]
    return (np.ascontiguousarray(np.concatenate([x] + [g[0] for g in got])),
            np.concatenate([vol] + [g[1] for g in got]),
            np.concatenate([kap] + [g[2] for g in got]))


def refresh_due(t, dt, tau):
    """Whether a step from t to t + dt refreshes an average kept for tau: true when a multiple
    of tau lies in (t - dt, t] (the first step at or after it; always at t = 0)."""
    return math.floor(t / tau) > math.floor((t - dt) / tau)


def regularise(sim, dt):
    """At the start of a step of dt: <kappa> (column nonlocal_column) of every particle of a
    material with a nonlocal_length, from the committed local kappa (column 0), when due
    (module docstring: every implicit step, every REFRESH l / c_p explicitly); collective.
    Adds its wall time to sim.timers["nonlocal"] (from a barrier on: not the wait for the
    other ranks to finish their step)."""
    import time
    p = sim.particles
    mats = [m for m in p.materials if getattr(m, "nonlocal_length", None) is not None
            and (not sim.integrator.explicit
                 or refresh_due(sim.t, dt, REFRESH * m.nonlocal_length / m.p_wave_speed))]
    if not mats:
        return
    comm, grid = sim.comm, sim.grid
    if comm.size > 1:       # the wait for the slowest rank's step is not the averaging's cost
        comm.Barrier()
    t0 = time.perf_counter()
    origin = getattr(sim, "_nonlocal_origin", None)
    if origin is None:
        lo = np.ascontiguousarray(grid.node_x.min(axis=0) if grid.n_nodes
                                  else np.full(grid.gdim, np.inf), dtype=np.float64)
        origin = lo.copy()
        if comm.size > 1:
            from mpi4py import MPI
            comm.Allreduce(lo, origin, op=MPI.MIN)
        sim._nonlocal_origin = origin
    groups = dict((id(m), idx) for m, idx in sim.material_groups())
    for mat in mats:
        idx = groups.get(id(mat), np.zeros(0, dtype=np.int64))
        x, vol, kap = _with_ghosts(comm, p.x[idx], p.V[idx], p.state[idx, 0],
                                   CUTOFF * mat.nonlocal_length)
        out = np.empty(len(idx))
        if comm.size > 1:
            _share_scans(comm, x, vol, kap, len(idx), origin, grid.h, mat.nonlocal_length, out)
        elif len(idx):
            nonlocal_average(x, vol, kap, len(idx), origin, grid.h, mat.nonlocal_length, out)
        p.state[idx, mat.nonlocal_column] = out
    sim.timers["nonlocal"] = sim.timers.get("nonlocal", 0.0) + time.perf_counter() - t0


class NonlocalSoftening:
    """Mixin of MohrCoulomb and VonMises: the optional nonlocal softening variable.

    nonlocal_length: None (local softening, the default) or the internal length l > 0;
    nonlocal_m: the over-nonlocal factor m >= 1 (module docstring).  With a length the
    material has one more state column, `nonlocal_column`, holding <kappa>.
    `plastic` marks the material as flowing plastically (shapes.choose_shape)."""

    plastic = True

    def _set_nonlocal(self, length, m, local_columns):
        owner = type(self).__name__
        self._nl_m = check_real(owner, "nonlocal_m", m)
        if not self._nl_m > 1.0:
            raise ValueError(f"{owner}: parameter 'nonlocal_m' must be > 1 (over-nonlocal), "
                             f"got {self._nl_m!r}")
        if length is None:
            self._nl_length = None
            self.n_state = local_columns
            self.nonlocal_column = -1
        else:
            self._nl_length = check_positive(owner, "nonlocal_length", length)
            self.n_state = local_columns + 1
            self.nonlocal_column = local_columns

    nonlocal_length = property(lambda self: self._nl_length,
                               doc="Internal length l of the nonlocal average (None: local).")
    nonlocal_m = property(lambda self: self._nl_m, doc="Over-nonlocal factor m.")

    def _nonlocal_repr(self):
        if self._nl_length is None:
            return ""
        return f", nonlocal_length={self._nl_length!r}, nonlocal_m={self._nl_m!r}"
