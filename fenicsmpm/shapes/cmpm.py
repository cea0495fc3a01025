"""Composite MPM (CMPM) shape functions on structured quadrilateral/hexahedral grids
(seed 000 §2.8, eqs 2.54-2.56 as corrected in BENCHMARKS.md "DM-GC and CMPM").

A particle in lattice cell j (local coordinate xi in [-1, 1] per axis) is interpolated by the
1D Lagrange polynomials (eq 2.54) over the extended stencil of nodes j-1, j, j+1, j+2, at
xi_m = -3, -1, 1, 3:
    interior  [-(xi^3 - 3xi^2 - xi + 3)/48, (xi^3 - xi^2 - 9xi + 9)/16,
               (-xi^3 - xi^2 + 9xi + 9)/16, (xi^3 + 3xi^2 - xi - 3)/48]        (eq 2.55)
    boundary  (nodes -1, 1, 3) [(xi^2 - 4xi + 3)/8, (-xi^2 + 2xi + 3)/4, (xi^2 - 1)/8]  (eq 2.56)
and its mirror (nodes -3, -1, 1) at the other end; 2D/3D by tensor products. The stencil
spans the particle's cell and its neighbours; it is trimmed, per axis and side, where the
neighbour cells of that side (over the stencil's extent along the other axes) are off the
mesh or hold no particle (the material's free surface is a boundary too: a node reached only
by a sliver of a GIMP box carries almost no mass, and a stencil built on it makes the
implicit iteration stall); a trimmed side drops to the quadratic (eq 2.56) and a cell
trimmed on both sides to the linear pair. The cubic basis reproduces cubic fields, the
quadratic one quadratic fields, exactly."""
import numpy as np
from numba import njit

from .gimp import lattice


@njit(cache=True)
def lagrange_1d(xi, m_lo, m_hi, N_out, dN_out):
    """Lagrange basis (eq 2.54) and d/dxi on the nodes xi_m = 2m - 1, m = m_lo..m_hi
    (m in -1..2), into N_out[m - m_lo], dN_out[m - m_lo]."""
    for m in range(m_lo, m_hi + 1):
        xm = 2.0 * m - 1.0
        val = 1.0
        der = 0.0
        for q in range(m_lo, m_hi + 1):
            if q == m:
                continue
            xq = 2.0 * q - 1.0
            f = (xi - xq) / (xm - xq)
            der = der * f + val / (xm - xq)
            val *= f
        N_out[m - m_lo] = val
        dN_out[m - m_lo] = der


@njit(cache=True)
def _node(j0, m, ilo, nlat, table):
    """Local node of lattice point j0 + m (per axis), or -1 when it is not local."""
    flat = 0
    stride = 1
    for k in range(len(j0)):
        jl = j0[k] + m[k] - ilo[k]
        if jl < 0 or jl >= nlat[k]:
            return -1
        flat += jl * stride
        stride *= nlat[k]
    return table[flat]


@njit(cache=True)
def cmpm_shape(x, cell, cell_lat, origin, spacing, ncell, clo, cnl, ctable, material, ilo, nlat,
               table, nodes_out, N_out, dN_out):
    """CMPM weights and gradients of every particle over its (trimmed) extended stencil.

    x (n, d); cell: the particle's local cell, cell_lat (n_cells, d) the global lattice index
    of every local cell; ncell: global cells per axis; clo/cnl/ctable: the local cell lattice
    (first index and count per axis, flat -> local cell or -1); material (n_cells,): cells
    the stencil may extend into; ilo/nlat/table: the node lattice (shapes.gimp.lattice).
    Output padded to 4^d columns (padding: a stencil node with N = dN = 0). Returns -1, or
    the index of a particle whose stencil reaches a cell or node that is not local (the
    caller raises)."""
    d = x.shape[1]
    j0 = np.empty(d, dtype=np.int64)
    lo = np.empty(d, dtype=np.int64)
    hi = np.empty(d, dtype=np.int64)
    m = np.empty(d, dtype=np.int64)
    Nk = np.empty((d, 4))
    dNk = np.empty((d, 4))
    for p in range(x.shape[0]):
        for k in range(d):
            j0[k] = cell_lat[cell[p], k]
            lo[k] = -1 if j0[k] >= 1 else 0             # trimmed at the mesh boundary
            hi[k] = 2 if j0[k] + 2 <= ncell[k] else 1
        for k in range(d):                  # and where the neighbour cells are not material
            for side in range(2):
                if (lo[k] if side == 0 else hi[k] - 1) == 0:
                    continue
                ck = j0[k] - 1 if side == 0 else j0[k] + 1
                ok = True
                total = 1
                for q in range(d):
                    if q != k:
                        total *= hi[q] - lo[q]
                for t in range(total):
                    if not ok:
                        break
                    r = t
                    flat = 0
                    stride = 1
                    for q in range(d):
                        if q == k:
                            cq = ck
                        else:
                            w = hi[q] - lo[q]
                            cq = j0[q] + lo[q] + r % w
                            r //= w
                        jl = cq - clo[q]
                        if jl < 0 or jl >= cnl[q]:
                            return p
                        flat += jl * stride
                        stride *= cnl[q]
                    c = ctable[flat]
                    if c < 0:
                        return p
                    ok = material[c]
                if not ok:
                    if side == 0:
                        lo[k] = 0
                    else:
                        hi[k] = 1
        for k in range(d):
            L = spacing[k]
            xi = 2.0 * (x[p, k] - origin[k] - j0[k] * L) / L - 1.0
            lagrange_1d(xi, lo[k], hi[k], Nk[k], dNk[k])
            for a in range(hi[k] - lo[k] + 1):
                dNk[k, a] *= 2.0 / L
        total = 1
        for k in range(d):
            total *= hi[k] - lo[k] + 1
        for t in range(total):
            r = t
            w = 1.0
            for k in range(d):
                n1 = hi[k] - lo[k] + 1
                m[k] = lo[k] + r % n1
                r //= n1
                w *= Nk[k, m[k] - lo[k]]
            node = _node(j0, m, ilo, nlat, table)
            if node < 0:
                return p
            nodes_out[p, t] = node
            N_out[p, t] = w
            for k in range(d):
                g = dNk[k, m[k] - lo[k]]
                for q in range(d):
                    if q != k:
                        g *= Nk[q, m[q] - lo[q]]
                dN_out[p, t, k] = g
        for t in range(total, nodes_out.shape[1]):
            nodes_out[p, t] = nodes_out[p, 0]
            N_out[p, t] = 0.0
            for k in range(d):
                dN_out[p, t, k] = 0.0
    return -1


