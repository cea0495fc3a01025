"""Particles: the material-point cloud as contiguous arrays (structure of arrays).

Material points are a quadrature cloud: every grid integral is a sum over particles with
weight V_p. `fill` places n points per direction in each owned cell with volumes equal to
the cell measure split exactly (|det J| times the reference weight), so the cloud
integrates the cell volume exactly.
"""
import numpy as np

from .kernels.axisymmetric import check_radius
from .shapes import standard as ks

# name -> (trailing shape as a function of gdim, dtype)
FIELDS = {
    "x": (lambda d: (d,), np.float64),        # position
    "v": (lambda d: (d,), np.float64),        # velocity
    "a": (lambda d: (d,), np.float64),        # acceleration (every integrator; explicit: (v_new - v_old) / dt)
    "u": (lambda d: (d,), np.float64),        # displacement since creation
    "mass": (lambda d: (), np.float64),
    "V0": (lambda d: (), np.float64),         # initial volume
    "V": (lambda d: (), np.float64),          # current volume
    "F": (lambda d: (3, 3), np.float64),      # deformation gradient (plane strain in 2D)
    "stress": (lambda d: (3, 3), np.float64), # Cauchy stress, tension positive
    "work": (lambda d: (), np.float64),       # accumulated stress work (strain energy) per particle
    "material_id": (lambda d: (), np.int32),
    "cell": (lambda d: (), np.int32),
    "xi": (lambda d: (d,), np.float64),       # reference coordinates in `cell`
    "id": (lambda d: (), np.int64),           # global particle id
}


def _reference_points(cell_type, n):
    """n points per direction in the reference cell, and their weights (sum = ref volume)."""
    from dolfinx.mesh import CellType
    if cell_type in (CellType.quadrilateral, CellType.hexahedron):
        d = 2 if cell_type == CellType.quadrilateral else 3
        t = (np.arange(n) + 0.5) / n
        pts = np.stack(np.meshgrid(*([t] * d), indexing="ij"), axis=-1).reshape(-1, d)
        return pts, np.full(len(pts), 1.0 / n ** d)
    d = 2 if cell_type == CellType.triangle else 3
    verts = simplex_subdivision(d, n)
    return verts.mean(axis=1), np.full(len(verts), (0.5 if d == 2 else 1.0 / 6.0) / n ** d)


def _simplex_points(grid, nc, ref, n):
    """Positions (nc len(ref), gdim) of the reference points `ref` (sub-simplex centroids of
    simplex_subdivision(d, n)) in the first nc cells, and |det J| per point, computed from
    the cells' vertices sorted by their coordinates: the same bits on every partition.
    (dolfinx orders a simplex's vertices by their global index, which depends on the
    partition; x = X_0 + J xi then differed in its last bits between runs on different rank
    counts, and a `region` bound through a centroid kept different particles.) x is the
    barycentric sum sum_k lambda_k X_k in that order, lambda_k = m_k / (n (d + 1)), m_k integers."""
    d = ref.shape[1]
    den = n * (d + 1)
    m = np.rint(ref * den).astype(np.int64)
    m = np.column_stack([den - m.sum(axis=1), m])                # (npts, d + 1), actual order
    if not np.allclose(m[:, 1:] / den, ref, rtol=0.0, atol=1e-13):
        raise AssertionError("Particles.fill: reference points are not sub-simplex centroids")
    X = grid.node_x[grid.cell_nodes[:nc]][:, :, :d]                   # (nc, d + 1, d)
    order = np.lexsort(tuple(X[:, :, a] for a in reversed(range(d))), axis=-1)
    Xs = np.take_along_axis(X, order[:, :, None], axis=1)
    lam = m.T[order] / den                                            # (nc, d + 1, npts)
    x = lam[:, 0, :, None] * Xs[:, 0, None, :]
    for k in range(1, d + 1):
        x = x + lam[:, k, :, None] * Xs[:, k, None, :]
    det = np.abs(np.linalg.det(Xs[:, 1:] - Xs[:, :1])) if nc else np.zeros(0)
    out = np.zeros((nc * len(ref), grid.gdim))
    out[:, :d] = x.reshape(-1, d)
    return out, np.repeat(det, len(ref))


