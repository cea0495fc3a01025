"""fenicsmpm.io.particle_raster / particle_profile (run serially and under mpirun -n 2): exact
per-cell results on a known particle set split over the ranks; on the distributed particles
of a real scene the raster equals the one of all particles on one rank (the reference comes
from an allgather done here, in the test only); bad input raises a ValueError naming the
parameter, on every rank."""
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.io import particle_profile, particle_raster

comm = MPI.COMM_WORLD
BOUNDS = ((0.0, 2.0), (0.0, 1.0))          # 2 x 2 cells of 1 x 0.5

# (x, y, value); the cell [i, j] each lands in: the upper bounds belong to the last cells,
# the last two are outside (beyond xmax, NaN) and left out
KNOWN = np.array([[0.1, 0.1, 1.0], [0.9, 0.4, 3.0], [0.5, 0.2, -4.0],      # [0, 0]
                  [1.5, 0.5, 5.0], [2.0, 1.0, 7.0],                        # [1, 1]
                  [0.2, 0.75, 2.5],                                        # [0, 1]
                  [2.5, 0.5, 100.0], [np.nan, 0.5, 100.0]])
EXPECTED = dict(mean=[[0.0, 2.5], [np.nan, 6.0]], max=[[3.0, 2.5], [np.nan, 7.0]],
                min=[[-4.0, 2.5], [np.nan, 5.0]], count=[[3.0, 1.0], [0.0, 2.0]])


def local_share(a):
    """This rank's share of rows of a (every size-th row): the set split over the ranks."""
    return a[comm.rank::comm.size]


@pytest.mark.parametrize("reduce", sorted(EXPECTED))
def test_known_particles_give_the_exact_cells(reduce):
    mine = local_share(KNOWN)
    r = particle_raster(comm, mine[:, :2], mine[:, 2], BOUNDS, (2, 2), reduce=reduce)
    if comm.rank == 0:
        np.testing.assert_array_equal(r, np.array(EXPECTED[reduce]))
    else:
        assert r is None


def test_count_needs_no_values_and_profile_gives_the_surface():
    """reduce="count" with values=None; the free surface (max y per x column) of a stepped
    set: column 0 holds y = 0.1, 0.3; column 1 nothing; column 2 y = 0.2, 0.9 (x = 3 = smax
    is in the last column)."""
    pts = np.array([[0.5, 0.1], [0.7, 0.3], [2.2, 0.2], [3.0, 0.9]])
    mine = local_share(pts)
    count = particle_raster(comm, mine, None, ((0.0, 3.0), (0.0, 1.0)), (3, 1), reduce="count")
    top = particle_profile(comm, mine[:, 0], mine[:, 1], (0.0, 3.0), 3, reduce="max")
    if comm.rank == 0:
        np.testing.assert_array_equal(count[:, 0], [2.0, 0.0, 2.0])
        np.testing.assert_array_equal(top, [0.3, np.nan, 0.9])


def reference(x, values, bounds, shape, reduce):
    """The per-cell reduction of all particles, with bin edges from np.linspace and a loop
    over the occupied cells (independent of the module's arithmetic)."""
    idx = []
    for k, ((lo, hi), n) in enumerate(zip(bounds, shape)):
        edges = np.linspace(lo, hi, n + 1)
        idx.append(np.clip(np.searchsorted(edges, x[:, k], side="right") - 1, 0, n - 1))
    out = np.full(shape, np.nan)
    for i, j in set(zip(*idx)):
        sel = values[(idx[0] == i) & (idx[1] == j)]
        out[i, j] = dict(mean=np.mean, max=np.max, min=np.min)[reduce](sel)
    return out


