"""XPIC(m) (fm.Explicit(transfer="xpic"), Hammerquist & Nairn 2017; issue 15 item 2): one
force-free step against the transfer written with explicit matrices."""
import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm


def _step(comm, **kw):
    """A stress-free elastic block with a smooth velocity field plus particle noise, one
    step without forces: (v before, v after, S (n_p, n_nodes), particle masses)."""
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [6, 6],
                                mesh.CellType.quadrilateral)
    g = fm.Grid(msh)
    pts = fm.Particles.fill(g, fm.LinearElastic(E=1e3, nu=0.3, density=1.0), per_cell=2,
                            region=lambda x: (x[:, 0] < 0.8) & (x[:, 1] < 0.7))
    rng = np.random.default_rng(1 + comm.rank)
    pts.v[:, 0] = 0.3 + 0.2 * pts.x[:, 1] + 0.05 * rng.standard_normal(len(pts))
    pts.v[:, 1] = -0.2 * pts.x[:, 0] + 0.05 * rng.standard_normal(len(pts))
    sim = fm.Simulation(g, pts, fm.Explicit("USL", **kw), dt=1e-9, shape="cpgimp")
    v0 = pts.v.copy()
    sim.run(steps=1, progress=False)
    S = np.zeros((len(pts), g.n_nodes))
    rows = np.repeat(np.arange(len(pts)), sim.nodes.shape[1])
    np.add.at(S, (rows, sim.nodes.ravel()), sim.N.ravel())      # padding adds N = 0
    return v0, sim.particles.v, S, sim.particles.mass


@pytest.mark.parametrize("order", [1, 2, 5])
def test_xpic_takes_the_grid_invisible_part_off_the_particle_velocities(order):
    """v^(n+1) = v^n - (I - S S+)^m v^n with no force (module docstring of
    integrators.explicit; S+ = M^-1 S^T M_p), to round-off; m = 1 is PIC, and the transfer
    keeps a uniform velocity. Each rank runs its own serial block (the matrices are local)."""
    v0, v1, S, mp = _step(MPI.COMM_SELF, transfer="xpic", xpic_order=order)
    m = S.T @ mp
    on = m > 0.0
    Sp = np.zeros_like(S.T)
    Sp[on] = (S.T[on] * mp[None, :]) / m[on, None]
    R = np.eye(len(mp)) - S @ Sp
    expect = v0 - np.linalg.matrix_power(R, order) @ v0
    assert np.abs(v1 - expect).max() < 1e-12, np.abs(v1 - expect).max()
    if order == 1:
        _, v_pic, _, _ = _step(MPI.COMM_SELF, transfer="flip", flip=0.0)
        assert np.abs(v1 - v_pic).max() < 1e-14
    assert np.abs(R @ v0).max() > 1e-2             # the noise FLIP would keep is there


def test_xpic_keeps_a_uniform_velocity_under_mpi():
    """A uniform velocity goes through XPIC(3) unchanged (S and S+ reproduce constants),
    on the grid shared by all ranks."""
    msh = mesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [1.0, 1.0]], [6, 6],
                                mesh.CellType.quadrilateral)
    g = fm.Grid(msh)
    pts = fm.Particles.fill(g, fm.LinearElastic(E=1e3, nu=0.3, density=1.0), per_cell=2,
                            velocity=lambda x: np.tile([0.3, -0.2], (len(x), 1)))
    sim = fm.Simulation(g, pts, fm.Explicit("MUSL", transfer="xpic", xpic_order=3), dt=1e-9,
                        shape="cpgimp")
    sim.run(steps=2, progress=False)
    assert np.abs(sim.particles.v - [0.3, -0.2]).max() < 1e-12


def test_xpic_input_validation():
    with pytest.raises(ValueError, match="'xpic_order' must be an int >= 1"):
        fm.Explicit(transfer="xpic", xpic_order=0)
    with pytest.raises(ValueError, match="'flip' applies to"):
        fm.Explicit(transfer="xpic", flip=0.5)
