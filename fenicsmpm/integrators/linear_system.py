"""The implicit grid system: a PETSc AIJ matrix with dolfinx's sparsity, filled from particle
quadrature through a precomputed CSR scatter plan, and a KSP configured by PETSc options.

Created only by implicit integrators (an explicit run builds no matrix and no KSP)."""
import logging

import numpy as np
import ufl
from dolfinx import fem
import dolfinx.fem.petsc
from petsc4py import PETSc

from ..shapes import standard as kt_shape
from ..kernels import transfer as kt
from ..kernels.fbar import fbar_stiffness

DEFAULT_PREFIX = "fenicsmpm_"
# the dynamic integrators' default (LinearSystem iterative=True): the mass term keeps
# J = K + M / (beta dt^2) well conditioned; measured (bench throughput, 1.04e5 particles,
# dt = 5 dt_crit, three runs): 0.45-0.62 s/step against 1.21-1.88 s with LU (standard
# family); the default shape (cpGIMP) 0.87-1.07 s
ITERATIVE = {"ksp_type": "gmres", "pc_type": "bjacobi", "ksp_rtol": 1e-10, "ksp_max_it": 1000}


# the quasi-static default (LinearSystem iterative=False): the LU factorization of the step's
# first tangent (solved with it alone), kept as GMRES's preconditioner for its further Newton
# iterations: computed again once the solves since took more than LAG_ITERATIONS GMRES
# iterations in all, or when GMRES fails with it (at ksp_max_it). Once GMRES has failed with
# kept factors, every further solve of that step and of the next k steps factors afresh, k
# doubling with each such failure up to LAG_BACKOFF_MAX (back to 0 when kept factors serve
# again): a plastic tangent that changes at every iteration makes each try a loss (the W5
# footing of tests/test_implicit_footing.py, 4.5 cells under B/2, 40 steps, serial, one
# thread, 2026-12-05: 83-85 s without this, 135 fresh factors in 169 solves, 524 KSP
# iterations; with it 65-68 s, 167 in 173, 215; one try every step 75 s; LU at every solve
# 66 s; the collapse pressure the same to 1e-7; before the ghost penalty's narrower pattern,
# integrators.ghost); the true residual to 1e-12 (a near-singular tangent, a footing near
# collapse, needs a solve as accurate as LU's)
LAG_ITERATIONS = 30
LAG_BACKOFF_MAX = 16
LAGGED = {"ksp_type": "gmres", "pc_type": "lu", "ksp_pc_side": "right", "ksp_rtol": 1e-12,
          "ksp_max_it": LAG_ITERATIONS // 2}


# MUMPS for the direct default from this many global dofs on (always on several ranks), with
# the optimised serial BLAS `make deps` installs (libopenblas0-serial); PETSc's own LU below.
# Measured (fenicsmpm.bench.throughput.lu_times, 2026-12-05: a refactorization plus a solve of
# the quasi-static block's cpGIMP tangent, PETSc's LU / MUMPS): 1,250 dofs 2.3 / 5.4 ms,
# 4,802 dofs 28.5 / 21.5 ms, 18,818 dofs 0.25 / 0.13 s, 54,450 dofs 1.44 / 0.62 s; with
# Debian's reference BLAS MUMPS was slower than PETSc's LU (a quasi-static step 4.1 / 3.4 s)
MUMPS_FROM_DOFS = 4000


# options of the factored matrix (e.g. mat_mumps_icntl_14): PETSc reads them when it factors,
# not in KSPSetFromOptions; LinearSystem puts them in the options database around each solve
FACTOR_OPTIONS = "mat_"


def _direct(comm, n_dofs, lagged=False, mumps=False):
    """The direct default for a system of n_dofs global dofs: LU (MUMPS on several ranks, from
    MUMPS_FROM_DOFS dofs, or when `mumps`: MUMPS options were given), as GMRES's lagged
    preconditioner (LAGGED) or applied once (preonly)."""
    mumps = mumps or comm.size > 1 or n_dofs >= MUMPS_FROM_DOFS
    return dict(LAGGED if lagged else {"ksp_type": "preonly", "pc_type": "lu"},
                **({"pc_factor_mat_solver_type": "mumps"} if mumps else {}))


class OutsidePattern(RuntimeError):
    """LinearSystem.plan: a particle couples a node pair outside the static matrix pattern
    (raised on every rank together); the implicit integrators widen the pattern and retry."""


class LinearSystem:
    """K du = R on the vector P1/Q1 space of `grid`.

    The local (ghost-inclusive) CSR structure is the node adjacency of the cells expanded to
    blocks; PETSc's matrix comes from dolfinx (`create_matrix` of a mass form, so the pattern
    is dolfinx's), and every assembly is one `setValuesLocalCSR` call. Constrained dofs
    (Dirichlet or inactive nodes) get a unit diagonal and zero right-hand side.

    rings > 1 (the wide shape families, see stencil_rings): the pattern is every node pair
    joined by a chain of at most `rings` cells (ring_adjacency, a static superset of what the
    particles couple), put into a dolfinx SparsityPattern on V's index map (ghost rows go to
    their owners) and made a PETSc matrix by dolfinx.cpp.la.petsc.create_matrix; nodeptr/adj
    are that local pattern. rings = 1 ("mpm") keeps the cell pattern above, unchanged.

    Solver options: PETSc options under `prefix` (default "fenicsmpm_"), e.g.
    `-fenicsmpm_ksp_type gmres -fenicsmpm_pc_type hypre`, or the `petsc_options` dict. The
    default is GMRES preconditioned by an LU factorization kept between solves (LAGGED,
    _solve_lagged; MUMPS on several ranks or from MUMPS_FROM_DOFS dofs); iterative=True (the
    dynamic integrators' default, used only when neither the dict nor the command line sets an
    option under `prefix`) starts with ITERATIVE and switches to that lagged LU for good,
    logged once, the first time the KSP fails, re-solving the same system."""

    def __init__(self, grid, petsc_options=None, prefix=DEFAULT_PREFIX, rings=1, shape="mpm",
                 iterative=False):
        self.grid = grid
        bs = self.bs = grid.gdim
        if not (isinstance(rings, (int, np.integer)) and rings >= 1):
            raise ValueError(f"LinearSystem: 'rings' must be a positive integer, got {rings!r}")
        self.rings, self.shape = int(rings), shape
        self._last_plan = None      # (nodes, plan) of the last plan() call (rows reused)
        if self.rings == 1:
            cn = grid.cell_nodes.astype(np.int64)
            nv = cn.shape[1]
            rows = np.repeat(cn, nv, axis=1).ravel()
            cols = np.tile(cn, (1, nv)).ravel()
            key = np.unique(rows * grid.n_nodes + cols)
            adj_rows = key // grid.n_nodes
            self.adj = np.ascontiguousarray(key % grid.n_nodes, dtype=np.int64)
            counts = np.bincount(adj_rows, minlength=grid.n_nodes)
            self.nodeptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
            u, w = ufl.TrialFunction(grid.V), ufl.TestFunction(grid.V)
            self.A = dolfinx.fem.petsc.create_matrix(fem.form(ufl.inner(u, w) * ufl.dx))
        else:
            self.nodeptr, self.adj = ring_adjacency(grid, self.rings)
            self.A = _pattern_matrix(grid, self.nodeptr, self.adj)
        self._base = (self.nodeptr, self.adj)
        self._extension = None            # the key of the pairs added by extend()
        self._scalar_csr()
        self.b = fem.Function(grid.V)
        self.x = fem.Function(grid.V)
        self.n_owned_dofs = grid.n_owned_nodes * bs
        self.ksp = PETSc.KSP().create(grid.comm)
        self.ksp.setOperators(self.A)
        self.ksp.setOptionsPrefix(prefix)
        # options: command line (-fenicsmpm_...) < built-in defaults for unset keys < the
        # petsc_options dict; what this object put into the options database is taken out
        # again after setFromOptions, so it cannot leak into the next simulation
        opts = PETSc.Options()
        _insert_command_line_options(prefix)
        self.prefix = prefix
        # factor options (FACTOR_OPTIONS, e.g. MUMPS's memory) keep the defaults and ask for
        # MUMPS; any other option replaces the defaults
        user = dict(petsc_options or {})
        self._factor_options = {k: v for k, v in user.items() if k.startswith(FACTOR_OPTIONS)}
        self._factor_checked = not self._factor_options
        user = {k: v for k, v in user.items() if k not in self._factor_options}
        given = [k[len(prefix):] for k in opts.getAll() if k.startswith(prefix)]
        defaults = not user and all(k.startswith(FACTOR_OPTIONS) for k in given)
        mumps = any(k.startswith(FACTOR_OPTIONS + "mumps_")
                    for k in list(self._factor_options) + given)
        self.fallback = bool(iterative) and defaults
        self.switched = False             # the iterative default failed and LU took over
        self.lagged = not iterative and defaults    # LAGGED: the LU is kept between solves
        self.factorizations = 0           # LU factorizations computed (lagged only)
        self._factored = False
        self._backoff = 0                 # steps without kept factors after the last failure
        self._skip = 0                    # steps left without them, this one included
        self._since = 0                   # GMRES iterations since the last factorization
        merged = (dict(ITERATIVE) if self.fallback
                  else _direct(grid.comm, self.A.getSize()[0], self.lagged, mumps))
        merged = {k: v for k, v in merged.items() if not opts.hasName(prefix + k)}
        merged.update(user)
        # the LU default's solver type (MUMPS) is not for a user's other PC (MUMPS has no ILU)
        pc_type = merged.get("pc_type") or opts.getString(prefix + "pc_type", "lu")
        if pc_type not in ("lu", "cholesky") and "pc_factor_mat_solver_type" not in user:
            merged.pop("pc_factor_mat_solver_type", None)
        self._mumps = mumps
        unused = self._set_options(merged, check=user)
        self.iterations = 0
        if unused:
            raise ValueError(f"petsc_options: PETSc did not use {sorted(unused)} (misspelt, or "
                             f"not an option of the chosen KSP/PC); see the PETSc manual pages of "
                             f"KSPSetFromOptions and PCSetFromOptions")

    def _scalar_csr(self):
        """The dof-level CSR arrays of the node pattern (nodeptr, adj)."""
        self.indptr, self.indices = kt.scalar_csr(self.nodeptr, self.adj, self.bs)
        self.diag = kt.diagonal_slots(self.nodeptr, self.adj, self.bs)
        self.data = np.zeros(len(self.indices))

    def extend(self, key, pairs, form):
        """Add the local node pairs `pairs` ((k, 2), both orders) to a one-ring pattern, e.g. the
        cell pairs of the facets a ghost penalty acts on (integrators.ghost); a pattern of two
        rings or more holds every such pair already and stays. `form`: a bilinear UFL form on V
        whose dolfinx sparsity holds those pairs on the ranks owning their rows; the matrix is
        made from it plus the cells' mass form, so its pattern is the cells' and the form's.
        `key` names the set of pairs: the same key again does nothing. Collective (every rank
        passes the same key); a new pattern is factored afresh at its first solve."""
        if self.rings > 1 or key == self._extension:
            return
        import scipy.sparse as sp
        self._extension = key
        n = self.grid.n_nodes
        ptr, adj = self._base
        both = np.vstack([pairs, pairs[:, ::-1]])
        pattern = (sp.csr_matrix((np.ones(len(adj)), adj, ptr), shape=(n, n))
                   + sp.csr_matrix((np.ones(len(both)), (both[:, 0], both[:, 1])), shape=(n, n))).tocsr()
        pattern.sort_indices()
        self.nodeptr = np.ascontiguousarray(pattern.indptr, dtype=np.int64)
        self.adj = np.ascontiguousarray(pattern.indices, dtype=np.int64)
        self._scalar_csr()
        w, u = sorted(form.arguments(), key=lambda a: a.number())   # the form's own (test, trial)
        self.A.destroy()
        self.A = dolfinx.fem.petsc.create_matrix(fem.form(ufl.inner(u, w) * ufl.dx + form))
        self.ksp.setOperators(self.A)
        self._last_plan = None
        self._factored = False

    def _set_options(self, options, check=()):
        """KSPSetFromOptions with `options` (without the prefix) put into PETSc's options
        database for the call and taken out again, so they cannot leak into the next
        simulation (what was there before is restored). Returns the keys of `check` that PETSc
        did not read."""
        opts, prefix = PETSc.Options(), self.prefix
        saved = {k: opts.getString(prefix + k) for k in options if opts.hasName(prefix + k)}
        for k, v in options.items():
            opts[prefix + k] = v
        self.ksp.setFromOptions()
        unused = [k for k in check if not _option_used(prefix + k)]
        for k in options:
            opts.delValue(prefix + k)
            if k in saved:
                opts[prefix + k] = saved[k]
        return unused

    def plan(self, nodes):
        """Scatter plan of the current particle-node connectivity (once per step). With the
        wide pattern (rings > 1) a node pair outside it raises OutsidePattern (a RuntimeError)
        on every rank (collective), never a dropped or misplaced term. The rows of particles
        whose nodes have not changed since the last call are kept (kt.stiffness_plan). A new
        step's first solve computes fresh LU factors (lagged default, _solve_lagged)."""
        self.new_step()
        shape = nodes.shape + (nodes.shape[1],)
        last = self._last_plan
        if last is not None and last[1].shape == shape:
            old, plan = last
        else:
            old, plan = nodes[:0], np.empty(shape, dtype=np.int64)
        self._last_plan = None                      # until this plan is complete
        miss = kt.stiffness_plan(nodes, self.nodeptr, self.adj, self.bs, plan, old)
        comm = self.grid.comm
        if comm.size > 1:                           # collective: every rank raises together
            from mpi4py import MPI
            if comm.allreduce(int(miss >= 0), op=MPI.MAX) and miss < 0:
                raise OutsidePattern(f"implicit shape={self.shape!r}: a particle on another "
                                     f"rank couples nodes outside the static matrix pattern "
                                     f"(see its message)")
        if miss >= 0:
            p, a, b = miss // nodes.shape[1] ** 2, miss // nodes.shape[1] % nodes.shape[1], miss % nodes.shape[1]
            xi, xj = self.grid.node_x[nodes[p, a]], self.grid.node_x[nodes[p, b]]
            raise OutsidePattern(
                f"implicit shape={self.shape!r}: local particle {p} couples the nodes at "
                f"{np.round(xi, 6).tolist()} and {np.round(xj, 6).tolist()}, which are more "
                f"than {self.rings} cell rings apart: outside the static matrix pattern "
                f"(its domain grew beyond what the pattern covers, e.g. a cpGIMP box stretched "
                f"past |F_kk| l0 = L/2 or a CPDI domain larger than a cell). Refine the grid, "
                f"use fewer particles per cell or shape='ugimp'/'cpdi1'; the term is not dropped")
        self._last_plan = (nodes.copy(), plan)
        return plan

    def assemble(self, nodes, dN, V, A4, plan, diag_add, constrained, extra=None, fbar=None):
        """Fill K = sum_p V_p B^T A_p B + diag(diag_add) with unit rows on constrained dofs;
        extra(data), if given, adds further particle terms to the local CSR values. With
        fbar = (dF0, cell, n_cells, n) the particle term is F-bar's consistent tangent
        (kernels.fbar.fbar_stiffness) instead."""
        self.data[:] = 0.0
        if fbar is None:
            kt.assemble_stiffness(self.grid.D, nodes, dN, V, A4, plan, self.nodeptr, constrained,
                                  self.data)
        else:
            bad = fbar_stiffness(self.grid.D, nodes, dN, V, A4, *fbar, plan, self.nodeptr,
                                 self.adj, constrained, self.data)
            self._raise_outside(bad, "F-bar couples the nodes of the particles of its cell")
        if extra is not None:
            extra(self.data)
        own = self.n_owned_dofs
        d = self.diag[:own]
        if self.grid.periodic is not None:          # tied mass: on the master rows only
            diag_add = np.where(self.grid.periodic.slave_dofs(self.bs), 0.0, diag_add)
        self.data[d] += np.where(constrained[:own], 1.0, diag_add[:own])
        self.A.zeroEntries()
        self.A.setValuesLocalCSR(self.indptr, self.indices, self.data, addv=PETSc.InsertMode.ADD)
        self.A.assemble()

    def _raise_outside(self, bad, what):
        """Collective: raise on every rank when a rank found a node pair outside the pattern
        (bad >= 0: its local particle), never a dropped term."""
        comm = self.grid.comm
        anywhere = comm.allreduce(int(bad >= 0)) if comm.size > 1 else int(bad >= 0)
        if anywhere:
            raise RuntimeError(f"implicit shape={self.shape!r}: {what}, and a pair of them is "
                               f"more than {self.rings} cell rings apart (local particle {bad}"
                               f"{'' if bad >= 0 else ' on another rank'}): outside the static "
                               f"matrix pattern; refine the grid or use fewer particles per cell")

    def add(self, B):
        """K += B for a matrix whose pattern is within K's (dolfinx forms on the same space)."""
        self.A.axpy(1.0, B, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)

    def solve(self, R):
        """Solve K dx = R, where R (n_nodes, gdim) is complete (already summed) on every rank."""
        self.b.x.array[:] = R.ravel()
        tie = self.grid.periodic                    # master-slave reduction (boundaries.periodic)
        if tie is not None:
            self.b.x.array[tie.slave_dofs(self.bs)] = 0.0
            self.ksp.setOperators(tie.reduce(self.A))
        self.b.x.scatter_forward()
        reason = self._solve_lagged() if self.lagged else self._solve_once()
        if reason < 0 and self.fallback:           # the iterative default failed: LU from now on
            its = self.iterations
            self._use_direct(reason)
            reason = self._solve_lagged()
            self.iterations += its
        if tie is not None:
            tie.expand(self.x.vector.copy(), self.x.vector)
        if reason < 0:
            raise RuntimeError(f"KSP failed: converged reason {reason} "
                               f"({_reason_name(reason)}) after {self.iterations} iterations")
        self.x.x.scatter_forward()
        return self.x.x.array.reshape(R.shape).copy()

    def _solve_once(self):
        """One KSP solve of b into x: the converged reason (iterations in self.iterations).
        The factor options (FACTOR_OPTIONS) are in the options database during the solve only;
        after the first solve that factors, one PETSc did not read raises ValueError."""
        opts = PETSc.Options()
        factors = not self._factor_checked and self.ksp.getPC().getType() in ("lu", "cholesky")
        for k, v in self._factor_options.items():
            opts[self.prefix + k] = v
        try:
            self.ksp.solve(self.b.vector, self.x.vector)
            unused = [k for k in self._factor_options if factors and
                      not _option_used(self.prefix + k)]
        finally:
            for k in self._factor_options:
                opts.delValue(self.prefix + k)
        if factors:
            self._factor_checked = True
            if unused:
                raise ValueError(f"petsc_options: the factorization did not use {sorted(unused)} "
                                 f"(misspelt, or not an option of its solver type "
                                 f"{self.ksp.getPC().getFactorSolverType()!r})")
        self.iterations = self.ksp.getIterationNumber()
        return self.ksp.getConvergedReason()

    def new_step(self):
        """A new step (plan): its first solve factors afresh, and so do all its solves while a
        failure of kept factors holds them off (LAGGED's comment, _solve_lagged)."""
        self._factored = False
        self._skip = max(0, self._skip - 1)

    def _solve_lagged(self):
        """The lagged default (LAGGED): fresh LU factors solve alone (preonly) at a step's
        first solve (plan), for the next solve once the solves since the last factorization
        took more than LAG_ITERATIONS iterations in all, and at once, the solve repeated, when
        GMRES fails with the old factors; otherwise GMRES (right-preconditioned: the true
        residual to rtol 1e-12) with the kept factors as its preconditioner. Deterministic:
        the same run factors at the same solves. Once GMRES has failed with kept factors in a
        step, the step's further solves, and those of the next steps, factor afresh (LAGGED's
        comment, LAG_BACKOFF_MAX). Measured: docs/guide/integrators.md."""
        fresh = not self._factored or self._skip > 0
        reason = self._lagged_once(fresh)
        if reason < 0 and not fresh:               # the old factors no longer serve
            its = self.iterations
            reason = self._lagged_once(True)
            self.iterations += its
            fresh = True
            self._backoff = min(2 * self._backoff or 1, LAG_BACKOFF_MAX)
            self._skip = self._backoff + 1
        elif not fresh:
            self._backoff = 0
        self.factorizations += fresh
        self._factored = True
        self._since = 0 if fresh else self._since + self.iterations
        if self._since > LAG_ITERATIONS:
            self._factored = False
        return reason

    def _lagged_once(self, fresh):
        """One solve of the lagged default: with fresh factors the LU solve alone (preonly,
        as an exact direct solve), else GMRES preconditioned by the kept factors."""
        self.ksp.setType("preonly" if fresh else "gmres")
        self.ksp.getPC().setReusePreconditioner(not fresh)
        return self._solve_once()

    def _use_direct(self, reason):
        """Switch the KSP to the direct default, lagged as QuasiStatic's (LAGGED,
        _solve_lagged; collective: the converged reason is global)."""
        self.fallback = False
        self.switched = True
        self.lagged = True
        self._factored = False
        if self.grid.comm.rank == 0:
            logging.getLogger("fenicsmpm").warning(
                "the iterative linear solver (GMRES + block Jacobi/ILU) failed (%s after %d "
                "iterations); using the direct LU solver from now on", _reason_name(reason),
                self.ksp.getIterationNumber())
        self._set_options(_direct(self.grid.comm, self.A.getSize()[0], True, self._mumps))

    def destroy(self):
        self.ksp.destroy()
        self.A.destroy()


def stencil_rings(sim):
    """Cell rings the implicit matrix pattern must span for the shape family of `sim`: node
    pairs (i, j) are in the pattern when a chain of at most `rings` cells joins i to j, each
    cell sharing a node with the next (rings = 1: one cell, dolfinx's pattern).

    A particle's nodes lie in the cells its domain touches. uGIMP/cpGIMP on the lattice: a box
    of half-width l (r = l / L per axis) touches the nodes closer than L + l, so two of its
    nodes are at most ceil(2 r) + 1 lattice steps apart per axis, and one cell ring is one
    step per axis: rings = ceil(2 r) + 1 (2 for r <= 1/2), r from the initial half-widths
    (times |F_kk| for cpGIMP), the largest over all ranks. CPDI: the corners of a domain no
    larger than a cell lie in the cells sharing a vertex with the particle's cell; two such
    cells are joined through that cell, so rings = 3 in general (2 on a structured quad
    lattice, where corners at most a cell apart lie in cells that share a vertex). Gauss-GIMP
    ("gauss"): its Gauss points lie inside the same pushed-forward voxel, so the CPDI bound
    holds. Quadratic B-splines ("bspline2"): a particle's nodes are the 3 nearest per axis, at
    most 2 lattice steps apart: rings = 2. With F-bar (sim.fbar) a wide family's particle
    couples its nodes with those of every particle of its cell (kernels.fbar.fbar_stiffness):
    one ring more."""
    shape = getattr(sim, "shape", "mpm")
    if shape == "mpm":
        return 1
    if getattr(sim, "fbar", False):      # F-bar: a node of p meets the nodes of its cell-mates
        return _family_rings(sim, shape) + 1
    return _family_rings(sim, shape)


def _family_rings(sim, shape):
    """stencil_rings of a wide family without F-bar."""
    if shape in ("ugimp", "cpgimp"):
        from ..shapes.gimp import half_widths
        p, lat = sim.particles, sim._wide.lat
        rmax = (float((half_widths(p.gimp_l0, p.F, p.x, lat["spacing"], lat["lo"], lat["hi"],
                                   shape == "cpgimp") / lat["spacing"]).max())
                if len(p) else 0.0)
        if sim.comm.size > 1:
            from mpi4py import MPI
            rmax = sim.comm.allreduce(rmax, op=MPI.MAX)
        return int(np.ceil(2.0 * rmax - 1e-9)) + 1 if rmax > 0 else 2
    if shape == "bspline2":
        return 2
    if shape in ("cpdi1", "cpdi2", "gauss"):
        g = sim.grid
        return 2 if g.structured and g.kind == kt_shape.TENSOR else 3
    raise ValueError(f"stencil_rings: unknown shape family {shape!r}")


def ring_adjacency(grid, rings):
    """(nodeptr, adj): for every local node (owned and ghost) the sorted local nodes joined to
    it by a chain of at most `rings` local cells (owned and ghost), consecutive cells sharing
    a node. Built as the Boolean power of the node-cell-node graph."""
    import scipy.sparse as sp
    nc, nv = grid.cell_nodes.shape
    B = sp.csr_matrix((np.ones(nc * nv, dtype=np.int8), grid.cell_nodes.ravel(),
                       np.arange(0, nc * nv + 1, nv)), shape=(nc, grid.n_nodes))
    A1 = (B.T @ B).tocsr()
    A1.data[:] = 1
    A = A1
    for _ in range(rings - 1):
        A = (A @ A1).tocsr()
        A.data[:] = 1                      # Boolean (no int8 overflow on the next product)
    A.sort_indices()
    return (np.ascontiguousarray(A.indptr, dtype=np.int64),
            np.ascontiguousarray(A.indices, dtype=np.int64))


def _pattern_matrix(grid, nodeptr, adj):
    """PETSc AIJ matrix (block size gdim) with the node pattern (nodeptr, adj) of local rows
    (owned and ghost): a dolfinx SparsityPattern on V's index map, ghost rows sent to their
    owners by assemble(), so every rank's owned rows hold the pairs any rank couples."""
    from dolfinx import cpp
    imap = grid.V.dofmap.index_map
    bs = grid.V.dofmap.index_map_bs
    pattern = cpp.la.SparsityPattern(grid.comm, [imap, imap], [bs, bs])
    adj32 = adj.astype(np.int32)
    for i in range(len(nodeptr) - 1):
        pattern.insert(np.array([i], dtype=np.int32), adj32[nodeptr[i]:nodeptr[i + 1]])
    pattern.assemble()
    A = cpp.la.petsc.create_matrix(grid.comm, pattern)
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    return A


def _insert_command_line_options(prefix, argv=None):
    """Copy `-<prefix>name [value]` arguments from the command line into PETSc's options
    database (dolfinx initialises PETSc without sys.argv, so they would be ignored)."""
    import sys
    argv = sys.argv[1:] if argv is None else argv
    opts = PETSc.Options()
    for i, a in enumerate(argv):
        if a.startswith("-" + prefix):
            nxt = argv[i + 1] if i + 1 < len(argv) else None
            value = nxt if nxt is not None and not (nxt.startswith("-") and not _is_number(nxt)) else None
            if not opts.hasName(a[1:]):
                opts[a[1:]] = value if value is not None else ""


def _is_number(s):
    try:
        float(s)
        return True
    except ValueError:
        return False


_PETSC_LIB = None


def _option_used(name):
    """Whether PETSc read option `name` (no leading dash): PetscOptionsUsed, which petsc4py
    3.18 does not wrap, called in the PETSc library petsc4py loaded (found in /proc/self/maps)."""
    import ctypes
    global _PETSC_LIB
    if _PETSC_LIB is None:
        with open("/proc/self/maps") as maps:
            paths = [ln.split()[-1] for ln in maps if "/libpetsc" in ln]
        _PETSC_LIB = ctypes.CDLL(paths[0])
    used = ctypes.c_int(0)
    _PETSC_LIB.PetscOptionsUsed(None, name.encode(), ctypes.byref(used))
    return bool(used.value)


def _reason_name(code):
    for k, v in vars(PETSc.KSP.ConvergedReason).items():
        if v == code and not k.startswith("_"):
            return k
    return "unknown"
