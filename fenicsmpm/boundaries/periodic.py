"""Periodic lateral boundaries (BENCHMARKS.md section P, "Periodic sides"; seed 003 §2.1).

Tie. The grid nodes on the two faces x_a = min and x_a = max of the mesh along `axis` are
paired by their other coordinates (equal height). A pair is one degree of freedom: every
nodal sum (mass, momentum, force, the grid-smoothed stress) is summed over the pair and both
nodes hold the sum, so they get one velocity, acceleration and displacement increment.
`Grid.accumulate` applies the tie after its MPI exchange (`PeriodicTie.tie`), so the
explicit integrators (symplectic Euler, explicit generalized-alpha) and the residual of the
implicit ones see tied arrays without further code.

Implicit runs (master-slave reduction of the PETSc system, `LinearSystem`): the node on the
min face is the master, its partner the slave. With P the prolongation (x = P x_r: identity
on every dof except a slave dof, which copies its master's), the solved matrix is
    K_r = P^T K P + I_slave
(K assembled from the untied particle and Robin contributions, with the lumped mass
diagonal, already tied, put on the master rows only), the right-hand side is the tied
residual with the slave entries zeroed, and the slave dofs take their master's solution.

Under MPI the pairs are found by a rendezvous (each side node's key is sent to the rank
key-hash mod size, which matches left and right and answers the partner's global index;
only side nodes travel), and the partner values are fetched every call by a PETSc scatter
from the owned values, so the two faces may lie on different ranks.

Particles. Simulation(on_leave="periodic") re-enters a particle that left through one
face at x_a -/+ W (W = max - min) with all its other fields unchanged (`wrap`)."""
import numpy as np

__all__ = ["PeriodicTie", "wrap"]


