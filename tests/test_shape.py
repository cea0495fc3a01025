"""Standard-MPM shape functions and point location (fenicsmpm.shapes.standard, Grid.locate).

On triangles, quadrilaterals, tetrahedra and hexahedra, structured (dolfinx create_rectangle /
create_box) and distorted (moved or randomly jittered vertices, so the O(1) structured
locate is not used), at random points strictly inside random owned cells:
  - partition of unity  sum_i N_i = 1 (1e-12) and sum_i grad N_i = 0 (1e-10),
  - exact reproduction of an affine field u = A x + b:
      sum_i N_i u(x_i) = u(x_p) and sum_i u(x_i) (x) grad N_i = A (1e-10),
  - the located cell is the one the point was generated in, agrees with a brute-force
    search over every local cell, and the isoparametric map gives the point back:
      sum_i N_i x_i = x_p (1e-12),
  - the structured and the bounding-box-tree paths agree, and points outside get -1.
"""
import inspect

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm
from conftest import distort_interior
from fenicsmpm.shapes import standard as ks

CT = dmesh.CellType
CELL_TYPES = [CT.triangle, CT.quadrilateral, CT.tetrahedron, CT.hexahedron]
N_POINTS = 60


def _build_mesh(comm, cell_type):
    """Structured mesh of the box [0, 1.5] x [0, 1] (x [0, 1]) with unequal cell sizes."""
    if cell_type in (CT.triangle, CT.quadrilateral):
        return dmesh.create_rectangle(comm, [[0.0, 0.0], [1.5, 1.0]], [6, 4], cell_type)
    return dmesh.create_box(comm, [[0.0, 0.0, 0.0], [1.5, 1.0, 1.0]], [3, 2, 2], cell_type)


def make_grid(comm, cell_type, distortion):
    """Grid on the structured mesh, or with interior vertices moved by up to 0.15 h
    ("moved") or 0.1 h ("jittered") per component."""
    msh = _build_mesh(comm, cell_type)
    h = 0.25 if msh.topology.dim == 2 else 0.5
    amplitude = dict(none=0.0, moved=0.15 * h, jittered=0.1 * h)[distortion]
    if amplitude:
        assert distort_interior(msh, amplitude) > 0
    return fm.Grid(msh)


def random_points(grid, rng, n=N_POINTS, margin=0.02):
    """n points strictly inside random owned cells: (cells, xi, x)."""
    d = grid.gdim
    cells = rng.integers(0, grid.n_owned_cells, n).astype(np.int32)
    if grid.kind == ks.SIMPLEX:
        lam = rng.dirichlet(np.ones(d + 1), size=4 * n)
        lam = lam[lam.min(axis=1) > margin][:n]
        assert len(lam) == n
        xi = np.ascontiguousarray(lam[:, 1:])
    else:
        xi = rng.uniform(margin, 1.0 - margin, (n, d))
    x = np.empty((n, d))
    detJ = np.empty(n)
    call_kernel(ks.reference_points_to_physical, grid, cells=cells, xi=xi, x_out=x, detJ_out=detJ)
    assert np.all(detJ > 0)
    return cells, xi, x


def call_kernel(kernel, grid, **arrays):
    """Call a numba kernel of fenicsmpm.shapes.standard with its arguments taken by name:
    from `arrays` first, else the Grid attribute of that name (so the tests follow the
    kernels' signatures, e.g. D, kind, cell_nodes, node_x, simplex_grad, affine_Jinv)."""
    names = inspect.signature(kernel.py_func).parameters
    missing = [n for n in names if n not in arrays and not hasattr(grid, n)]
    assert not missing, f"{kernel.__name__}: no value for parameter(s) {missing}"
    return kernel(*[arrays[n] if n in arrays else getattr(grid, n) for n in names])


def shape_at(grid, cells, xi):
    n, nv, d = len(cells), grid.cell_nodes.shape[1], grid.gdim
    nodes = np.empty((n, nv), dtype=np.int32)
    N = np.empty((n, nv))
    dN = np.empty((n, nv, d))
    call_kernel(ks.mpm_shape, grid, cells=cells, xi=xi, nodes_out=nodes, N_out=N, dN_out=dN)
    return nodes, N, dN


def gmax(comm, a):
    """Global max of |a| (collective; 0 for an empty array)."""
    return comm.allreduce(float(np.max(np.abs(a))) if np.size(a) else 0.0, op=MPI.MAX)


CASES = ([(ct, "none") for ct in CELL_TYPES]
         + [(CT.quadrilateral, "moved"), (CT.hexahedron, "moved")]
         + [(ct, "jittered") for ct in CELL_TYPES])
