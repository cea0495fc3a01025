"""Particle splitting (issue 10; seed 002 §3.4.1 eq 3.25): mass and momentum are conserved
exactly, children carry the parent's affine velocity field, a rigid rotation splits nothing,
and the ids stay globally unique under MPI."""
import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.partition import strips

WORLD = MPI.COMM_WORLD
A = np.array([[0.3, -0.2], [0.5, 0.1]])
B = np.array([0.7, -0.4])


def _setup(n=8, velocity=None, E=1e-3):
    """A 1 m block in a 4 m square grid cut into reproducible strips (fm.partition)."""
    msh = mesh.create_rectangle(WORLD, [[0, 0], [4, 4]], [n, n], mesh.CellType.quadrilateral,
                                partitioner=strips(n, n))
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=E, nu=0.0, density=1.0)
    p = fm.Particles.fill(grid, mat, per_cell=2, velocity=velocity,
                          region=lambda x: np.all((x > 1.5) & (x < 2.5), axis=1))
    return grid, p


def test_children_carry_the_affine_velocity_and_conserve_mass_and_momentum():
    grid, p = _setup(velocity=lambda x: x @ A.T + B)
    sim = fm.Simulation(grid, p, fm.Explicit("USL"), dt=1e-3)
    split = sim.enable_splitting()
    sim.locate_and_shape()
    sim.nodal = dict(velocity=grid.node_x @ A.T + B)          # the affine grid field
    p.voxel[::3, 0, 0] *= 2.5                                  # every third voxel stretched in x
    m0, mom0, n0 = p.total(p.mass), p.momentum(), p.n_global()
    expected = WORLD.allreduce(len(range(0, len(p), 3)))
    n_split = split.apply(sim)
    assert n_split == expected > 0
    assert p.n_global() == n0 + n_split and split.count == n_split
    assert np.isclose(p.total(p.mass), m0, rtol=1e-15, atol=0)
    assert np.allclose(p.momentum(), mom0, rtol=1e-14, atol=0)
    assert np.allclose(p.v, p.x @ A.T + B, rtol=0, atol=1e-13), "children off the affine field"
    ids = np.concatenate(WORLD.allgather(p.id))
    assert len(np.unique(ids)) == len(ids), "ids not unique after splitting"
    # the children of a stretched voxel sit a quarter of its (stretched) edge from the parent
    assert np.allclose(np.sort(p.voxel[:, 0, 0])[: 3], np.sort(p.voxel[:, 0, 0])[0])


def test_free_extension_splits_and_rotation_does_not():
    """A block stretching freely along x with v = (x - 2, 0) (stress negligible, E = 1e-3;
    the particles keep their velocities, so the stretch is 1 + t) for 1.5 s: every particle
    splits along x when its voxel's stretch passes alpha = 2 (the interior 6 of 8 particle
    columns; the outermost columns see the smaller gradient of the block's edge nodes), never
    along y."""
    rate = 1.0
    grid, p = _setup(n=16, velocity=lambda x: np.c_[rate * (x[:, 0] - 2.0), np.zeros(len(x))])
    n0, m0 = p.n_global(), p.total(p.mass)
    sim = fm.Simulation(grid, p, fm.Explicit("USL"), dt=2e-3)
    split = sim.enable_splitting()
    sim.run(t_end=1.5)
    assert split.count >= 0.75 * n0, (split.count, n0)
    q = sim.particles
    assert q.n_global() == n0 + split.count
    side = 0.125                                               # 2 particles per 0.25 m cell
    assert np.allclose(q.voxel[:, 1, 1], side) and np.allclose(q.voxel[:, 0, 1], 0.0)
    reset = WORLD.allreduce(int(np.count_nonzero(~np.isclose(q.voxel_ref[:, 0, 0], side))))
    assert reset == 2 * split.count                           # both children of each split
    assert np.isclose(sim.particles.total(sim.particles.mass), m0, rtol=1e-14)



def test_rigid_rotation_does_not_split_but_simple_shear_does():
    """eq 3.25 on C = F_s^T F_s: a rotation by 100 degrees (the seed's F_11 = cos < beta would
    split it) does not trigger; a simple shear F_12 = 1.2 > gamma does, across the sheared edge."""
    from fenicsmpm.splitting import push_forward_voxels, split_directions
    c, s_ = np.cos(np.radians(100.0)), np.sin(np.radians(100.0))
    rot = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1.0]])
    shear = np.array([[1, 1.2, 0], [0, 1, 0], [0, 0, 1.0]])
    E = np.tile(np.eye(2) * 0.5, (2, 1, 1))
    E_ref = E.copy()
    push_forward_voxels(np.stack([rot, shear]), E)
    edge = np.empty(2, dtype=np.int64)
    assert split_directions(E, E_ref, 2.0, 0.5, 1.0, edge) == 1
    assert edge[0] == -1 and edge[1] == 1                     # the sheared edge (0.6, 0.5) is longer