@pytest.mark.parametrize("reduce", ["mean", "max", "min"])
def test_distributed_scene_matches_all_particles_on_one_rank(reduce):
    """The particles of a 10 x 6 mesh (made on MPI.COMM_WORLD, so split over the ranks when
    run under mpirun), moved by a smooth field so the cells hold different numbers of them.
    The raster equals the reference of the gathered particles and the module's own result
    for all of them on one rank (comm = COMM_SELF): max / min and counts bit for bit, the
    mean to round-off (its sums run in another order)."""
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.2]], [10, 6],
                                 dmesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1000.0), per_cell=3)
    x = p.x + 0.05 * np.sin(7.0 * p.x[:, ::-1])
    values = np.cos(3.0 * x[:, 0]) * x[:, 1] + 1e-3 * p.id
    bounds, shape = ((0.1, 1.9), (-0.05, 1.25)), (7, 5)
    r = particle_raster(comm, x, values, bounds, shape, reduce=reduce)
    n = particle_raster(comm, x, None, bounds, shape, reduce="count")
    all_x, all_v = np.concatenate(comm.allgather(x)), np.concatenate(comm.allgather(values))
    if comm.rank != 0:
        assert r is None and n is None
        return
    assert comm.size == 1 or len(x) < len(all_x)          # split over the ranks
    inside = ((all_x[:, 0] >= 0.1) & (all_x[:, 0] <= 1.9) & (all_x[:, 1] >= -0.05)
              & (all_x[:, 1] <= 1.25))
    assert n.sum() == inside.sum() and 0 < inside.sum() < len(all_x)
    ref = reference(all_x[inside], all_v[inside], bounds, shape, reduce)
    serial = particle_raster(MPI.COMM_SELF, all_x, all_v, bounds, shape, reduce=reduce)
    np.testing.assert_array_equal(np.isnan(r), n == 0)
    if reduce == "mean":
        np.testing.assert_allclose(r, ref, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(r, serial, rtol=1e-12, atol=1e-14)
    else:
        np.testing.assert_array_equal(r, ref)
        np.testing.assert_array_equal(r, serial)


GOOD = dict(x=np.array([[0.5, 0.5]]), values=np.array([1.0]), bounds=BOUNDS, shape=(2, 2))


@pytest.mark.parametrize("bad, name", [
    (dict(shape=(0, 2)), "shape"), (dict(shape=(2.0, 2)), "shape"),
    (dict(shape=(True, 2)), "shape"), (dict(shape=4), "shape"), (dict(bounds=((2.0, 0.0), (0.0, 1.0))), "bounds"),
    (dict(bounds=((0.0, 1.0), (0.0, np.inf))), "bounds"), (dict(bounds=(0.0, 1.0)), "bounds"),
    (dict(reduce="median"), "reduce"), (dict(values=np.array([1.0, 2.0])), "values"),
    (dict(values=None), "values"), (dict(x=np.array([0.5, 0.5])), "x")])
def test_bad_input_names_the_parameter(bad, name):
    kw = dict(GOOD, **bad)
    with pytest.raises(ValueError, match=f"'{name}'"):
        particle_raster(comm, kw["x"], kw["values"], kw["bounds"], kw["shape"],
                        reduce=kw.get("reduce", "mean"))


@pytest.mark.parametrize("bad, name", [(dict(n=0), "n"), (dict(bounds=(1.0, 1.0)), "bounds"),
                                       (dict(s=np.zeros((1, 2))), "s"),
                                       (dict(reduce="sum"), "reduce")])
def test_profile_bad_input_names_the_parameter(bad, name):
    kw = dict(s=np.array([0.5]), values=np.array([1.0]), bounds=(0.0, 1.0), n=2, reduce="max")
    kw.update(bad)
    with pytest.raises(ValueError, match=f"'{name}'"):
        particle_profile(comm, **kw)


def test_a_length_mismatch_on_one_rank_raises_on_every_rank():
    """Only rank 0 passes one value too many: every rank raises (none is left waiting in
    the reduction)."""
    values = np.array([1.0, 2.0]) if comm.rank == 0 else np.array([1.0])
    with pytest.raises(ValueError, match="'values'"):
        particle_raster(comm, GOOD["x"], values, BOUNDS, (2, 2))
    comm.barrier()


def test_raster_shape_counts_cells_of_the_given_size():
    """raster_shape: cells of about `size` per axis, at least one."""
    from fenicsmpm.io import raster_shape
    assert raster_shape(((0.0, 3.0), (-1.0, 1.0)), 0.5) == (6, 4)
    assert raster_shape(((0.0, 0.1), (0.0, 1.0)), 0.5) == (1, 2)
