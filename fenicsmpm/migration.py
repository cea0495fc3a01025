"""Particle ownership under MPI: each rank holds the particles inside its owned cells.

After particles move, the ones located in a ghost cell are sent to that cell's owner over a
neighbourhood communicator (MPI distributed graph) whose edges are the ghost-cell owners.
Particles found in no local cell, owned or ghost, take the fallback, which one global
reduction per step detects: their positions are shared with every rank, the rank owning a
cell containing the point claims it, and a global all-to-all moves them. Particles no rank
claims have left the global domain and are reported, never dropped silently. On one rank
this module is never called."""
import numpy as np



def _pack(p, sel):
    return {name: getattr(p, name)[sel] for name in p.field_names()}


def neighbourhood(grid):
    """Distributed-graph communicator over the ranks sharing ghost cells with this one
    (symmetric: ranks owning my ghosts, plus ranks having my cells as ghosts). Cached."""
    nbr = getattr(grid, "_neighbourhood", None)
    if nbr is None:
        comm = grid.comm
        owners = grid.mesh.topology.index_map(grid.mesh.topology.dim).owners
        mine = set(int(r) for r in np.unique(owners))
        everyone = comm.allgather(sorted(mine))
        ranks = sorted(mine | {r for r, lst in enumerate(everyone) if comm.rank in lst})
        nbr = comm.Create_dist_graph_adjacent(ranks, ranks, reorder=False)
        grid._neighbourhood = (nbr, ranks)
    return grid._neighbourhood


def migrate(p):
    """Send every particle whose `cell` is not an owned cell to the owning rank.

    `p.cell` must be the result of locating p.x on this rank (-1: no local cell).
    Returns (ids, positions) of the particles that no rank owns, identical on all ranks;
    they stay on their rank with cell -1 and the caller decides what to do with them."""
    grid = p.grid
    comm = grid.comm
    size, rank = comm.size, comm.rank
    n_owned = grid.n_owned_cells
    ghost_owner = grid.mesh.topology.index_map(grid.mesh.topology.dim).owners
    cells = p.cell
    dest = np.full(len(p), rank, dtype=np.int64)
    ghost = cells >= n_owned
    dest[ghost] = ghost_owner[cells[ghost] - n_owned]
    lost = np.flatnonzero(cells < 0)
    far = np.zeros(len(p), dtype=bool)          # destinations resolved by the global fallback
    n_lost, n_ghost = comm.allreduce(np.array([len(lost), int(np.count_nonzero(ghost))]))
    if n_lost == 0 and n_ghost == 0:
        return _nothing(grid)                    # the usual step: one small reduction
    if n_lost:
        all_lost = comm.allgather(p.x[lost])
        claims = []
        for xs in all_lost:
            c, _ = grid.locate(xs) if len(xs) else (np.zeros(0, np.int32), None)
            claims.append(np.where((c >= 0) & (c < n_owned), rank, size))
        dest[lost] = np.min([cl[rank] for cl in comm.allgather(claims)], axis=0)
        dest[dest >= size] = rank                # unclaimed: outside the global domain
        far[lost] = dest[lost] != rank
        recv_far = comm.alltoall([_pack(p, np.flatnonzero(far & (dest == r))) if r != rank
                                  else None for r in range(size)])
    else:
        recv_far = []
    nbr, ranks = neighbourhood(grid)
    moving = ~far & (dest != rank)
    recv = nbr.neighbor_alltoall([_pack(p, np.flatnonzero(moving & (dest == r))) for r in ranks])
    stay = np.flatnonzero(dest == rank)
    n_stay = len(stay)
    parts = [_pack(p, stay)] + [d for d in list(recv) + list(recv_far) if d is not None]
    for name in p.field_names():
        setattr(p, name, np.ascontiguousarray(np.concatenate([d[name] for d in parts])))
    if len(p) > n_stay:                              # locate arrivals in this rank's numbering
        c, xi = grid.locate(p.x[n_stay:])
        p.cell[n_stay:] = c
        p.xi[n_stay:] = xi
    p.version += 1
    if n_lost == 0:
        return _nothing(grid)
    gone = p.cell < 0                            # unclaimed by every rank in the fallback
    return (np.concatenate(comm.allgather(p.id[gone])),
            np.concatenate(comm.allgather(p.x[gone])))


def _nothing(grid):
    return np.zeros(0, dtype=np.int64), np.zeros((0, grid.gdim))
