"""Benchmark case `gimp-factors`: the cpGIMP weights stored as per-axis factors against the
padded node rows the particle passes read today (issue 16: "exploit the tensor-product
structure of GIMP weights"). A measurement of a storage layout, not a path the simulation
takes yet.

    python -m fenicsmpm.bench gimp-factors [--quick] [--out DIR]

On a lattice a GIMP weight is a product of 1D factors (shapes.gimp.tensor_product):
    S_ip = S_x,a(p) S_y,b(p),   grad S_ip = (dS_x,a S_y,b, S_x,a dS_y,b),
node i = the lattice point (j0_x + a, j0_y + b). The rows store every node index, weight and
gradient (9 columns in 2D: 4 + 8 + 16 B each, 252 B a particle, written by the shape pass and
read by P2G, the internal force, G2P and the stress update); the factors store j0 as one flat
lattice offset and S, dS per axis and node (3 each in 2D: 8 + 96 B), and a pass forms the
products it needs. The factored passes below visit the nonzero-weight nodes in the rows'
order (axis 0 fastest), so their sums are the rows' sums to the bit (checked: `bits_equal`).

Scene: bench throughput's explicit block (cells 512 full, 164 quick; 2 x 2 particles per cell,
cpGIMP), after 3 explicit steps. Timed on one thread each (the serial loops of both: the
rows' shape pass shapes.gimp._gimp, P2G transfer._mass_momentum, force transfer._force;
the factored kernels here), the fastest of `repeats` calls. The factored force has no
active-node restriction (the rows' force is called without it too). Metrics per pass: ms rows,
ms factors, ratio. Writes gimp-factors.json and gimp-factors.png."""
import os

import numpy as np
from numba import njit

from . import common
from ..shapes.gimp import _closed_weight, _weight, half_width

CASE = "gimp-factors"
SIZES = {"full": dict(cells=512, repeats=7), "quick": dict(cells=40, repeats=3)}


@njit(cache=True)
def factors(x, lp0, F, origin, spacing, lo, hi, ilo, nlat, base, S, dS):
    """Per particle the flat lattice offset of its first node (base) and the 1D cpGIMP factors
    S[p, k, a], dS[p, k, a] of the 3 nodes from it along axis k (0 past the box), by
    shapes.gimp's half_width, _closed_weight and _weight (2D). Returns the number of particles
    whose box reaches a 4th node on an axis (a box stretched past a cell: not stored here)."""
    inv_L = 1.0 / spacing
    inv_2L = 0.5 / spacing
    wide = 0
    for q in range(x.shape[0]):
        b0 = 0
        stride = 1
        for k in range(2):
            L = spacing[k]
            lp = half_width(lp0[q, k], F[q, k, k], L, True, x[q, k], lo[k], hi[k])
            a = max(x[q, k] - lp, lo[k])
            b = min(x[q, k] + lp, hi[k])
            j0 = int(np.floor((a - origin[k]) / L))
            m = int(np.ceil((b - origin[k]) / L)) - j0 + 1
            if m > 3:
                wide += 1
            closed = lp <= 0.5 * L and a == x[q, k] - lp and b == x[q, k] + lp
            inv_w = 1.0 / (b - a)
            inv_Ll = 1.0 / (L * lp) if closed else 0.0
            for r in range(3):
                s, ds = 0.0, 0.0
                if r < m:
                    j = j0 + r
                    if closed:
                        s, ds = _closed_weight(x[q, k] - (origin[k] + j * L), L, lp, inv_L[k],
                                               inv_Ll)
                    else:
                        s, ds = _weight(a, b, inv_w, origin[k] + j * L, L, inv_L[k], inv_2L[k])
                S[q, k, r] = s
                dS[q, k, r] = ds
            b0 += (j0 - ilo[k]) * stride
            stride *= nlat[k]
        base[q] = b0
    return wide


