"""Force-driven rigid bodies (fm.RigidLoad in fm.ExplicitContact; contact.rigid).

A rigid block (M = 160 kg per unit thickness) driven by F = 160 N (no gravity) starts
0.2 m from a free elastic block of the same mass (frictionless contact):
- before contact it accelerates freely: v = F t / M to round-off;
- from contact on it pushes the block: the total momentum follows the impulse F t to
  round-off (the contact mass m_c stays below M here, so the lagged reaction is not damped;
  measured 3e-14 with shape="mpm" and "cpgimp"; an added mass in every step lost 2.7 % and
  5.4 %),
- the reported reaction body_contact_force on the rigid body is minus the force on the block.
Serial and under mpirun -n 2."""
import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI

import fenicsmpm as fm

comm = MPI.COMM_WORLD


def _scene(F):
    msh = mesh.create_rectangle(comm, [[0.0, 0.0], [2.4, 0.6]], [48, 12], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    mat = fm.LinearElastic(E=1e6, nu=0.3, density=1000.0)
    box = lambda a, b: (lambda x: (x[:, 0] > a) & (x[:, 0] < b) & (x[:, 1] > 0.1) & (x[:, 1] < 0.5))
    blk = fm.Particles.fill(grid, mat, per_cell=2, region=box(0.8, 1.2))
    rig = fm.Particles.fill(grid, fm.LinearElastic(E=1e6, nu=0.3, density=1000.0), per_cell=2,
                            region=box(0.2, 0.6))
    law = fm.RigidLoad((F, 0.0))
    sim = fm.Simulation(grid, blk + rig, fm.ExplicitContact("MUSL", mu=0.0, rigid={1: law}), dt="auto")
    return sim, law


def test_free_flight_then_push():
    F, M = 160.0, 160.0
    sim, law = _scene(F)
    q = sim.particles
    rig = q.material_id == 1
    assert abs(q.total(q.mass[rig]) / M - 1) < 1e-12
    sim.run(t_end=0.3)                           # no contact yet (the gap closes at ~0.6 s)
    assert abs(law.v[0] / (F * sim.t / M) - 1) < 1e-9, law.v
    forces = []
    sim.observe(lambda s: forces.append(np.array(s.integrator.body_contact_force)))
    sim.run(t_end=1.5)
    q = sim.particles
    rig = q.material_id == 1
    p_block = q.total(q.mass[~rig] * q.v[~rig, 0])
    p_total = M * law.v[0] + p_block
    err = p_total / (F * sim.t) - 1
    fc = np.array(forces)                        # (steps, bodies, 2)
    if comm.rank == 0:
        print(f"\nRigidLoad: block momentum {p_block:.2f}, total {p_total:.2f} vs F t = "
              f"{F * sim.t:.2f} ({100 * err:+.2f} %), largest push {fc[:, 0, 0].max():.1f} N")
    assert p_block > 0.3 * F * sim.t             # the block is being pushed
    assert abs(err) < 1e-10, err
    assert fc[:, 0, 0].max() > F                 # contact acted
    assert np.abs(fc[:, 1] + fc[:, 0]).max() < 1e-9 * np.abs(fc).max()   # reaction = -action


def test_rigid_load_input():
    with pytest.raises(ValueError, match="force"):
        fm.RigidLoad((np.nan, 0.0))
    law = fm.RigidLoad((1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="length 2"):
        law.start(1.0, 2)
    with pytest.raises(ValueError, match="no mass"):
        fm.RigidLoad((1.0, 0.0)).start(0.0, 2)
