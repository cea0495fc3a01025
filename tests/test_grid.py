"""Grid geometry data and Particles.fill on dolfinx meshes.

- grid.h: the cell size on a structured quadrilateral/hexahedral mesh (the shortest edge
  for rectangular cells), and the smallest altitude on simplex meshes (right triangles:
  a b / sqrt(a^2 + b^2); tetrahedra: min 3 |K| / |face| computed from the vertices).
- grid.structured: True on create_rectangle (quads, triangles) and create_box (hexes, tets).
- Particles.fill: the particle volumes sum to the mesh volume (1e-12 relative) for all
  four cell types and per_cell = 1, 2, 3, also on meshes with moved interior vertices;
  every particle lies in its cell; mass = density x volume.
"""
import itertools

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm

CT = dmesh.CellType
RHO = 1850.0


def _rect(comm, ct, n=(6, 2), L=(1.5, 1.0)):
    return dmesh.create_rectangle(comm, [[0.0, 0.0], list(L)], list(n), ct)


def _box(comm, ct, n=(3, 2, 2), L=(1.5, 1.0, 1.0)):
    return dmesh.create_box(comm, [[0.0, 0.0, 0.0], list(L)], list(n), ct)


def test_h_square_quads(comm):
    grid = fm.Grid(_rect(comm, CT.quadrilateral, n=(8, 4), L=(2.0, 1.0)))
    assert abs(grid.h - 0.25) < 1e-14, f"grid.h = {grid.h!r}, expected the cell size 0.25 (1e-14)"


def test_h_rectangular_quads_and_hexes(comm):
    """Cells 0.25 x 0.5 (x 0.5): h is the shortest edge, 0.25."""
    q = fm.Grid(_rect(comm, CT.quadrilateral))
    h = fm.Grid(_box(comm, CT.hexahedron, n=(6, 2, 2)))
    assert abs(q.h - 0.25) < 1e-14, f"quadrilateral grid.h = {q.h!r}, expected 0.25 (1e-14)"
    assert abs(h.h - 0.25) < 1e-14, f"hexahedral grid.h = {h.h!r}, expected 0.25 (1e-14)"


def test_h_right_triangles(comm):
    """Right triangles with legs a = 0.25, b = 0.5: altitudes a, b and a b / sqrt(a^2 + b^2)."""
    grid = fm.Grid(_rect(comm, CT.triangle))
    a, b = 0.25, 0.5
    exact = a * b / np.hypot(a, b)
    assert abs(grid.h - exact) < 1e-12 * exact, (
        f"triangle grid.h = {grid.h!r}, expected smallest altitude {exact!r} (1e-12 rel)")


def test_h_tetrahedra(comm):
    """Smallest altitude 3 |K| / |opposite face| over all tetrahedra, from the vertices."""
    grid = fm.Grid(_box(comm, CT.tetrahedron, n=(3, 2, 2)))
    xc = grid.node_x[grid.cell_nodes[: grid.n_owned_cells]]
    vol = np.abs(np.einsum("ci,ci->c", np.cross(xc[:, 1] - xc[:, 0], xc[:, 2] - xc[:, 0]),
                           xc[:, 3] - xc[:, 0])) / 6.0
    alt = np.inf
    for k in range(4):
        f = [j for j in range(4) if j != k]
        area = 0.5 * np.linalg.norm(np.cross(xc[:, f[1]] - xc[:, f[0]], xc[:, f[2]] - xc[:, f[0]]),
                                    axis=1)
        alt = min(alt, float(np.min(3.0 * vol / area)))
    alt = comm.allreduce(alt, op=MPI.MIN)
    assert abs(grid.h - alt) < 1e-12 * alt, (
        f"tetrahedral grid.h = {grid.h!r}, expected smallest altitude {alt!r} (1e-12 rel)")


@pytest.mark.parametrize("ct", [CT.quadrilateral, CT.triangle, CT.hexahedron, CT.tetrahedron],
                         ids=lambda c: c.name)