@njit(cache=True)
def p2g_factors(base, S, table, nx, mass, v, m_out, mv_out):
    """m_i += S_ip m_p, (m v)_i += S_ip m_p v_p from the factors (nonzero weights only)."""
    for q in range(base.shape[0]):
        mp, v0, v1 = mass[q], v[q, 0], v[q, 1]
        for b in range(3):
            sy = S[q, 1, b]
            if sy == 0.0:
                continue
            for a in range(3):
                w = S[q, 0, a] * sy
                if w == 0.0:
                    continue
                i = table[base[q] + a + b * nx]
                wm = w * mp
                m_out[i] += wm
                mv_out[i, 0] += wm * v0
                mv_out[i, 1] += wm * v1


@njit(cache=True)
def force_factors(base, S, dS, table, nx, mass, V, stress, out):
    """out_i += 0 m_p - V_p sigma_p . grad S_ip from the factors, the terms and their order as
    kernels.transfer._force's 2D loop with g = 0 (its N m g term is +0.0)."""
    for q in range(base.shape[0]):
        s00, s01, s10, s11 = stress[q, 0, 0], stress[q, 0, 1], stress[q, 1, 0], stress[q, 1, 1]
        mp, vp = mass[q], V[q]
        for b in range(3):
            sy, dsy = S[q, 1, b], dS[q, 1, b]
            for a in range(3):
                sx = S[q, 0, a]
                w = sx * sy
                if w == 0.0:
                    continue
                b0, b1 = dS[q, 0, a] * sy, dsy * sx
                i = table[base[q] + a + b * nx]
                wm = w * mp
                out[i, 0] += wm * 0.0 - vp * (s00 * b0 + s01 * b1)
                out[i, 1] += wm * 0.0 - vp * (s10 * b0 + s11 * b1)


def measure(sim, repeats):
    """{pass: (seconds rows, seconds factors)} and whether the factored P2G and force give
    the rows' bits, on the local particles of a cpGIMP Simulation on a 2D lattice."""
    from ..kernels import transfer as kt
    from ..shapes import gimp
    p, g, lat = sim.particles, sim.grid, sim._wide.lat
    n = len(p)
    ns = sim._wide._window(sim)
    rows = (np.empty((n, (ns - 1) ** 2), np.int32), np.empty((n, (ns - 1) ** 2)),
            np.empty((n, (ns - 1) ** 2, 2)), np.empty(n, np.int64))
    base, S, dS = np.empty(n, np.int64), np.empty((n, 2, 3)), np.empty((n, 2, 3))
    shape_args = (p.x, p.gimp_l0, p.F, lat["origin"], lat["spacing"], lat["lo"], lat["hi"],
                  lat["ilo"], lat["nlat"])
    x, lp0, F = shape_args[:3]
    def shape_rows():
        gimp._gimp(g.D, x, lp0, F, True, *shape_args[3:], lat["table"], ns, np.int64(0), n,
                   *rows)

    t = {"shape": (common.fastest_call(repeats, shape_rows),
                   common.fastest_call(repeats, lambda: factors(*shape_args, base, S, dS)))}
    if factors(*shape_args, base, S, dS):
        raise ValueError("gimp-factors: a particle's box reaches 4 lattice nodes on an axis "
                         "(stretched past a cell); the factored layout here stores 3")
    nodes, N, dN = (np.ascontiguousarray(a[:, :max(int(rows[3].max(initial=1)), 1)])
                    for a in rows[:3])
    table, nx = lat["table"], int(lat["nlat"][0])
    m1, m2 = np.zeros(g.n_nodes), np.zeros(g.n_nodes)
    mv1, mv2 = np.zeros((g.n_nodes, 2)), np.zeros((g.n_nodes, 2))
    stress = p.stress.copy()
    stress[:, :2, :2] += np.random.default_rng(0).standard_normal((n, 2, 2))
    f1, f2 = np.zeros((g.n_nodes, 2)), np.zeros((g.n_nodes, 2))
    no_active = np.zeros((0, 1), dtype=np.bool_)
    passes = {
        "p2g": (lambda: kt._mass_momentum(g.D, nodes, N, p.mass, p.v, np.int64(0), n, m1, mv1),
                lambda: p2g_factors(base, S, table, nx, p.mass, p.v, m2, mv2)),
        "force": (lambda: kt._force(g.D, nodes, N, dN, p.mass, p.V, stress, np.zeros(2),
                                    no_active, np.int64(0), n, f1),
                  lambda: force_factors(base, S, dS, table, nx, p.mass, p.V, stress, f2))}
    for name, (by_rows, by_factors) in passes.items():
        t[name] = (common.fastest_call(repeats, by_rows),
                   common.fastest_call(repeats, by_factors))
    # one call each from zero: the bits of the two layouts
    for a in (m1, m2, mv1, mv2, f1, f2):
        a[:] = 0.0
    for by_rows, by_factors in passes.values():
        by_rows()
        by_factors()
    same = bool(np.array_equal(m1, m2) and np.array_equal(mv1, mv2) and np.array_equal(f1, f2))
    return t, same, nodes.shape[1]


