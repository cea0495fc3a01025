"""Nonlocal regularisation of the softening variable of MohrCoulomb and VonMises (issue 19).

Without a length scale a softening law localises into one cell: the band width, the
dissipated energy and the post-peak response depend on h.  Here the variable that drives
softening, the accumulated plastic (deviatoric) strain kappa (VonMises: eps_p, MohrCoulomb:
eps_d^p), is replaced in the strength law by an over-nonlocal average over the particles of
the same material within 3 l:

    kappa_bar_p = max(0, (1 - m) kappa_p + m <kappa>_p),
    <kappa>_p   = sum_q w(r_pq) V_q kappa_q / sum_q w(r_pq) V_q,
    w(r)        = r / l^2 exp(-(r / l)^2),                       r_pq = |x_p - x_q| < 3 l,

the weight of Galavi & Schweiger (2010, Int. J. Geomech. 10(1)) and the over-nonlocal
combination of Vermeer & Brinkgreve (1994) that they use, with m > 1 (default 2) and the
internal length l (`nonlocal_length`).  Why this form rather than Burghardt, Brannon &
Guilkey (2012, the plain nonlocal average m = 1 of the plastic strain for MPM): with m = 1
the averaged variable is smooth but the local plastic strain that feeds it can still
concentrate in one row of points (Jirasek & Rolshoven 2003 analyse this for integral
nonlocal plasticity: m = 1 regularises the dissipation, not the width of the plastic zone),
while m > 1 makes a point that has strained more than its neighbourhood relatively stronger,
so plastic flow spreads over a zone of width ~ l.  The weight vanishes at r = 0 (a point
does not average itself).  kappa_bar is clipped at 0 so that the strength never exceeds the
peak.  The sums use the current particle volumes V_q.

Time discretisation (explicit and implicit alike): kappa_bar is computed once per step, at
its start, from the committed local kappa (Simulation._advance -> `regularise`), stored in
the material's last state column and frozen during the step.  Within the step the return
mapping is the local perfectly plastic one at the frozen strength c(kappa_bar_n) (VonMises)
or phi(kappa_bar_n), c(kappa_bar_n) (MohrCoulomb), and the local kappa grows by the step's
plastic increment.  The Newton tangent is therefore the exact consistent tangent of this
frozen-strength return (no softening term, no nonlocal coupling between particles): Newton
keeps its quadratic convergence and its matrix stays symmetric for VonMises, at the price of
an O(dt) lag of the softening behind the plastic flow (refine the load steps to reduce it).

Neighbour search: the points are binned into a uniform lattice of cell size h (the grid's
smallest cell size) anchored at the mesh's lower corner, so on structured grids the bins are
the grid's cells; a point scans the ceil(3 l / h) rings of bins around its own: O(n k) for
k neighbours, no O(n^2).  Under MPI every rank receives the particles of the other ranks
that lie within 3 l of its particles' bounding box (ghost particles, one alltoall), so the
average is the serial one up to the summation order.  The time spent is reported in
sim.timers["nonlocal"].
"""
import math

import numba
import numpy as np

from .validation import check_positive, check_real

__all__ = ["NonlocalSoftening", "nonlocal_average", "regularise", "CUTOFF"]

CUTOFF = 3.0        # neighbours within CUTOFF * l (w(3 l) / max w < 1e-3)


@numba.njit(cache=True)
def nonlocal_average(x, vol, kap, n_own, origin, hb, length, m, out):
    """out[p] = A_p = (1 - m) kap[p] + m sum_q w_pq V_q kap_q / sum_q w_pq V_q for the first
    n_own points p of x (the rest are ghosts), w = r / l^2 exp(-(r/l)^2) for r < 3 l
    (Galavi & Schweiger 2010), neighbours found in bins of size hb from `origin`."""
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
    hot = np.zeros(len(start) - 1, dtype=np.bool_)      # bins holding a point with kap != 0
    for j in range(n):
        order[fill[lin[j]]] = j
        fill[lin[j]] += 1
        if kap[j] != 0.0:
            hot[lin[j]] = True
    rad2 = (CUTOFF * length) ** 2
    il2 = 1.0 / (length * length)
    nr = int(math.ceil(CUTOFF * length / hb))
    lo = np.zeros(3, dtype=np.int64)
    hi = np.ones(3, dtype=np.int64)
    for p in range(n_own):
        for k in range(d):
            lo[k] = max(0, b[p, k] - nr)
            hi[k] = min(nb[k], b[p, k] + nr + 1)
        near = False
        for b0 in range(lo[0], hi[0]):
            for b1 in range(lo[1], hi[1]):
                for b2 in range(lo[2], hi[2]):
                    near = near or hot[(b0 * nb[1] + b1) * nb[2] + b2]
        if not near:                # every kap within reach is 0 (kap[p] too): A_p = 0
            out[p] = 0.0
            continue
        num = 0.0
        den = 0.0
        for b0 in range(lo[0], hi[0]):
            for b1 in range(lo[1], hi[1]):
                for b2 in range(lo[2], hi[2]):
                    c = (b0 * nb[1] + b1) * nb[2] + b2
                    for jj in range(start[c], start[c + 1]):
                        q = order[jj]
                        r2 = 0.0
                        for k in range(d):
                            r2 += (x[p, k] - x[q, k]) ** 2
                        if r2 < rad2:
                            w = math.sqrt(r2) * il2 * math.exp(-r2 * il2) * vol[q]
                            num += w * kap[q]
                            den += w
        avg = num / den if den > 0.0 else kap[p]
        out[p] = (1.0 - m) * kap[p] + m * avg


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
        sel = np.all((x > lo - radius) & (x < hi + radius), axis=1)
        send.append((x[sel], vol[sel], kap[sel]) if np.any(sel) else None)
    got = [g for g in comm.alltoall(send) if g is not None]
    return (np.ascontiguousarray(np.concatenate([x] + [g[0] for g in got])),
            np.concatenate([vol] + [g[1] for g in got]),
            np.concatenate([kap] + [g[2] for g in got]))


def regularise(sim):
    """At the start of a step: kappa_bar (column nonlocal_column) of every particle of a
    material with a nonlocal_length, from the committed local kappa (column 0); collective.
    Adds its wall time to sim.timers["nonlocal"]."""
    import time
    p = sim.particles
    mats = [m for m in p.materials if getattr(m, "nonlocal_length", None) is not None]
    if not mats:
        return
    t0 = time.perf_counter()
    comm, grid = sim.comm, sim.grid
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
        col = mat.nonlocal_column
        x, vol, kap = _with_ghosts(comm, p.x[idx], p.V[idx], p.state[idx, 0],
                                   CUTOFF * mat.nonlocal_length)
        out = np.empty(len(idx))
        if len(idx):
            nonlocal_average(x, vol, kap, len(idx), origin, grid.h, mat.nonlocal_length,
                             mat.nonlocal_m, out)
        p.state[idx, col] = out
    sim.timers["nonlocal"] = sim.timers.get("nonlocal", 0.0) + time.perf_counter() - t0


class NonlocalSoftening:
    """Mixin of MohrCoulomb and VonMises: the optional nonlocal softening variable.

    nonlocal_length: None (local softening, the default) or the internal length l > 0;
    nonlocal_m: the over-nonlocal factor m >= 1 (module docstring).  With a length the
    material has one more state column, `nonlocal_column`, holding kappa_bar."""

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