def test_splitting_input_validation():
    grid, p = _setup()
    sim = fm.Simulation(grid, p, fm.Explicit("USL"), dt=1e-3)
    with pytest.raises(ValueError, match="alpha > 1 > beta"):
        sim.enable_splitting(alpha=0.9)
    with pytest.raises(ValueError, match="'gamma' must be a finite number > 0"):
        sim.enable_splitting(gamma=-1.0)


def test_restart_continues_split_ids(shared_tmp_path):
    """A checkpoint after splits: the restarted run numbers new children after the old ones
    and reproduces the continuous run bit for bit."""
    import os
    path = os.path.join(shared_tmp_path, "ck")

    def build():
        grid, p = _setup(n=16, velocity=lambda x: np.c_[x[:, 0] - 2.0, np.zeros(len(x))])
        sim = fm.Simulation(grid, p, fm.Explicit("USL"), dt=2e-3)
        sim.enable_splitting()
        return sim
    ref = build()
    ref.run(steps=600)
    first = build()
    first.run(steps=500, checkpoint=path, checkpoint_every=500)   # splits at 487 | 509, 552
    assert first.splitting.count > 0
    again = fm.Simulation.restart(path, build)
    assert again.splitting.count == first.splitting.count
    again.run(steps=100)
    assert again.splitting.count == ref.splitting.count > first.splitting.count
    assert np.array_equal(again.particles.id, ref.particles.id)
    assert np.array_equal(again.particles.x, ref.particles.x)


@pytest.mark.parametrize("cell, shape", [(mesh.CellType.quadrilateral, "auto"),
                                         (mesh.CellType.quadrilateral, "cpdi2"),
                                         (mesh.CellType.triangle, "auto"),
                                         (mesh.CellType.quadrilateral, "cpdi1"),
                                         (mesh.CellType.triangle, "cpdi1")],
                         ids=["cpgimp", "cpdi2-quads", "cpdi2-triangles", "cpdi1-quads",
                              "cpdi1-triangles"])
def test_children_get_half_the_parents_domain(cell, shape):
    """The children of a split share the parent's particle domain (splitting.halve_domains):
    cpGIMP boxes halve along the cut axis, CPDI2 domains are cut in two through edge
    midpoints. Every domain then has its particle's volume (round-off) and the domains still
    tile the 1 m^2 block. Before,
    both children kept the parent's whole domain with half its mass. CPDI1's edges and
    simplex offsets likewise. dolfinx's default
    partitioner under MPI."""
    msh = mesh.create_rectangle(WORLD, [[0, 0], [4, 4]], [8, 8], cell)
    grid = fm.Grid(msh)
    p = fm.Particles.fill(grid, fm.LinearElastic(E=1e-3, nu=0.0, density=1.0), per_cell=2,
                          region=lambda x: np.all((x > 1.5) & (x < 2.5), axis=1))
    sim = fm.Simulation(grid, p, fm.Explicit("USL"), dt=1e-3, shape=shape)
    split = sim.enable_splitting()
    sim.locate_and_shape()
    sim.nodal = dict(velocity=np.zeros((grid.n_nodes, 2)))
    p.voxel[::3, 0, 0] *= 2.5                                  # cut across x
    assert split.apply(sim) > 0
    if sim.shape == "cpgimp":
        area = 4.0 * p.gimp_l0[:, 0] * p.gimp_l0[:, 1]         # F = I: box (2 l0x) x (2 l0y)
        assert WORLD.allreduce(int(np.sum(np.isclose(p.gimp_l0[:, 0], 0.0625)))) > 0
    elif sim.shape == "cpdi1" and cell == mesh.CellType.quadrilateral:
        area = np.abs(np.linalg.det(p.cpdi_r0))                # parallelogram of r1, r2
    else:
        c = p.cpdi_corners if sim.shape == "cpdi2" else p.cpdi_t0
        x, y = c[..., 0], c[..., 1]
        area = 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)
    assert np.all(area > 0.0) and np.allclose(area, p.V, rtol=1e-12, atol=0.0)
    assert abs(WORLD.allreduce(float(area.sum())) - 1.0) < 1e-12