DISTORTED_TENSOR = [(CT.quadrilateral, "moved"), (CT.quadrilateral, "jittered"),
                    (CT.hexahedron, "moved")]


@pytest.fixture(params=CASES, ids=lambda c: f"{c[0].name}-{c[1]}")
def case(request, comm, rng):
    cell_type, distortion = request.param
    grid = make_grid(comm, cell_type, distortion)
    cells, xi, x = random_points(grid, rng)
    return grid, distortion, cells, xi, x


def test_structured_detection(case, comm):
    """create_rectangle / create_box grids use the O(1) path; distorted ones must not."""
    grid, distortion, *_ = case
    expected = distortion == "none"
    flags = comm.allgather(grid.structured)
    assert all(f == expected for f in flags), (
        f"grid.structured per rank = {flags}, expected {expected} for a '{distortion}' mesh")


def test_partition_of_unity(case, comm):
    grid, _, cells0, _, x = case
    cells, xi = grid.locate(x)
    _, N, dN = shape_at(grid, cells, xi)
    e_sum = gmax(comm, N.sum(axis=1) - 1.0)
    e_grad = gmax(comm, dN.sum(axis=1))
    assert e_sum < 1e-12, f"max |sum N - 1| = {e_sum:.3e} (tol 1e-12)"
    assert e_grad < 1e-10, f"max |sum grad N| = {e_grad:.3e} (tol 1e-10)"


def test_affine_reproduction(case, comm, rng):
    """u(x) = A x + b is reproduced exactly, with its gradient A."""
    grid, _, _, _, x = case
    d = grid.gdim
    A = np.array(comm.bcast(rng.uniform(-2, 2, (d, d)), root=0))
    b = np.array(comm.bcast(rng.uniform(-1, 1, d), root=0))
    cells, xi = grid.locate(x)
    nodes, N, dN = shape_at(grid, cells, xi)
    u_nodes = grid.node_x @ A.T + b
    u_p = np.einsum("pa,pai->pi", N, u_nodes[nodes])
    grad = np.einsum("pai,paj->pij", u_nodes[nodes], dN)
    e_val = gmax(comm, u_p - (x @ A.T + b))
    e_grad = gmax(comm, grad - A)
    assert e_val < 1e-10, f"max |sum N u_i - u(x_p)| = {e_val:.3e} (tol 1e-10)"
    assert e_grad < 1e-10, f"max |sum u_i (x) grad N_i - A| = {e_grad:.3e} (tol 1e-10)"


def test_locate_maps_back(case, comm):
    """The located cell is the generating one, and sum N_i(xi) x_i gives x back (1e-12)."""
    grid, _, cells0, _, x = case
    cells, xi = grid.locate(x)
    wrong = comm.allreduce(int(np.count_nonzero(cells != cells0)))
    nodes, N, _ = shape_at(grid, np.where(cells < 0, 0, cells).astype(np.int32), xi)
    err = gmax(comm, np.einsum("pa,pai->pi", N, grid.node_x[nodes]) - x)
    assert wrong == 0, f"{wrong} points located in a cell other than the one containing them"
    assert err < 1e-12, f"max |sum N_i x_i - x_p| = {err:.3e} (tol 1e-12)"


def test_locate_brute_force(case, comm):
    """Pulling every point back into every local cell (the kernel grid.locate uses) finds
    exactly one containing cell, the one grid.locate returns."""
    grid, _, _, _, x = case
    x = x[:20]
    cells, _ = grid.locate(x)
    nc = grid.n_cells
    xx = np.ascontiguousarray(np.repeat(x, nc, axis=0))
    cc = np.tile(np.arange(nc, dtype=np.int32), len(x))
    xi = np.zeros_like(xx)
    inside = np.zeros(len(xx), dtype=np.bool_)
    call_kernel(ks.pull_back, grid, x=xx, cells=cc, xi_out=xi, inside_out=inside)
    # a point reported inside a cell must map back to itself from that cell
    nodes, N, _ = shape_at(grid, cc, xi)
    resid = np.linalg.norm(np.einsum("pa,pai->pi", N, grid.node_x[nodes]) - xx, axis=1)
    false_inside = comm.allreduce(int(np.count_nonzero(inside & (resid > 1e-10))))
    inside = inside.reshape(len(x), nc)
    n_inside = inside.sum(axis=1)
    brute = np.argmax(inside, axis=1)
    bad_count = comm.allreduce(int(np.count_nonzero(n_inside != 1)))
    mismatch = comm.allreduce(int(np.count_nonzero(brute != cells)))
    assert false_inside == 0, (
        f"pull_back reports {false_inside} (point, cell) pairs as inside although "
        f"sum N_i(xi) x_i misses the point by > 1e-10 (unconverged Newton pull-back)")
    assert bad_count == 0, f"{bad_count} interior points lie in != 1 cell by brute force"
    assert mismatch == 0, f"{mismatch} points where grid.locate differs from brute force"


