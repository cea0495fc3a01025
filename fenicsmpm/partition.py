"""A deterministic partition of `dolfinx.mesh.create_rectangle` meshes into strips.

dolfinx's graph partitioners (SCOTCH, ParMETIS) do not cut a mesh the same way twice, even
in one process, so two runs on the same number of ranks differ in particle order and in the
order of floating-point sums. A run that must be reproducible bit for bit (a restart from a
checkpoint compared with the continuous run, a regression test) builds its mesh with

    msh = create_rectangle(comm, [[x0, y0], [x1, y1]], [nx, ny], cell_type,
                           partitioner=fm.partition.strips(nx, ny, axis=0))

Cells go to ranks by the position of their centre along `axis` (equal strips); ghosts are the
shared-facet layer (dolfinx's default GhostMode.shared_facet) plus, with `vertex_ghosts`, every
cell sharing a vertex with another rank's cells (GhostMode.shared_vertex)."""
import itertools

import numpy as np
from dolfinx import graph
from dolfinx.mesh import compute_midpoints


def strips(nx, ny, axis=0, vertex_ghosts=False):
    """Cell partitioner for `create_rectangle(..., [nx, ny], ...)` (quadrilaterals or
    triangles with the default diagonal). dolfinx 0.5 numbers the input vertices column by
    column, v = ix (ny + 1) + iy; `check_strips` verifies the result on the mesh."""
    for name, val in (("nx", nx), ("ny", ny)):
        if not (isinstance(val, (int, np.integer)) and val >= 1):
            raise ValueError(f"strips: '{name}' must be a positive integer, got {val!r}")
    if axis not in (0, 1):
        raise ValueError(f"strips: 'axis' must be 0 or 1, got {axis!r}")

    def partition(comm, nparts, tdim, cells, ghost_mode=None):
        if len(cells.offsets) < 2:                                  # no cells on this rank
            return graph.create_adjacencylist(np.zeros(0, np.int32), np.zeros(1, np.int32))
        k = int(cells.offsets[1] - cells.offsets[0])
        arr = np.asarray(cells.array, dtype=np.int64).reshape(-1, k)
        coord = arr // (ny + 1) / nx if axis == 0 else arr % (ny + 1) / ny
        owner = np.minimum((coord.mean(axis=1) * nparts).astype(np.int32), nparts - 1)
        shared = 1 if vertex_ghosts else 2                          # vertices in common
        pairs = _neighbour_pairs(arr, shared)
        ghosts = [set() for _ in range(len(arr))]
        for i, j in pairs[owner[pairs[:, 0]] != owner[pairs[:, 1]]]:
            ghosts[i].add(int(owner[j]))
            ghosts[j].add(int(owner[i]))
        dest = [[int(owner[i])] + sorted(ghosts[i]) for i in range(len(arr))]
        offsets = np.cumsum([0] + [len(d) for d in dest]).astype(np.int32)
        flat = np.array([r for d in dest for r in d], dtype=np.int32)
        return graph.create_adjacencylist(flat, offsets)
    return partition


def _neighbour_pairs(arr, shared):
    """Pairs (i, j) of cells with at least `shared` vertices in common (1 or 2)."""
    if shared == 2:                                 # a common edge: a vertex pair in both
        combos = np.array(list(itertools.combinations(range(arr.shape[1]), 2)))
        edges = np.sort(arr[:, combos], axis=2).reshape(-1, 2)
        key = edges[:, 0] * (arr.max() + 1) + edges[:, 1]
        owner = np.repeat(np.arange(len(arr)), len(combos))
    else:
        key = arr.ravel()
        owner = np.repeat(np.arange(len(arr)), arr.shape[1])
    order = np.argsort(key, kind="stable")
    key, owner = key[order], owner[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    groups = np.split(owner, starts[1:])
    pairs = [(a, b) for g in groups if len(g) > 1 for a, b in itertools.combinations(g, 2)]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def check_strips(msh, axis=0, bounds=(0.0, 1.0)):
    """Raise if a rank owns a cell outside its strip of [bounds] along `axis`."""
    comm, tdim = msh.comm, msh.topology.dim
    n_owned = msh.topology.index_map(tdim).size_local
    mid = compute_midpoints(msh, tdim, np.arange(n_owned, dtype=np.int32))[:, axis]
    a, b = bounds
    lo, hi = a + (b - a) * comm.rank / comm.size, a + (b - a) * (comm.rank + 1) / comm.size
    if not np.all((mid > lo) & (mid < hi)):
        raise RuntimeError("strips: the mesh was not cut where it was asked (has dolfinx changed "
                           "its vertex numbering of create_rectangle?)")