def run(quick=False, out="bench-results", comm=None, verbose=True):
    from mpi4py import MPI
    from . import throughput as tp
    comm = common.world(comm)
    size = SIZES["quick" if quick else "full"]
    spec = dict(tp.FULL[0], cells=size["cells"], shape="cpgimp")
    cfg = tp.scene_config(spec)
    sim = tp.build_scene(cfg, comm)
    for _ in range(3):
        sim.step()
    t, same, nv = measure(sim, size["repeats"])
    n = sim.particles.n_global()
    same = comm.allreduce(same, op=MPI.LAND)
    nv = comm.allreduce(nv, op=MPI.MAX)     # the rows' columns: the most nodes a particle has
    runs = []
    for name, (rows, fac) in t.items():
        rows, fac = comm.allreduce(rows, op=MPI.MAX), comm.allreduce(fac, op=MPI.MAX)
        m = dict(ms_rows=1e3 * rows, ms_factors=1e3 * fac, rows_over_factors=rows / fac,
                 bytes_rows=nv * (4 + 8 + 16), bytes_factors=8 + 2 * 3 * 16,
                 bits_equal=float(same), row_columns=nv)
        c = dict(cfg, shape="cpgimp", kernel=name, threads=1)
        runs.append(common.make_record(name, c, n, common.global_cells(sim), 1, fac, m))
    doc = common.result(CASE, runs, comm, quick=quick)
    common.write_result(doc, out, comm)
    if verbose:
        common.print_table([dict(name=r["name"], **r["metrics"]) for r in runs],
                           [("pass", "name"), ("rows ms", "ms_rows"),
                            ("factors ms", "ms_factors"), ("rows / factors", "rows_over_factors"),
                            ("B rows", "bytes_rows"), ("B factors", "bytes_factors"),
                            ("same bits (1)", "bits_equal")],
                           comm=comm, title=common.table_title(doc, f"{n:,} particles, one thread"))
    fig, axes = common.new_figure(size=(6.0, 4.0))
    if comm.rank == 0:
        ax = axes[0][0]
        k = np.arange(len(runs))
        ax.bar(k - 0.2, [r["metrics"]["ms_rows"] for r in runs], 0.4, label="padded rows")
        ax.bar(k + 0.2, [r["metrics"]["ms_factors"] for r in runs], 0.4, label="per-axis factors")
        ax.set_xticks(k)
        ax.set_xticklabels([r["name"] for r in runs])
        ax.set_ylabel(f"ms per call, one thread ({n:,} particles)")
        ax.legend(fontsize=8)
    common.save_figure(fig, os.path.join(out, f"{CASE}.png"), comm,
                       title=common.figure_title(doc, "cpGIMP weights: rows or factors"))
    return doc