def test_structured_flag(comm, ct):
    msh = _rect(comm, ct) if ct in (CT.quadrilateral, CT.triangle) else _box(comm, ct)
    flags = comm.allgather(fm.Grid(msh).structured)
    assert all(flags), f"{ct.name}: grid.structured per rank = {flags}, expected True"


@pytest.mark.parametrize("ct,per_cell,distorted", list(itertools.product(
    [CT.triangle, CT.quadrilateral, CT.tetrahedron, CT.hexahedron], [1, 2, 3], [False, True])),
    ids=lambda v: v.name if isinstance(v, CT) else str(v))
def test_fill_volume_and_mass(comm, distort, ct, per_cell, distorted):
    """Sum of particle volumes = mesh volume 1.5 (1e-12 rel); mass = density V (1e-14 rel);
    particles per cell: n^d; each particle is located in the cell that created it."""
    d = 2 if ct in (CT.quadrilateral, CT.triangle) else 3
    msh = _rect(comm, ct) if d == 2 else _box(comm, ct)
    if distorted:
        assert distort(msh, 0.1 * 0.25) > 0
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=1e6, nu=0.3, density=RHO)
    p = fm.Particles.fill(grid, mat, per_cell=per_cell)
    volume = float(p.total(p.V))
    mass = float(p.total(p.mass))
    n_cells = comm.allreduce(grid.n_owned_cells)
    vol_err = abs(volume - 1.5) / 1.5
    mass_err = comm.allreduce(float(np.max(np.abs(p.mass - RHO * p.V) / (RHO * p.V))),
                              op=MPI.MAX)
    cells, _ = grid.locate(p.x)
    misplaced = comm.allreduce(int(np.count_nonzero(cells != p.cell)))
    assert vol_err < 1e-12, f"sum V_p = {volume!r}, mesh volume 1.5 (rel err {vol_err:.2e}, tol 1e-12)"
    assert abs(mass - RHO * 1.5) < 1e-12 * RHO * 1.5, f"total mass {mass!r} != rho |Omega| = {RHO * 1.5}"
    assert mass_err < 1e-14, f"max |m_p - rho V_p| / (rho V_p) = {mass_err:.2e} (tol 1e-14)"
    assert p.n_global() == n_cells * per_cell ** d, (
        f"{p.n_global()} particles, expected {n_cells} cells x {per_cell}^{d}")
    assert np.all(p.V > 0) and misplaced == 0, f"{misplaced} particles not located in their cell"


@pytest.mark.parametrize("ct", [CT.triangle, CT.tetrahedron], ids=lambda c: c.name)
def test_structured_simplex_locate_starts_at_the_hint(comm, ct):
    """On a structured simplex grid Grid.locate tries each point's hinted cell first, then
    the box search: with right, wrong and missing hints every point is found in a cell that
    holds it (its reference coordinates map back to it, 1e-12), the same cell as without a
    hint except on shared faces, and points outside the local mesh get -1."""
    msh = _rect(comm, ct, n=(6, 4)) if ct == CT.triangle else _box(comm, ct)
    grid = fm.Grid(msh)
    assert grid.structured
    rng = np.random.default_rng(3)
    d = grid.gdim
    hi = np.array([1.5, 1.0, 1.0][:d])
    x = np.vstack([rng.random((400, d)) * hi, hi + 0.1])     # the last point is outside
    plain, _ = grid.locate(x)
    nc = len(grid.cell_nodes)
    hints = np.where(rng.random(len(x)) < 0.5, plain, rng.integers(-1, nc, len(x))).astype(np.int32)
    cells, xi = grid.locate(x, hints)
    assert np.array_equal(cells < 0, plain < 0)
    assert cells[-1] == -1 or comm.size > 1
    ok = cells >= 0
    X = grid.node_x[grid.cell_nodes[cells[ok]]][:, :, :d]              # (m, d + 1, d)
    back = X[:, 0] + np.einsum("mkd,mk->md", X[:, 1:] - X[:, :1], xi[ok])
    assert np.abs(back - x[ok]).max() < 1e-12
    assert np.all(xi[ok] >= -1e-9) and np.all(xi[ok].sum(axis=1) <= 1 + 1e-9)
    same = np.mean(cells[ok] == plain[ok])
    assert same > 0.95, f"only {same:.1%} of the points found in the unhinted cell"