@pytest.mark.parametrize("cell_type,distortion", DISTORTED_TENSOR,
                         ids=[f"{c.name}-{d}" for c, d in DISTORTED_TENSOR])
def test_locate_with_previous_cell(comm, cell_type, distortion):
    """grid.locate(x, cells) with any previous cell (the hint used in the time loop) returns
    the cell that contains the point, on distorted quadrilateral/hexahedral meshes where
    the pull-back is a Newton solve."""
    grid = make_grid(comm, cell_type, distortion)
    assert not grid.structured
    rng = np.random.default_rng(5 + comm.rank)
    cells0, _, x = random_points(grid, rng, n=400)
    nc = grid.n_cells
    xx = np.repeat(x, nc, axis=0)
    hint = np.tile(np.arange(nc, dtype=np.int32), len(x))
    true = np.repeat(cells0, nc)
    cells, _ = grid.locate(xx, hint)
    wrong = comm.allreduce(int(np.count_nonzero((cells != true) & (cells >= 0))))
    lost = comm.allreduce(int(np.count_nonzero(cells < 0)))
    total = comm.allreduce(len(xx))
    assert wrong == 0 and lost == 0, (
        f"locate with a previous-cell hint: {wrong} of {total} (point, hint) pairs put in a "
        f"wrong cell, {lost} reported outside the mesh (expected 0)")


def test_locate_distorted_hex_many_points(comm):
    """Without hints, every point strictly inside a cell of a hexahedral mesh with
    non-planar faces is found (no -1 for points inside the mesh)."""
    grid = make_grid(comm, CT.hexahedron, "moved")
    rng = np.random.default_rng(5 + comm.rank)
    cells0, _, x = random_points(grid, rng, n=4000)
    cells, _ = grid.locate(x)
    wrong = comm.allreduce(int(np.count_nonzero((cells != cells0) & (cells >= 0))))
    lost = comm.allreduce(int(np.count_nonzero(cells < 0)))
    assert wrong == 0 and lost == 0, (
        f"{lost} of {comm.allreduce(len(x))} interior points reported outside the mesh, "
        f"{wrong} in a wrong cell (expected 0)")


def test_outside_points(case, comm):
    """Points off the mesh get cell -1, on both locate paths."""
    grid, *_ = case
    d = grid.gdim
    lo = np.array([0.0] * d)
    hi = np.array([1.5] + [1.0] * (d - 1))
    mid = 0.5 * (lo + hi)
    pts = []
    for k in range(d):
        for off in (-0.3, -1e-3):
            p = mid.copy(); p[k] = lo[k] + off; pts.append(p)
        for off in (1e-3, 0.4):
            p = mid.copy(); p[k] = hi[k] + off; pts.append(p)
    pts.append(lo - 0.01)
    pts.append(hi + 5.0)
    pts = np.array(pts)
    cells, _ = grid.locate(pts)
    found = comm.allreduce(int(np.count_nonzero(cells >= 0)))
    assert found == 0, f"{found} points outside the mesh were located in a cell"


def test_structured_and_tree_agree(comm, rng):
    """On the four structured meshes the O(1) path and the bounding-box-tree path return the
    same cells and reference coordinates for points strictly inside cells."""
    n_diff = 0
    xi_err = 0.0
    for ct in CELL_TYPES:
        fast = make_grid(comm, ct, "none")
        assert fast.structured, f"{ct.name}: create_rectangle/create_box grid not structured"
        tree = fm.Grid(fast.mesh)
        tree._structured = None           # force the bounding-box-tree path
        cells0, _, x = random_points(fast, rng)
        c1, xi1 = fast.locate(x)
        c2, xi2 = tree.locate(x)
        assert tree._tree is not None, "the bounding-box-tree path was not used"
        n_diff += int(np.count_nonzero(c1 != c2)) + int(np.count_nonzero(c1 != cells0))
        xi_err = max(xi_err, float(np.max(np.abs(xi1 - xi2))))
    n_diff = comm.allreduce(n_diff)
    xi_err = comm.allreduce(xi_err, op=MPI.MAX)
    assert n_diff == 0, f"structured and tree locate disagree on {n_diff} cells"
    assert xi_err < 1e-12, f"structured and tree reference coordinates differ by {xi_err:.3e}"