class CompositeBasis:
    """CMPM shape functions of a structured grid; `lat` is shapes.gimp.lattice(grid) (computed,
    collectively, when not given). cell_lat (n_cells, d): the global lattice index of every
    local cell; ncell: global cells per axis; clo, cnl, ctable: the local cell lattice (first
    index and count per axis; flat index, axis 0 fastest, -> local cell or -1)."""

    def __init__(self, grid, lat=None):
        self.grid = grid
        self.lat = lat = lattice(grid) if lat is None else lat
        sp = lat["spacing"]
        d = grid.gdim
        corner = grid.node_x[grid.cell_nodes].min(axis=1)
        self.cell_lat = np.ascontiguousarray(np.round((corner - lat["origin"]) / sp), dtype=np.int64)
        self.ncell = np.round((lat["hi"] - lat["lo"]) / sp).astype(np.int64)
        empty = len(self.cell_lat) == 0
        self.clo = np.zeros(d, dtype=np.int64) if empty else self.cell_lat.min(axis=0)
        self.cnl = np.zeros(d, dtype=np.int64) if empty else self.cell_lat.max(axis=0) - self.clo + 1
        strides = np.cumprod(np.concatenate([[1], self.cnl[:-1]]))
        self.ctable = np.full(int(np.prod(self.cnl)), -1, dtype=np.int64)
        self.ctable[(self.cell_lat - self.clo) @ strides] = np.arange(len(self.cell_lat))
        self._dg0 = None

    def material(self, count):
        """Cells holding a particle, from the local particle count per local cell (owned
        cells hold their particles; ghost cells get their owner's flag). Collective."""
        flag = count[: self.grid.n_cells] > 0
        if self.grid.comm.size == 1:
            return flag
        from dolfinx import fem
        if self._dg0 is None:
            V0 = fem.FunctionSpace(self.grid.mesh, ("DG", 0))
            self._dg0 = (fem.Function(V0), V0.dofmap.list.array[: self.grid.n_cells])
        f, dofs = self._dg0
        own = self.grid.n_owned_cells
        f.x.array[dofs[:own]] = flag[:own]
        f.x.scatter_forward()
        return f.x.array[dofs] > 0.5

    def evaluate(self, x, cell, material):
        """(nodes, N, dN) at positions x (n, d) in local cells `cell`, over the stencil trimmed
        where the neighbour cells are off the mesh or not `material` (module docstring);
        padded to 4^d columns."""
        d, lat = self.grid.gdim, self.lat
        n = len(x)
        nodes = np.empty((n, 4 ** d), dtype=np.int32)
        N = np.empty((n, 4 ** d))
        dN = np.empty((n, 4 ** d, d))
        bad = cmpm_shape(np.ascontiguousarray(x), np.ascontiguousarray(cell, dtype=np.int64),
                         self.cell_lat, lat["origin"], lat["spacing"], self.ncell, self.clo,
                         self.cnl, self.ctable, np.ascontiguousarray(material, dtype=np.bool_),
                         lat["ilo"], lat["nlat"], lat["table"], nodes, N, dN)
        if bad >= 0:
            raise RuntimeError(f"CMPM: the extended stencil of the particle at "
                               f"{np.round(x[bad], 6).tolist()} reaches grid cells that are not on "
                               f"this rank; in parallel, create the mesh with partitioner="
                               f"fenicsmpm.grid.vertex_ghost_partitioner()")
        return nodes, N, dN