@pytest.mark.parametrize("cell", ["triangle", "quadrilateral", "tetrahedron"])
def test_node_and_particle_coordinates_are_the_same_bits_on_any_partition(cell):
    """Grid.node_x is the mesh geometry's own coordinates and Particles.fill's positions and
    volumes are computed in a vertex order fixed by the coordinates, so the set of node
    coordinates and of particle (x, V) is bit for bit the serial one on any number of ranks
    (COMM_SELF reference on every rank). Before, tabulate_dof_coordinates left 82 / 6 / 233 of
    558 / 558 / 343 node coordinates with other last bits on 2 ranks (the checkpoint matches
    nodes by their coordinate bits across rank counts), and a `region` bound through a
    sub-simplex centroid kept a different particle set."""
    world = MPI.COMM_WORLD

    def build(comm):
        if cell == "tetrahedron":
            msh = dmesh.create_box(comm, [[0.0] * 3, [1.0] * 3], [6, 6, 6],
                                   dmesh.CellType.tetrahedron)
        else:
            msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [3.0, 1.7]], [30, 17],
                                         getattr(dmesh.CellType, cell))
        grid = fm.Grid(msh)
        mat = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
        p = fm.Particles.fill(grid, mat, per_cell=2)
        rows = [np.column_stack([p.x, p.V, np.zeros(len(p.x))])]
        if cell == "triangle":                          # and the edge layout with its corners
            q = fm.Particles.fill_edges(grid, mat)
            rows.append(np.column_stack([q.x, q.V, np.ones(len(q.x)),
                                         q.cpdi_corners.reshape(len(q.x), -1)]))
            rows[0] = np.column_stack([rows[0], np.zeros((len(p.x), 8))])
        return grid.node_x[: grid.n_owned_nodes], np.concatenate(rows)

    def rows(a):
        return set(map(tuple, a))
    nodes, parts = build(world)
    ref_nodes, ref_parts = build(MPI.COMM_SELF)
    assert rows(np.concatenate(world.allgather(nodes))) == rows(ref_nodes)
    assert rows(np.concatenate(world.allgather(parts))) == rows(ref_parts)
    assert sum(world.allgather(len(parts))) == len(ref_parts)


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_a_point_on_a_grid_line_is_owned_by_exactly_one_rank(cell):
    """Structured location counts boxes from the global lattice corner with the global
    spacing, so a point on a grid line between two ranks lands in the same box on every rank
    and exactly one rank owns it. With each rank's own corner and spacing, the points of a
    penalty polyline along y = 0.5 (a rank boundary of the 10 x 20 axisymmetric rod-on-block
    mesh) were owned by no rank, and the contact was lost (tests/test_penalty_contact.py)."""
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [0.5, 1.0]], [10, 20],
                                 getattr(dmesh.CellType, cell))
    grid = fm.Grid(msh)
    h = 0.05
    lines = np.arange(0, 21) * h
    x = np.array([(0.5 * h + i * h, y) for y in lines for i in range(10)]
                 + [(xv, 0.5 * h + j * h) for xv in lines[:11] for j in range(20)])
    cells, _ = grid.locate(x)
    owned = ((cells >= 0) & (cells < grid.n_owned_cells)).astype(np.int64)
    total = np.zeros_like(owned)
    MPI.COMM_WORLD.Allreduce(owned, total, op=MPI.SUM)
    assert np.all(total == 1), (np.count_nonzero(total == 0), np.count_nonzero(total > 1))