def simplex_subdivision(d, n):
    """The n^d sub-simplices of equal measure that tile the reference triangle (d = 2) or
    tetrahedron (d = 3), as their reference vertices (n^d, d + 1, d). Particles.fill puts one
    particle at each centroid; CPDI uses the sub-simplices as the particles' domains
    (shapes.cpdi.initial_simplices), so they tile the cell. Triangles: the n^2 congruent
    sub-triangles, the upright ones first; tetrahedra: tet_subdivision."""
    if d == 3:
        return tet_subdivision(n)
    up = [[(i, j), (i + 1, j), (i, j + 1)] for i in range(n) for j in range(n - i)]
    down = [[(i + 1, j + 1), (i, j + 1), (i + 1, j)] for i in range(n) for j in range(n - 1 - i)]
    return np.array(up + down, dtype=float) / n


def tet_subdivision(n):
    """The n^3 sub-tetrahedra of equal volume that tile the reference tetrahedron (the
    edgewise subdivision: the Kuhn tetrahedra of the unit cubes inside the n-scaled Kuhn
    simplex 0 <= c <= b <= a <= n, mapped affinely onto the reference tetrahedron), as their
    reference vertices (n^3, 4, 3)."""
    import itertools
    kuhn = []
    for c in itertools.product(range(n), repeat=3):
        for perm in itertools.permutations(range(3)):
            v = [np.array(c, dtype=float)]
            for ax in perm:
                v.append(v[-1] + np.eye(3)[ax])
            v = np.array(v)
            if np.all((v[:, 0] >= v[:, 1]) & (v[:, 1] >= v[:, 2]) & (v[:, 2] >= 0)
                      & (v[:, 0] <= n)):
                kuhn.append(v)
    kuhn = np.array(kuhn) / n                         # in the Kuhn simplex a >= b >= c
    # Kuhn simplex (0,0,0), (1,0,0), (1,1,0), (1,1,1) -> reference (0,0,0), e1, e2, e3:
    # xi = (a - b, b - c, c)
    a, b, c = kuhn[..., 0], kuhn[..., 1], kuhn[..., 2]
    return np.stack([a - b, b - c, c], axis=-1)