class PeriodicTie:
    """The pairing of the two faces of `grid` normal to `axis` (see the module docstring).

    Attributes: axis, lo, hi, width (hi - lo), n_pairs (global), `master` and `slave`
    (local node indices of the pairs whose both nodes are local; informative)."""

    def __init__(self, grid, axis=0, tol=None):
        if not (isinstance(axis, (int, np.integer)) and 0 <= axis < grid.gdim):
            raise ValueError(f"periodic: 'axis' must be an integer in [0, {grid.gdim}), got {axis!r}")
        from mpi4py import MPI
        comm = grid.comm
        self.grid, self.axis = grid, int(axis)
        x = grid.node_x
        lo = x[:, axis].min() if len(x) else np.inf
        hi = x[:, axis].max() if len(x) else -np.inf
        if comm.size > 1:
            lo, hi = comm.allreduce(lo, op=MPI.MIN), comm.allreduce(hi, op=MPI.MAX)
        self.lo, self.hi, self.width = float(lo), float(hi), float(hi - lo)
        if not self.width > 0:
            raise ValueError("periodic: the mesh has no extent along the periodic axis")
        scale = float(np.abs(x).max()) if len(x) else 0.0
        if comm.size > 1:
            scale = comm.allreduce(scale, op=MPI.MAX)      # the same key grid on every rank
        self.tol = 1e-8 * max(self.width, scale) if tol is None else float(tol)
        left = np.flatnonzero(np.abs(x[:, axis] - lo) < self.tol)
        right = np.flatnonzero(np.abs(x[:, axis] - hi) < self.tol)
        imap = grid.V.dofmap.index_map
        gl = imap.local_to_global(np.arange(grid.n_nodes, dtype=np.int32)).astype(np.int64)
        other = [k for k in range(grid.gdim) if k != axis]
        step = 10.0 * self.tol

        def keys(idx):
            return [tuple(int(v) for v in np.round(x[i, other] / step)) for i in idx]

        side_nodes = np.concatenate([left, right])
        side = np.concatenate([np.zeros(len(left), np.int8), np.ones(len(right), np.int8)])
        kk = keys(side_nodes)
        # rendezvous: key -> rank hash(key) % size, which pairs the global indices
        size = comm.size
        dest = [hash(k) % size for k in kk]
        out = [[] for _ in range(size)]
        for k, s, g, r in zip(kk, side, gl[side_nodes], dest):
            out[r].append((k, int(s), int(g)))
        recv = comm.alltoall(out) if size > 1 else out
        table = {}
        for part in recv:
            for k, s, g in part:
                table.setdefault(k, [set(), set()])[s].add(g)
        bad = [k for k, (a, b) in table.items() if len(a) != 1 or len(b) != 1]
        nbad = comm.allreduce(len(bad)) if size > 1 else len(bad)
        if nbad:
            raise ValueError(f"periodic: {nbad} node(s) on the faces normal to axis {axis} have no "
                             f"partner at the same position on the opposite face (the mesh must "
                             f"match node for node across the periodic sides)")
        answer = [[next(iter(table[k][1 - s])) for k, s, g in part] for part in recv]
        back = comm.alltoall(answer) if size > 1 else answer
        # the answers come back in the order of the requests to each rank
        partner_global = np.empty(len(kk), dtype=np.int64)
        for r in range(size):
            mine = [i for i, d in enumerate(dest) if d == r]
            partner_global[mine] = back[r]
        self.nodes = side_nodes.astype(np.int64)                     # local side nodes
        self.partner_global = partner_global
        self.is_slave_node = np.zeros(grid.n_nodes, dtype=bool)
        self.is_slave_node[right] = True
        n_owned_pairs = int(np.count_nonzero(left < grid.n_owned_nodes))
        self.n_pairs = comm.allreduce(n_owned_pairs) if size > 1 else n_owned_pairs
        g2l = {int(g): i for i, g in enumerate(gl)}
        self.partner_local = np.array([g2l.get(int(g), -1) for g in self.partner_global], dtype=np.int64)
        both = self.partner_local >= 0
        self.master = self.nodes[both & (side == 0)]
        self.slave = self.partner_local[both & (side == 0)]
        self._serial = comm.size == 1
        self._scatters = {}
        self._P = self._Ared = None

    # ------------------------------------------------------------------ explicit tie
    def _partner_values(self, arr, bs):
        if self._serial:
            return arr[self.partner_local]
        from petsc4py import PETSc
        sc = self._scatters.get(bs)
        grid = self.grid
        if sc is None:
            n_own = grid.n_owned_nodes
            src = PETSc.Vec().createMPI((n_own * bs, PETSc.DECIDE), bsize=bs, comm=grid.comm)
            dst = PETSc.Vec().createSeq(len(self.nodes) * bs, bsize=bs)
            iset = PETSc.IS().createBlock(bs, self.partner_global.astype(np.int32),
                                          comm=PETSc.COMM_SELF)
            sc = self._scatters[bs] = (src, dst, PETSc.Scatter().create(src, iset, dst, None))
        src, dst, scatter = sc
        src.array[:] = arr[: grid.n_owned_nodes].ravel()
        scatter.scatter(src, dst, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        return dst.array.reshape((len(self.nodes),) + arr.shape[1:]).copy()

    def tie(self, *arrays):
        """Sum each nodal array (n_nodes,) or (n_nodes, k) over the node pairs, in place.
        The arrays must be complete (already summed over ranks); collective under MPI."""
        for arr in arrays:
            bs = 1 if arr.ndim == 1 else int(np.prod(arr.shape[1:]))
            flat = arr.reshape(arr.shape[0], bs)
            vals = self._partner_values(flat, bs)
            flat[self.nodes] += vals
            if not np.shares_memory(flat, arr):
                arr[...] = flat.reshape(arr.shape)

    # ------------------------------------------------------------------ implicit reduction
    def slave_dofs(self, bs):
        """Boolean mask over the local dofs (n_nodes * bs) of the slave nodes."""
        return np.repeat(self.is_slave_node, bs)

    def _prolongation(self, A):
        from petsc4py import PETSc
        grid = self.grid
        bs = grid.gdim
        n_own = grid.n_owned_nodes
        imap = grid.V.dofmap.index_map
        start = imap.local_range[0]
        cols = (start + np.arange(n_own, dtype=np.int64))
        master_of = np.full(grid.n_nodes, -1, dtype=np.int64)
        master_of[self.nodes] = self.partner_global
        own_slave = self.is_slave_node[:n_own]
        cols = np.where(own_slave, master_of[:n_own], cols)
        cols = (cols[:, None] * bs + np.arange(bs)).ravel().astype(PETSc.IntType)
        rows = np.arange(n_own * bs + 1, dtype=PETSc.IntType)
        P = PETSc.Mat().createAIJ(A.getSizes(), comm=grid.comm)
        P.setPreallocationNNZ((1, 1))
        r0 = A.getOwnershipRange()[0]
        P.setValuesCSR(rows, cols, np.ones(len(cols)))
        P.assemble()
        one = P.createVecLeft()
        one.array[:] = np.repeat(own_slave, bs).astype(float)
        self._slave_diag = one
        assert r0 == start * bs
        return P

    def reduce(self, A):
        """K_r = P^T A P + I_slave (a new or reused PETSc matrix)."""
        from petsc4py import PETSc
        if self._P is None:
            self._P = self._prolongation(A)
        if self._Ared is None:
            self._Ared = A.PtAP(self._P)
            self._Ared.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        else:
            A.PtAP(self._P, result=self._Ared)
        self._Ared.setDiagonal(self._slave_diag, addv=PETSc.InsertMode.ADD)
        return self._Ared

    def expand(self, x_reduced, x_full):
        """x_full = P x_reduced (slave dofs copy their master's)."""
        self._P.mult(x_reduced, x_full)


def wrap(sim, tie):
    """Re-enter the local particles that are in no cell (`cell` < 0) and lie beyond a
    periodic face at x_a -/+ W; returns the number wrapped on this rank. Only `x` (and the
    located `cell`, `xi`) change; velocity, stress, displacement, F, history and id stay."""
    p = sim.particles
    gone = np.flatnonzero(p.cell < 0)
    if len(gone) == 0:
        return 0
    a = tie.axis
    xa = p.x[gone, a]
    shift = np.where(xa > tie.hi, -tie.width, np.where(xa < tie.lo, tie.width, 0.0))
    moved = gone[shift != 0.0]
    if len(moved):
        p.x[moved, a] += shift[shift != 0.0]
        c, xi = sim.grid.locate(p.x[moved])
        p.cell[moved] = c
        p.xi[moved] = xi
    return len(moved)
