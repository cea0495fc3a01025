"""Grid: a dolfinx mesh, its vector P1/Q1 space, point location and nodal exchange.

The mesh belongs to dolfinx; this module only extracts the arrays the particle kernels need:
node coordinates (ghost-inclusive, in the dof numbering of the vector space), the node
indices of each cell, and per-cell affine data for simplices. Point location uses O(1)
arithmetic on structured rectangle/box grids and a dolfinx bounding-box tree otherwise.
"""
import numpy as np
import dolfinx
from dolfinx import fem, geometry
from dolfinx.mesh import CellType

from .shapes import standard as ks

_SUPPORTED = {
    CellType.triangle: ks.SIMPLEX,
    CellType.tetrahedron: ks.SIMPLEX,
    CellType.quadrilateral: ks.TENSOR,
    CellType.hexahedron: ks.TENSOR,
}


class Grid:
    """Background grid over any dolfinx mesh of triangles, quadrilaterals, tetrahedra or
    hexahedra with affine/multilinear (degree 1) geometry.

    Attributes: `mesh`, `V` (vector Lagrange degree 1), `gdim`, `comm`, `n_nodes`
    (ghost-inclusive), `n_owned_nodes`, `node_x` (n_nodes, gdim), `cell_nodes`
    (n_cells, nodes_per_cell), `n_owned_cells`, `h` (smallest cell size, for the CFL
    limit), `structured` (whether the O(1) locate path is used), `axisymmetric`.

    axisymmetric=True (2D only) reads the mesh as a meridian plane (r, z) = (x[0], x[1]),
    r >= 0, of a body of revolution (Sulsky & Schreyer 1996): particle volumes and masses are
    per radian (V = r A), the hoop strain is u_r / r, and boundary forms are weighted by r
    (fenicsmpm.kernels.axisymmetric).
    """

    def __init__(self, mesh, axisymmetric=False):
        if not isinstance(mesh, dolfinx.mesh.Mesh):
            raise TypeError(f"Grid: 'mesh' must be a dolfinx.mesh.Mesh, got {type(mesh).__name__}")
        ct = mesh.topology.cell_type
        if ct not in _SUPPORTED:
            names = ", ".join(c.name for c in _SUPPORTED)
            raise ValueError(f"Grid: unsupported cell type '{ct.name}'; supported: {names}")
        if mesh.geometry.cmap.degree != 1:
            raise ValueError(f"Grid: only degree-1 geometry is supported, got degree "
                             f"{mesh.geometry.cmap.degree}")
        if mesh.geometry.dim != mesh.topology.dim:
            raise ValueError(f"Grid: manifold meshes are not supported (gdim={mesh.geometry.dim}, "
                             f"tdim={mesh.topology.dim})")
        self.mesh = mesh
        self.comm = mesh.comm
        self.cell_type = ct
        self.kind = _SUPPORTED[ct]
        self.gdim = mesh.geometry.dim
        self.D = tuple(range(self.gdim))   # compile-time dimension for the numba kernels
        tdim = mesh.topology.dim
        self.V = fem.VectorFunctionSpace(mesh, ("Lagrange", 1))
        imap = self.V.dofmap.index_map
        self.n_owned_nodes = imap.size_local
        self.n_nodes = imap.size_local + imap.num_ghosts
        cmap = mesh.topology.index_map(tdim)
        self.n_owned_cells = cmap.size_local
        self.n_cells = cmap.size_local + cmap.num_ghosts
        nv = self.V.dofmap.dof_layout.num_dofs
        self.cell_nodes = np.ascontiguousarray(
            self.V.dofmap.list.array.reshape(-1, nv)[: self.n_cells], dtype=np.int32)
        self.node_x = self._node_coordinates()
        self._affine_data()
        self.h = self._min_cell_size()
        self._structured = self._detect_structured()
        self._global_lattice()
        self.structured = self._structured is not None
        self._tree = None
        self._exchange = {}
        self._max_vec = {}
        self.periodic = None     # boundaries.periodic.PeriodicTie, applied by accumulate
        self.axisymmetric = bool(axisymmetric)
        if self.axisymmetric:
            if self.gdim != 2:
                raise ValueError(f"Grid: axisymmetric=True needs a 2D (r, z) mesh, got gdim={self.gdim}")
            rmin = float(self.node_x[:, 0].min()) if self.n_nodes else np.inf
            if self.comm.size > 1:
                from mpi4py import MPI
                rmin = self.comm.allreduce(rmin, op=MPI.MIN)
            if rmin < -1e-12 * max(1.0, self.h):
                raise ValueError(f"Grid: axisymmetric=True needs r = x[0] >= 0 everywhere, the mesh "
                                 f"reaches r = {rmin:.6g}")

    # ------------------------------------------------------------------ geometry data
    def _affine_data(self):
        d = self.gdim
        nv = self.cell_nodes.shape[1]
        self.simplex_Jinv = np.zeros((0, d, d))
        self.simplex_grad = np.zeros((1, nv, d))
        self.affine_Jinv = self.simplex_Jinv
        if self.kind != ks.SIMPLEX:
            # parallelogram/parallelepiped cells: x(xi) = x_0 + sum_k xi_k (x_{2^k} - x_0) is
            # exact, so location is a single affine map (no Newton)
            xc = self.node_x[self.cell_nodes]
            if len(xc) == 0:
                return
            E = xc[:, [1 << k for k in range(d)], :] - xc[:, :1, :]          # (nc, d, d) rows = edges
            bits = np.array([[(a >> k) & 1 for k in range(d)] for a in range(nv)], dtype=float)
            pred = xc[:, :1, :] + np.einsum("ak,ckj->caj", bits, E)
            if np.allclose(pred, xc, rtol=0, atol=1e-10 * max(1.0, np.abs(xc).max())):
                self.affine_Jinv = np.ascontiguousarray(np.linalg.inv(np.transpose(E, (0, 2, 1))))
            return
        xc = self.node_x[self.cell_nodes]                     # (nc, d+1, d)
        J = np.transpose(xc[:, 1:, :] - xc[:, :1, :], (0, 2, 1))   # J[c, i, k] = x_{k+1,i} - x_{0,i}
        Jinv = np.linalg.inv(J)
        grad = np.empty((len(xc), nv, d))
        grad[:, 1:, :] = Jinv                                 # grad xi_k = row k of J^-1
        grad[:, 0, :] = -Jinv.sum(axis=1)
        self.simplex_Jinv = self.affine_Jinv = np.ascontiguousarray(Jinv)
        self.simplex_grad = np.ascontiguousarray(grad)
        self.cell_volume_ref = 1.0 / (2.0 if d == 2 else 6.0)

    def _min_cell_size(self):
        if self.n_cells == 0:
            local = np.inf
        elif self.kind == ks.SIMPLEX:
            # smallest altitude = 1 / max |grad N_a|
            local = 1.0 / np.max(np.linalg.norm(self.simplex_grad, axis=2))
        else:
            xc = self.node_x[self.cell_nodes]
            edges = [np.linalg.norm(xc[:, a ^ (1 << k)] - xc[:, a], axis=1)
                     for a in range(xc.shape[1]) for k in range(self.gdim) if not a & (1 << k)]
            local = float(np.min(edges))
        from mpi4py import MPI
        return self.comm.allreduce(local, op=MPI.MIN) if self.comm.size > 1 else local

    def _detect_structured(self):
        """Recognise a lattice of equal axis-aligned boxes, each holding whole cells."""
        if self.n_cells == 0:
            return None
        xc = self.node_x[self.cell_nodes]
        cmin, cmax = xc.min(axis=1), xc.max(axis=1)
        ext = cmax - cmin
        spacing = ext[0].copy()
        if np.any(spacing <= 0) or not np.allclose(ext, spacing, rtol=1e-9, atol=0.0):
            return None
        lo = self.node_x.min(axis=0)
        t = (self.node_x - lo) / spacing
        if not np.allclose(t, np.round(t), atol=1e-7):
            return None
        nbox = np.round((self.node_x.max(axis=0) - lo) / spacing).astype(np.int64)
        ijk = np.floor(((cmin + cmax) / 2 - lo) / spacing).astype(np.int64)
        strides = np.cumprod(np.concatenate([[1], nbox[:-1]]))
        flat = ijk @ strides
        order = np.argsort(flat, kind="stable")
        counts = np.bincount(flat, minlength=int(np.prod(nbox)))
        per_box = int(counts.max())
        if per_box > 8:
            return None
        table = np.full((len(counts), per_box), -1, dtype=np.int32)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        rank_in_box = np.arange(len(flat)) - starts[flat[order]]
        table[flat[order], rank_in_box] = order.astype(np.int32)
        return dict(origin=lo, spacing=spacing, nbox=nbox, table=table)

    def _global_lattice(self):
        """The structured lattice's global lower corner and spacing (`origin_global`,
        `spacing_global`: the minima over ranks), its global upper corner (`upper_global`, the
        maximum of the ranks' largest node coordinates) and the global index of this rank's
        first box (`first`), for locate: with its own corner and spacing each rank computed its
        own (x - origin) / spacing, and a point on a grid line between two ranks could fall in the
        ghost box on both (penalty polylines along a rank boundary were then located by
        neither, and the contact lost). Collective."""
        s = self._structured
        mine = (np.concatenate([s["origin"], s["spacing"], -self.node_x.max(axis=0)])
                if s is not None else np.full(3 * self.gdim, np.inf))
        g = np.array(mine, dtype=np.float64)
        if self.comm.size > 1:                  # the spacing too: each rank measured its own
            from mpi4py import MPI
            self.comm.Allreduce(np.ascontiguousarray(mine, dtype=np.float64), g, op=MPI.MIN)
        if s is not None:
            d = self.gdim
            s["origin_global"], s["spacing_global"] = g[:d], g[d: 2 * d]
            s["upper_global"] = -g[2 * d:]
            s["first"] = np.rint((s["origin"] - s["origin_global"])
                                 / s["spacing_global"]).astype(np.int64)

    # ------------------------------------------------------------------ location
    def locate(self, x, cells=None):
        """Cell and reference coordinates of points x (n, gdim).

        `cells` (optional) holds each point's previous cell: on unstructured meshes and on
        structured triangle/tetrahedron grids (a box holds several simplices) only the points
        that left it are searched again; structured quadrilaterals/hexahedra locate by
        arithmetic alone. Points in no local cell get cell -1.
        Returns (cells int32, xi float64)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        n = x.shape[0]
        xi = np.zeros((n, self.gdim))
        out = np.full(n, -1, dtype=np.int32)
        if n == 0:
            return out, xi
        s = self._structured
        if s is not None and (cells is None or self.kind != ks.SIMPLEX):
            ks.locate_structured(self.D, self.kind, x, s["origin_global"], s["first"],
                                 s["spacing_global"], s["nbox"], s["table"],
                                 self.cell_nodes, self.node_x, self.affine_Jinv, out, xi)
            return out, xi
        inside = np.zeros(n, dtype=np.bool_)
        if cells is not None:
            out[:] = cells
            ks.pull_back(self.kind, x, out, self.cell_nodes, self.node_x, self.affine_Jinv,
                         xi, inside)
        lost = np.flatnonzero(~inside)
        if len(lost):
            found, xl = self.locate(x[lost]) if s is not None else self._tree_locate(x[lost])
            out[lost] = found
            xi[lost] = xl
        return out, xi

    def _tree_locate(self, x):
        """Bounding-box-tree candidates, confirmed by the exact pull-back (not by dolfinx's
        convex-hull test, which is wrong for the curved faces of non-affine hexahedra)."""
        if self._tree is None:
            self._tree = geometry.BoundingBoxTree(self.mesh, self.mesh.topology.dim)
        pts = np.zeros((len(x), 3))
        pts[:, : self.gdim] = x
        cand = geometry.compute_collisions(self._tree, pts)
        cells = np.empty(len(x), dtype=np.int32)
        xi = np.zeros((len(x), self.gdim))
        ks.first_inside(self.kind, np.ascontiguousarray(x), cand.offsets.astype(np.int64),
                        cand.array.astype(np.int32), self.cell_nodes, self.node_x,
                        self.affine_Jinv, cells, xi)
        return cells, xi

    def has_vertex_ring(self):
        """Whether every cell touching a vertex of an owned cell is local (collective).

        Always true in serial; in parallel it holds for meshes created with
        partitioner=vertex_ghost_partitioner(), not with dolfinx's shared_facet ghosts
        (diagonal neighbours are missing). Shape functions wider than one cell (GIMP, CPDI) need it. Compares, per
        node, the local count of cells containing it with the global count."""
        if self.comm.size == 1:
            return True
        from mpi4py import MPI
        owned = np.zeros(self.n_nodes)
        np.add.at(owned, self.cell_nodes[: self.n_owned_cells].ravel(), 1.0)
        self.accumulate(owned)
        local = np.zeros(self.n_nodes)
        np.add.at(local, self.cell_nodes.ravel(), 1.0)
        need = np.unique(self.cell_nodes[: self.n_owned_cells])
        ok = bool(np.all(local[need] == owned[need]))
        return self.comm.allreduce(ok, op=MPI.LAND)

    # ------------------------------------------------------------------ nodes
    def nodes_where(self, where):
        """Boolean mask over local nodes for a locator where(x) -> bool, x of shape (n, gdim)."""
        mask = np.asarray(where(self.node_x), dtype=bool)
        if mask.shape != (self.n_nodes,):
            raise ValueError(f"locator must return one bool per point, shape ({self.n_nodes},), "
                             f"got {mask.shape}")
        return mask

    def global_count(self, mask_owned):
        """Global number of True entries in a mask over owned entities."""
        n = int(np.count_nonzero(mask_owned))
        return self.comm.allreduce(n) if self.comm.size > 1 else n

    def _node_coordinates(self):
        """(n_nodes, gdim) node coordinates: on a P1 geometry the mesh's own coordinates,
        copied through the cells' dofmaps, so the same bits on every partition
        (tabulate_dof_coordinates evaluates the coordinate element at the reference vertices,
        whose round-off depends on the cell a node is reached from: the particle positions of
        Particles.fill then differed in their last bits between rank counts); otherwise
        tabulate_dof_coordinates."""
        msh = self.mesh
        gdofs = msh.geometry.dofmap.array
        if len(gdofs) != len(self.V.dofmap.list.array):          # a higher-order geometry
            return np.ascontiguousarray(self.V.tabulate_dof_coordinates()[:, : self.gdim])
        x = np.empty((self.n_nodes, self.gdim))
        x[self.V.dofmap.list.array] = msh.geometry.x[gdofs, : self.gdim]
        return x

    def accumulate(self, *arrays):
        """Sum nodal contributions across ranks (reverse scatter with add, then forward).

        A no-op on one rank. Each array has shape (n_nodes,) or (n_nodes, k). With periodic
        sides (`periodic`, boundaries.periodic) the sums are then tied over the node pairs."""
        if self.comm.size > 1:
            self._scatter(arrays, add=True)
        if self.periodic is not None:
            self.periodic.tie(*arrays)

    def _scatter(self, arrays, add):
        """Through a dolfinx vector of the nodes' index map: with add, the ghosts' values
        added to their owners' (reverse scatter); then the owners' values to the ghosts."""
        from dolfinx.la import ScatterMode, vector
        imap = self.V.dofmap.index_map
        for arr in arrays:
            bs = 1 if arr.ndim == 1 else arr.shape[1]
            vec = self._exchange.get(bs)
            if vec is None:
                vec = self._exchange[bs] = vector(imap, bs=bs)
            vec.array[:] = arr.ravel()
            if add:
                vec.scatter_reverse(ScatterMode.add)
            vec.scatter_forward()
            arr[...] = vec.array.reshape(arr.shape)

    def update_ghosts(self, *arrays):
        """Copy each owned node's value to its ghost copies on the other ranks (a forward
        scatter; arrays of shape (n_nodes,) or (n_nodes, k)). A no-op on one rank."""
        if self.comm.size > 1:
            self._scatter(arrays, add=False)

    def ensure_vertex_ring(self):
        """Give the mesh the vertex ghost layer that shape functions wider than one cell (GIMP,
        CPDI) need in parallel, when it lacks it (dolfinx's default shared-facet ghosts miss
        the diagonal neighbours): the mesh is created again from the same cells with the same
        owners and partitioner=vertex_ghost_partitioner(), and this Grid re-initialised on it
        (`mesh` is then the new dolfinx mesh; particles must be located again). Collective;
        returns True when the mesh was rebuilt."""
        if self.has_vertex_ring():
            return False
        from dolfinx import graph
        from mpi4py import MPI
        msh, tdim, gdim = self.mesh, self.mesh.topology.dim, self.gdim
        n_own = msh.topology.index_map(tdim).size_local
        gmap = msh.geometry.index_map()
        nv = len(msh.geometry.dofmap.links(0)) if n_own else 0
        nv = self.comm.allreduce(nv, op=MPI.MAX)
        dofs = msh.geometry.dofmap.array.reshape(-1, nv)[:n_own]
        cells = np.asarray(gmap.local_to_global(dofs.ravel()), dtype=np.int64).reshape(n_own, nv)
        x = np.ascontiguousarray(msh.geometry.x[: gmap.size_local, :gdim])

        def keep_owners(comm, nparts, tdim_, cells_, ghost_mode):
            n = len(cells_.offsets) - 1
            return graph.create_adjacencylist(np.full(n, comm.rank, dtype=np.int32),
                                              np.arange(n + 1, dtype=np.int32))

        new = dolfinx.mesh.create_mesh(self.comm, cells, x, msh.ufl_domain(),
                                       partitioner=vertex_ghost_partitioner(keep_owners))
        self.__init__(new, axisymmetric=self.axisymmetric)
        return True

    def reduce_max(self, values, nodes=None):
        """The maximum over ranks of per-node values, (n_nodes,) or (n_nodes, k), or given at
        local `nodes` only: a node shared by ranks gets the largest value any rank has (a
        reverse scatter with MAX, then forward); collective."""
        from petsc4py import PETSc
        v = np.asarray(values, dtype=np.float64)
        bs = 1 if v.ndim == 1 else v.shape[1]
        vec = self._max_vec.get(bs)
        if vec is None:
            vec = self._max_vec[bs] = dolfinx.la.create_petsc_vector(self.V.dofmap.index_map, bs)
        with vec.localForm() as loc:
            a = loc.array.reshape(self.n_nodes, bs)
            if nodes is None:
                a[:] = v.reshape(self.n_nodes, bs)
            else:
                a[:] = -np.inf
                a[nodes] = v.reshape(len(nodes), bs)
        vec.ghostUpdate(addv=PETSc.InsertMode.MAX_VALUES, mode=PETSc.ScatterMode.REVERSE)
        vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        with vec.localForm() as loc:
            a = loc.array.reshape(self.n_nodes, bs)
            out = (a if nodes is None else a[nodes]).copy()
        return out.reshape(v.shape)


def vertex_ghost_partitioner(partitioner=None):
    """A dolfinx cell partitioner whose ghost layer holds every cell sharing a vertex with a
    rank's owned cells: what GhostMode.shared_vertex would give (dolfinx 0.5 disables that
    mode). GIMP and CPDI shape functions need it in parallel, e.g.
        create_rectangle(comm, pts, n, CellType.quadrilateral,
                         partitioner=fenicsmpm.grid.vertex_ghost_partitioner())
    `partitioner` (default dolfinx's create_cell_partitioner()) chooses the owners. The
    vertex neighbours are found without gathering the mesh: each (vertex, owner) pair goes to
    the vertex's home rank (vertex mod size), which returns every owner of the vertex to the
    ranks holding a cell that uses it (two all-to-all exchanges)."""
    from dolfinx import graph
    from dolfinx.cpp.mesh import create_cell_partitioner
    base = create_cell_partitioner() if partitioner is None else partitioner

    def partition(comm, nparts, tdim, cells, ghost_mode):
        dest = base(comm, nparts, tdim, cells, ghost_mode)
        n = len(cells.offsets) - 1
        owner = np.asarray(dest.array)[np.asarray(dest.offsets)[:-1]].astype(np.int64)
        k = int(cells.offsets[1] - cells.offsets[0]) if n else 0
        arr = np.asarray(cells.array, dtype=np.int64).reshape(n, k)
        pairs = _vertex_owners(comm, arr.ravel(), np.repeat(owner, k))
        # (cell, rank) for every owner rank of every vertex of the cell
        lo = np.searchsorted(pairs[:, 0], arr.ravel(), side="left")
        cnt = np.searchsorted(pairs[:, 0], arr.ravel(), side="right") - lo
        cell = np.repeat(np.repeat(np.arange(n), k), cnt)
        take = np.repeat(lo - np.r_[0, np.cumsum(cnt)[:-1]], cnt) + np.arange(cnt.sum())
        cr = np.unique(np.stack([cell, pairs[take, 1]], axis=1), axis=0)
        cr = cr[cr[:, 1] != owner[cr[:, 0]]]                    # ghosts: ranks other than owner
        rows = np.concatenate([np.stack([np.arange(n), owner], axis=1), cr])
        rows = rows[np.lexsort((np.r_[np.zeros(n), np.ones(len(cr))], rows[:, 0]))]
        offsets = np.searchsorted(rows[:, 0], np.arange(n + 1)).astype(np.int32)
        return graph.create_adjacencylist(rows[:, 1].astype(np.int32), offsets)
    return partition


def _vertex_owners(comm, vertices, owners):
    """Sorted unique (vertex, owner rank) pairs for every vertex in `vertices`, whatever rank
    holds the other cells using it (distributed by vertex mod size)."""
    size = comm.size
    me = np.stack([vertices, owners], axis=1)

    def route(rows, to):
        order = np.argsort(to, kind="stable")
        counts = np.bincount(to, minlength=size)
        return comm.alltoall(np.split(rows[order], np.cumsum(counts)[:-1]))

    got = route(np.c_[me, np.full(len(me), comm.rank)], vertices % size)
    got = np.concatenate(got) if got else np.zeros((0, 3), np.int64)
    known = np.unique(got[:, :2], axis=0)                       # (vertex, owner) at home
    asked = np.unique(got[:, [0, 2]], axis=0)                   # (vertex, asking rank)
    lo = np.searchsorted(known[:, 0], asked[:, 0], side="left")
    cnt = np.searchsorted(known[:, 0], asked[:, 0], side="right") - lo
    take = np.repeat(lo - np.r_[0, np.cumsum(cnt)[:-1]], cnt) + np.arange(cnt.sum())
    reply = known[take]
    back = route(reply, np.repeat(asked[:, 1], cnt))
    back = np.concatenate(back) if back else np.zeros((0, 2), np.int64)
    return np.unique(back.reshape(-1, 2), axis=0)
