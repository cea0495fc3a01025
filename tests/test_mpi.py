"""Particle ownership and migration (meaningful under mpirun -n 2; also runs serially)."""
import numpy as np
import pytest
from mpi4py import MPI
from dolfinx import mesh

import fenicsmpm as fm


def _jitter(msh, amp=0.01):
    x = msh.geometry.x
    inner = np.all((x[:, :2] > 1e-9) & (x[:, :2] < 1 - 1e-9), axis=1)
    x[inner, 0] += amp * np.sin(37 * x[inner, 1])
    x[inner, 1] += amp * np.cos(23 * x[inner, 0])


@pytest.mark.parametrize("cell_type", [mesh.CellType.quadrilateral, mesh.CellType.triangle])
@pytest.mark.parametrize("structured", [True, False])
def test_translating_block_migrates(cell_type, structured):
    """A block translating across the whole mesh (and across rank boundaries) keeps every
    particle, owned by the rank of its cell, with F = I and its momentum."""
    comm = MPI.COMM_WORLD
    msh = mesh.create_rectangle(comm, [[0, 0], [1, 1]], [16, 16], cell_type)
    if not structured:
        _jitter(msh)
    grid = fm.Grid(msh)
    assert grid.structured == structured
    mat = fm.LinearElastic(E=10.0, nu=0.3, density=1.0)
    v = np.array([1.0, 0.8])
    p = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: (x[:, 0] < 0.3) & (x[:, 1] < 0.3),
                          velocity=v)
    n0, ids0 = p.n_global(), np.sort(np.concatenate(comm.allgather(p.id)))
    m0 = p.total(p.mass)
    sim = fm.Simulation(grid, p, fm.Explicit("MUSL"), dt=0.005)
    sim.run(steps=100)                       # moves 0.5 in x, 0.4 in y
    ids = np.sort(np.concatenate(comm.allgather(p.id)))
    assert p.n_global() == n0 and np.array_equal(ids, ids0), "particles lost or duplicated"
    owned = comm.allreduce(int(np.all((p.cell >= 0) & (p.cell < grid.n_owned_cells))), op=MPI.MIN)
    assert owned == 1, "a particle sits on a rank that does not own its cell"
    assert np.allclose(p.momentum() / m0, v, rtol=1e-12, atol=0)
    fdev = comm.allreduce(float(np.max(np.abs(p.F - np.eye(3)), initial=0.0)), op=MPI.MAX)
    assert fdev < 1e-12
    # positions: x = x0 + v t exactly (uniform translation)
    err = comm.allreduce(float(np.max(np.abs(p.u - v * sim.t), initial=0.0)), op=MPI.MAX)
    assert err < 1e-12


def test_leaving_the_domain_is_reported_on_all_ranks():
    comm = MPI.COMM_WORLD
    msh = mesh.create_rectangle(comm, [[0, 0], [1, 1]], [8, 8], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=10.0, nu=0.3, density=1.0)
    p = fm.Particles.fill(grid, mat, per_cell=2, region=lambda x: x[:, 0] > 0.8, velocity=(1.0, 0.0))
    n_edge = p.n_global()
    sim = fm.Simulation(grid, p, fm.Explicit("MUSL"), dt=0.005)
    with pytest.raises(RuntimeError, match=r"particle\(s\) left the mesh"):
        sim.run(steps=100)
    # the outermost particle column (x = 1 - h/4 = 0.96875) leaves after ceil(0.03125/0.005) steps
    assert sim.step_count == 7
    assert n_edge > 0


def test_from_points_is_distributed():
    """Points given on rank 0 end up on the ranks owning their cells; none is lost."""
    comm = MPI.COMM_WORLD
    msh = mesh.create_rectangle(comm, [[0, 0], [1, 1]], [8, 8], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=10.0, nu=0.3, density=1.0)
    rng = np.random.default_rng(0)
    pts = rng.random((200, 2)) if comm.rank == 0 else np.zeros((0, 2))
    p = fm.Particles.from_points(grid, mat, pts, 1e-3)
    assert p.n_global() == 200
    assert np.all(p.cell < grid.n_owned_cells) and np.all(p.cell >= 0)
    allx = np.concatenate(comm.allgather(p.x))
    ref = rng.__class__(np.random.PCG64(0)).random((200, 2))
    assert np.allclose(np.sort(allx[:, 0]), np.sort(ref[:, 0]), atol=0)
    with pytest.raises(ValueError, match="outside the mesh"):
        fm.Particles.from_points(grid, mat, np.array([[1.5, 0.5]]) if comm.rank == 0 else np.zeros((0, 2)), 1e-3)


def test_an_error_on_one_rank_is_raised_on_every_rank():
    """errors.raise_together: a RuntimeError on the last rank only reaches every rank (the
    others quote it), so none waits in a collective the failing rank never reaches; without
    an error the value comes back, and in serial the call is plain."""
    from fenicsmpm.errors import raise_together
    comm = MPI.COMM_WORLD
    assert raise_together(comm, lambda a: a + 1, 1) == 2

    def fail_last():
        if comm.rank == comm.size - 1:
            raise RuntimeError("the domain of particle 7 reaches grid nodes that are not local")
        return 0
    with pytest.raises(RuntimeError, match="particle 7") as err:
        raise_together(comm, fail_last)
    if comm.size > 1 and comm.rank != comm.size - 1:
        assert str(err.value).startswith(f"on rank {comm.size - 1}: RuntimeError: ")
    assert comm.allreduce(1) == comm.size              # every rank is here, none hangs
