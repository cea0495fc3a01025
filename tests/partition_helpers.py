"""A deterministic two-way split of `create_rectangle` meshes for the MPI tests.

dolfinx's default graph partitioner (SCOTCH/ParMETIS) may cut a mesh differently on another
machine, so a test that needs particles to cross a rank boundary fixes the cut itself:
cells whose centre lies at x < x_split go to rank 0, the rest to rank 1 (with more ranks, to
vertical strips). Ghosts are the shared-facet layer, as in dolfinx's GhostMode.shared_facet."""
import itertools

import numpy as np
from dolfinx import graph
from dolfinx.mesh import compute_midpoints


def strip_partitioner(n):
    """Partitioner for `create_rectangle(comm, [[0, 0], [1, 1]], [n, n], ...)`.

    dolfinx 0.5 numbers the rectangle's input vertices column by column, v = ix (n + 1) + iy;
    `assert_strips` checks the result, so a change of numbering fails loudly."""
    def partition(comm, nparts, tdim, cells, ghost_mode=None):
        if len(cells.offsets) < 2:                                  # no cells on this rank
            return graph.create_adjacencylist(np.zeros(0, np.int32), np.zeros(1, np.int32))
        k = int(cells.offsets[1] - cells.offsets[0])
        arr = np.asarray(cells.array, dtype=np.int64).reshape(-1, k)
        cx = (arr // (n + 1)).mean(axis=1) / n                      # cell centre x
        owner = np.minimum((cx * nparts).astype(np.int32), nparts - 1)
        # facet neighbours: two cells sharing a pair of vertices
        pairs = np.array(list(itertools.combinations(range(k), 2)))
        a = np.sort(arr[:, pairs], axis=2).reshape(-1, 2)
        cell_of = np.repeat(np.arange(len(arr)), len(pairs))
        _, inverse, counts = np.unique(a[:, 0] * (arr.max() + 1) + a[:, 1],
                                       return_inverse=True, return_counts=True)
        shared = counts[inverse] == 2
        order = np.argsort(inverse[shared], kind="stable")
        c = cell_of[shared][order].reshape(-1, 2)                   # neighbouring cell pairs
        ghosts = [set() for _ in range(len(arr))]
        for i, j in c[owner[c[:, 0]] != owner[c[:, 1]]]:
            ghosts[i].add(int(owner[j]))
            ghosts[j].add(int(owner[i]))
        dest = [[int(owner[i])] + sorted(ghosts[i]) for i in range(len(arr))]
        offsets = np.cumsum([0] + [len(d) for d in dest]).astype(np.int32)
        flat = np.array([r for d in dest for r in d], dtype=np.int32)
        return graph.create_adjacencylist(flat, offsets)
    return partition


def assert_strips(msh):
    """Each rank owns exactly the cells of its vertical strip of the unit square."""
    comm = msh.comm
    tdim = msh.topology.dim
    n_owned = msh.topology.index_map(tdim).size_local
    mid = compute_midpoints(msh, tdim, np.arange(n_owned, dtype=np.int32))[:, 0]
    lo, hi = comm.rank / comm.size, (comm.rank + 1) / comm.size
    assert np.all((mid > lo) & (mid < hi)), "strip_partitioner: the cut is not where it was asked"