class Particles:
    """State arrays of the local particles (see FIELDS) plus the list of materials.

    `material_id[p]` indexes `materials`; `state` holds per-particle history variables,
    (n, max n_state of the materials)."""

    def __init__(self, grid, materials, **arrays):
        self.grid = grid
        self.gdim = grid.gdim
        self.materials = list(materials)
        n = len(arrays["x"])
        for name, (shape, dtype) in FIELDS.items():
            arr = arrays.get(name)
            if arr is None:
                arr = np.zeros((n,) + shape(self.gdim), dtype=dtype)
                if name == "F":
                    arr[:] = np.eye(3)
            setattr(self, name, np.ascontiguousarray(arr, dtype=dtype))
        n_state = max([m.n_state for m in self.materials] + [0])
        st = arrays.get("state")
        self.state = np.zeros((n, n_state)) if st is None else np.ascontiguousarray(st)
        self.version = 0          # bumped whenever particles are reshuffled (migration)
        self.optional = []        # names of optional fields added with add_field

    def add_field(self, name, trailing_shape=(), dtype=np.float64):
        """Add an optional per-particle field (zeros), e.g. sigma_ini of a staged analysis or
        the data of a particle-layer boundary. It migrates with the particles; scenes that do
        not use a feature do not carry its fields. Returns the array."""
        if not hasattr(self, name):
            setattr(self, name, np.zeros((len(self),) + tuple(trailing_shape), dtype=dtype))
            self.optional.append(name)
        return getattr(self, name)

    def field_names(self):
        """Every per-particle array that moves with a particle (FIELDS, state, optional)."""
        return list(FIELDS) + ["state"] + self.optional

    def __len__(self):
        return len(self.x)

    def n_global(self):
        """The number of particles on all ranks.

        Collective: under MPI it is a reduction over the grid's communicator, so every rank
        must call it, at the same point of the script (never inside `if rank == 0:`, where
        the other ranks would not join and rank 0 would wait for ever). Call it on every rank
        and print on one: `n = p.n_global(); if rank == 0: print(n)`. `len(p)` is the local
        count (no communication)."""
        n = len(self)
        return self.grid.comm.allreduce(n) if self.grid.comm.size > 1 else n

    # ------------------------------------------------------------------ creation
    @classmethod
    def fill(cls, grid, material, per_cell=2, region=None, velocity=None):
        """Fill every owned cell with per_cell points per direction (triangles and tetrahedra:
        per_cell^d at the centroids of the equal sub-simplices of simplex_subdivision).

        region(x) -> bool (x of shape (n, gdim)) keeps a subset; velocity is a constant
        vector or a callable velocity(x) -> (n, gdim)."""
        if isinstance(per_cell, bool) or not isinstance(per_cell, (int, np.integer)) or per_cell < 1:
            raise ValueError(f"Particles.fill: 'per_cell' must be a positive integer, got {per_cell!r}")
        _check_material(material)
        ref, w = _reference_points(grid.cell_type, int(per_cell))
        nc = grid.n_owned_cells
        cells = np.repeat(np.arange(nc, dtype=np.int32), len(ref))
        xi = np.ascontiguousarray(np.tile(ref, (nc, 1)))
        if grid.kind == ks.SIMPLEX:
            x, detJ = _simplex_points(grid, nc, ref, int(per_cell))
        else:
            x = np.empty((len(cells), grid.gdim))
            detJ = np.empty(len(cells))
            ks.reference_points_to_physical(grid.kind, cells, xi, grid.cell_nodes, grid.node_x,
                                            x, detJ)
        vol = detJ * np.tile(w, nc)
        if region is not None:
            if not callable(region):
                raise TypeError(f"Particles.fill: 'region' must be a function region(x) -> "
                                f"bool array, got {type(region).__name__}")
            keep = np.asarray(region(x))
            if keep.shape != (len(x),):
                raise ValueError(f"Particles.fill: 'region(x)' must return one bool per point, "
                                 f"shape ({len(x)},), got shape {keep.shape}")
            keep = keep.astype(bool)
            cells, xi, x, vol = cells[keep], xi[keep], x[keep], vol[keep]
        if grid.global_count(np.ones(len(x), bool)) == 0:
            raise ValueError("Particles.fill: the region selects no particle")
        return cls._create(grid, material, x, vol, cells, xi, velocity)

    @classmethod
    def from_points(cls, grid, material, x, volume, velocity=None):
        """Particles at given points `x`, an (n, gdim) array, with given volumes `volume` (a
        number, or an (n,) array; meridian areas on an axisymmetric grid). Each point goes to
        the rank that owns its cell; points outside the mesh raise a ValueError. Collective:
        every rank passes its own points (possibly none)."""
        _check_material(material)
        x = _point_array(x, grid.gdim, "Particles.from_points", "x", grid)
        vol = np.asarray(volume, dtype=np.float64) if _is_numeric(volume) else None
        if vol is None or vol.ndim > 1 or (vol.ndim == 1 and vol.shape != (len(x),)):
            raise ValueError(f"Particles.from_points: 'volume' must be a number or an array of "
                             f"one volume per point, shape ({len(x)},), got "
                             f"{np.shape(volume) if vol is not None else type(volume).__name__}")
        vol = np.broadcast_to(vol, (len(x),)).copy()
        if np.any(~(vol > 0)) or np.any(~np.isfinite(vol)):
            bad = vol[~(np.isfinite(vol) & (vol > 0))][0]
            raise ValueError(f"Particles.from_points: 'volume' must be finite and > 0, got {bad}")
        cells, xi = grid.locate(x)
        p = cls._create(grid, material, x, vol, cells, xi, velocity)
        ids, xs = p.send_to_owners()
        if len(ids):
            raise ValueError(f"Particles.from_points: {len(ids)} point(s) lie outside the mesh, "
                             f"first at x = {tuple(xs[0])}")
        p._number()
        return p

    @classmethod
    def fill_edges(cls, grid, material, region=None, velocity=None):
        """One particle per edge of a triangle mesh, its domain the edge's diamond: the two
        triangles (a, b, c_k) that join the edge (a, b) to the centroids c_k of the cells on
        either side (one cell and the edge midpoint on the mesh boundary), so the domains
        tile the body, 1.5 particles a cell. The particle sits at the diamond's centroid with
        its area and carries its corners (a, c_1, b, c_2) as the quadrilateral CPDI2 domain
        (field `cpdi_corners`; shapes.cpdi): a domain over two cells averages their P1
        gradients, the edge-based smoothing of ES-FEM (Liu, Nguyen-Thoi & Lam 2009), whose
        stress converges faster than the single cell's gradient of Particles.fill's
        sub-triangles (V3 MMS, docs/guide/choosing.md). Use with shape="auto"/"cpdi2".

        region(x) -> bool selects the material cells by their centroids (an edge between a
        material cell and another gets the material side's half); velocity as in fill.
        2D triangle meshes only (ValueError otherwise). Collective: gives the mesh the vertex
        ghost layer (Grid.ensure_vertex_ring), so every rank sees both cells of the edges it
        owns; each edge's particle goes to the rank owning its centroid's cell."""
        _check_material(material)
        if grid.gdim != 2 or grid.kind != ks.SIMPLEX or grid.axisymmetric:
            raise ValueError("Particles.fill_edges: needs a plane 2D triangle mesh "
                             "(CellType.triangle, not axisymmetric); use Particles.fill")
        grid.ensure_vertex_ring()
        topo = grid.mesh.topology
        topo.create_entities(1)
        topo.create_connectivity(2, 1)
        nc = grid.n_cells
        c2e = topo.connectivity(2, 1).array.reshape(-1, 3)[:nc]
        X = grid.node_x[grid.cell_nodes][:, :, :2]                 # (nc, 3, 2)
        # every sum below in an order fixed by the coordinates (not by the partition's vertex
        # numbering), so the particles are the same bits on any number of ranks (_simplex_points)
        Xs = np.take_along_axis(X, np.lexsort((X[:, :, 1], X[:, :, 0]), axis=-1)[:, :, None], 1)
        cen = (Xs[:, 0] + Xs[:, 1] + Xs[:, 2]) / 3.0
        mat_cell = np.ones(nc, dtype=bool)
        if region is not None:
            if not callable(region):
                raise TypeError(f"Particles.fill_edges: 'region' must be a function region(x) "
                                f"-> bool array, got {type(region).__name__}")
            mat_cell = np.asarray(region(cen)).astype(bool)
            if mat_cell.shape != (nc,):
                raise ValueError(f"Particles.fill_edges: 'region(x)' must return one bool per "
                                 f"point, shape ({nc},), got shape {mat_cell.shape}")
        # the pieces (a, b, c) of every material cell, local edge i opposite vertex i
        c_idx, i_idx = np.nonzero(np.broadcast_to(mat_cell[:, None], (nc, 3)))
        edge = c2e[c_idx, i_idx]
        keep = edge < topo.index_map(1).size_local                 # edges this rank owns
        c_idx, i_idx, edge = c_idx[keep], i_idx[keep], edge[keep]
        a = X[c_idx, (i_idx + 1) % 3]
        b = X[c_idx, (i_idx + 2) % 3]
        swap = (a[:, 0] > b[:, 0]) | ((a[:, 0] == b[:, 0]) & (a[:, 1] > b[:, 1]))
        a, b = np.where(swap[:, None], b, a), np.where(swap[:, None], a, b)
        c = cen[c_idx]
        area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                            - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))
        order = np.lexsort((c[:, 1], c[:, 0], edge))             # by edge, its pieces by c
        edge, a, b, c, area = edge[order], a[order], b[order], c[order], area[order]
        first = np.flatnonzero(np.diff(edge, prepend=-1) != 0)       # an edge's first piece
        two = np.diff(np.append(first, len(edge))) == 2
        sec = np.where(two, first + 1, first)
        A = area[first] + np.where(two, area[sec], 0.0)
        x = (area[first, None] * (a[first] + b[first] + c[first])
             + np.where(two, area[sec], 0.0)[:, None] * (a[sec] + b[sec] + c[sec])) / (3.0 * A[:, None])
        corners = np.stack([a[first], c[first], b[first],
                            np.where(two[:, None], c[sec], 0.5 * (a[first] + b[first]))], axis=1)
        ccw = ((corners[:, 2, 0] - corners[:, 0, 0]) * (corners[:, 3, 1] - corners[:, 1, 1])
               - (corners[:, 3, 0] - corners[:, 1, 0]) * (corners[:, 2, 1] - corners[:, 0, 1]))
        corners[ccw < 0] = corners[ccw < 0][:, [0, 3, 2, 1]]
        if grid.global_count(np.ones(len(x), bool)) == 0:
            raise ValueError("Particles.fill_edges: the region selects no cell")
        cells, xi = grid.locate(np.ascontiguousarray(x))
        p = cls._create(grid, material, np.ascontiguousarray(x), A, cells, xi, velocity)
        p.add_field("cpdi_corners", (4, 2))[:] = corners
        p.send_to_owners()
        p._number()
        return p

    @classmethod
    def _create(cls, grid, material, x, vol, cells, xi, velocity):
        """vol is the cell-measure share of each point; on an axisymmetric grid it is a
        meridian area and the volume per radian is r vol (fenicsmpm.kernels.axisymmetric)."""
        n = len(x)
        if grid.axisymmetric:
            check_radius(x, "Particles")
            vol = vol * x[:, 0]
        v = np.zeros((n, grid.gdim))
        if velocity is not None:
            val = velocity(x) if callable(velocity) else velocity
            shapes = ((grid.gdim,), (n, grid.gdim)) if callable(velocity) else ((grid.gdim,),)
            if not _is_numeric(val) or np.shape(val) not in shapes:
                raise ValueError(f"Particles: 'velocity' must be a vector of length {grid.gdim} "
                                 f"or a function velocity(x) -> ({n}, {grid.gdim}) array, got "
                                 f"{'shape ' + str(np.shape(val)) if _is_numeric(val) else repr(val)}")
            v[:] = np.asarray(val, dtype=np.float64)
            n_bad = grid.global_count(~np.isfinite(v).all(axis=1))     # collective
            if n_bad:
                raise ValueError(f"Particles: 'velocity' must be finite, got non-finite values "
                                 f"at {n_bad} point(s)")
        p = cls(grid, [material], x=x, v=v, mass=material.density * vol, V0=vol, V=vol.copy(),
                cell=cells, xi=xi)
        p._number()
        return p

    def send_to_owners(self):
        """Hand particles to the rank owning their cell (MPI); return (ids, x) of particles
        in no cell of the global mesh (the same on all ranks). `cell` must be current."""
        if self.grid.comm.size > 1:
            from .migration import migrate
            return migrate(self)
        out = self.cell < 0
        return self.id[out], self.x[out]

    def _number(self):
        """Global ids 0..N-1, contiguous per rank."""
        comm = self.grid.comm
        start = comm.exscan(len(self)) if comm.size > 1 else 0
        self.id = np.arange(start or 0, (start or 0) + len(self), dtype=np.int64)

    def __add__(self, other):
        """Concatenate two particle sets on the same grid (materials are merged)."""
        if other.grid is not self.grid:
            raise ValueError("Particles: cannot add particle sets on different grids")
        mats = list(self.materials)
        remap = np.empty(len(other.materials), dtype=np.int32)
        for k, m in enumerate(other.materials):
            if not any(m is q for q in mats):
                mats.append(m)
            remap[k] = next(i for i, q in enumerate(mats) if q is m)
        edges = [hasattr(q, "cpdi_corners") for q in (self, other)]
        if edges[0] != edges[1]:
            raise ValueError("Particles: cannot add a set made by Particles.fill_edges (its "
                             "quadrilateral CPDI2 domains) to one without domains; make both "
                             "with fill_edges, or both with fill")
        if [n for n in self.optional + other.optional if n != "cpdi_corners"]:
            raise ValueError("Particles: add particle sets before starting stages or adding "
                             "particle-layer boundaries")
        extra = ["cpdi_corners"] if edges[0] else []
        arrays = {name: np.concatenate([getattr(self, name), getattr(other, name)])
                  for name in FIELDS}
        arrays["material_id"] = np.concatenate([self.material_id, remap[other.material_id]])
        n_state = max([m.n_state for m in mats] + [0])
        st = np.zeros((len(self) + len(other), n_state))
        st[: len(self), : self.state.shape[1]] = self.state
        st[len(self):, : other.state.shape[1]] = other.state
        p = Particles(self.grid, mats, state=st, **arrays)
        for name in extra:
            p.add_field(name, getattr(self, name).shape[1:])[:] = np.concatenate(
                [getattr(self, name), getattr(other, name)])
        p._number()
        return p

    # ------------------------------------------------------------------ diagnostics
    def total(self, values):
        """Global sum of a per-particle quantity (array over local particles)."""
        s = np.sum(values, axis=0)
        return self.grid.comm.allreduce(s) if self.grid.comm.size > 1 else s

    def kinetic_energy(self):
        """Global kinetic energy sum m v.v / 2 (collective)."""
        return float(self.total(0.5 * self.mass * np.einsum("pi,pi->p", self.v, self.v)))

    def mean_speed(self):
        """Global mass-weighted mean speed sum |v_p| m_p / sum m_p (seed 002 eq 5.12), the
        run-out diagnostic of collapses and slopes (collective)."""
        speed = np.linalg.norm(self.v, axis=1)
        s = self.total(np.column_stack([speed * self.mass, self.mass]))
        return float(s[0] / s[1])

    def strain_energy(self):
        """Global accumulated stress work (strain energy) of the particles (collective)."""
        return float(self.total(self.work))

    def momentum(self):
        """Global momentum sum m v, a vector of length gdim (collective)."""
        return self.total(self.mass[:, None] * self.v)


def _is_numeric(value):
    """Whether np.asarray(value) is a regular array of real numbers."""
    try:
        a = np.asarray(value)
    except ValueError:                  # ragged nested sequences (numpy >= 1.24)
        return False
    return a.dtype != object and (np.issubdtype(a.dtype, np.number) or a.dtype == bool) \
        and not np.iscomplexobj(a)


def _point_array(x, gdim, owner, name, grid=None):
    """x as a contiguous (n, gdim) float array; a ValueError naming `name` for ragged, wrongly
    shaped, non-numeric (this rank's points) or non-finite input (on any rank, when `grid` is
    given: then every rank raises)."""
    if not _is_numeric(x):
        raise ValueError(f"{owner}: '{name}' must be an array of points of shape (n, {gdim}), "
                         f"got a ragged or non-numeric {type(x).__name__}")
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == gdim:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != gdim:
        raise ValueError(f"{owner}: '{name}' must have shape (n, {gdim}), got {a.shape}")
    bad = ~np.isfinite(a).all(axis=1)
    n_bad = grid.global_count(bad) if grid is not None else int(np.count_nonzero(bad))
    if n_bad:
        first = f", first {tuple(a[bad][0])}" if np.any(bad) else ""
        raise ValueError(f"{owner}: '{name}' must be finite, got {n_bad} point(s) with NaN or "
                         f"inf coordinates{first}")
    return np.ascontiguousarray(a)


def _check_material(material):
    for attr in ("density", "stress", "tangent", "n_state"):
        if not hasattr(material, attr):
            raise TypeError(f"Particles: 'material' must be a fenicsmpm material, got "
                            f"{type(material).__name__}")
