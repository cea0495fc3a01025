"""fm.ExplicitContact(interface="coverage"): the node-wise projection against a rigid body,
each node's correction scaled by the body's coverage of the node (contact.multi_velocity,
module docstring "Coverage interface"; the default interface="auto" scales the pairs of the
paired interface by it against rigid bodies that are axis-aligned boxes), serially and on 2
ranks.

- The coverage of Prandtl's footing (problems.footing.strip_footing, B/2 = 0.5 m, h = 0.25 m:
  its edge on a grid line) after one step: 0.5 at the edge node (the footing covers half of
  its cell patch), 1 at the node in between and at the node on the symmetry line (a grid
  boundary: half a patch, which the footing covers; the roller is taken out of the normals),
  every value in [0, 1]; the pressure history to 0.8 s the same on 2 ranks as serially (1e-6).
- The rough footing (mu = 10, von Mises soil, the defaults) with its edge on a grid line, 5
  cells under B/2 (h = 0.1 m), pushed to 0.8 s: the pressure from 0.5 s on within 3 % of
  (2 + pi) c_u (measured 1.0126; the node-wise projection 1.083 there, the footing acting
  half a cell wider: `python -m fenicsmpm.bench bearing-capacity`, rows rough /
  rough-coverage, docs/guide/contact.md).
- The half model (symmetry line a roller) reads what the whole footing does.
- A rigid V-shaped wedge (faces 30 degrees from the horizontal) pushed 0.2 m into an elastic
  block with the default interface (node-wise: the wedge is not a box): no soil particle's domain enters the wedge
  (measured at h = 0.05 m: 8.4 mm clear; with interface="coverage" the half-held nodes at the
  wedge's tip let the soil in, 53.9 mm deep, which is why "coverage" is for bodies with
  axis-aligned faces: `PYTHONPATH=. python tests/test_coverage_contact.py 0.05 coverage`).
"""
import sys

import numpy as np
from mpi4py import MPI

from fenicsmpm.problems.footing import strip_footing, B2

comm = MPI.COMM_WORLD
DEPTH = 3.0                 # strip_footing's soil depth: the footing's base


def _history(c, h, t_end, **scene):
    sim, q, _ = strip_footing(h=h, interface="coverage", comm=c, **scene)
    t, p, first = [], [], []

    def record(s):
        t.append(s.t)
        p.append(q())
        if not first:
            first.append(s.integrator._cover[:, 1].copy())
    sim.observe(record, every=1)
    sim.run(t_end=t_end, progress=False)
    return sim, np.array(t), np.array(p), first[0]


def test_footing_coverage_half_at_the_edge_and_serial_equals_parallel():
    sim, t, q, cover = _history(comm, 0.25, 0.8)
    x = sim.grid.node_x
    assert np.all((cover >= 0.0) & (cover <= 1.0))
    for xn, expect in ((B2, 0.5), (B2 - 0.25, 1.0), (0.0, 1.0)):
        at = np.isclose(x[:, 0], xn) & np.isclose(x[:, 1], DEPTH)
        vals = [v for part in comm.allgather(cover[at].tolist()) for v in part]
        assert vals, xn
        assert np.allclose(vals, expect, atol=2e-3), (xn, vals)
    if comm.size > 1:
        _, ts, qs, _ = _history(MPI.COMM_SELF, 0.25, 0.8)
        assert len(ts) == len(t)
        assert np.allclose(q, qs, rtol=1e-6, atol=1e-9), np.abs(q - qs).max()


def test_rough_footing_on_a_grid_line_reaches_prandtl():
    _, t, q, _ = _history(comm, 0.1, 0.8, mu=10.0)
    late = float(np.mean(q[t >= 0.5]))
    print(f"\nrough footing, coverage, 5 cells under B/2: q / (2 + pi) c_u = {late:.4f}")
    assert abs(late - 1.0) < 0.03, late



def test_half_model_equals_the_whole_footing():
    """The default interface treats the symmetry line (a roller) as a mirror: Prandtl's smooth
    footing at 2 cells under B/2 reads the same as a half model and as the whole footing in a
    soil body twice as wide (measured 1.1330 both with the default paired interface, 1.3415
    with the coverage interface, the default before, the mean over the steps from 0.5 s; with
    interface="node" the bench's 0.1 s windows read 1.164 half and 1.374 whole: its half
    model under-holds the footing's node on the symmetry line, whose mass-gradient normal
    is diagonal)."""
    q = []
    for half in (True, False):
        sim, p, _ = strip_footing(h=0.25, half=half)
        hist = []
        sim.observe(lambda s: hist.append((s.t, p())), every=1)
        sim.run(t_end=0.8, progress=False)
        t, v = np.array(hist).T
        q.append(float(np.mean(v[t >= 0.5])))
    print(f"\nsmooth footing, 2 cells under B/2: half model {q[0]:.4f}, whole {q[1]:.4f}")
    assert abs(q[0] - q[1]) < 1e-3 * q[1], q

def wedge(h=0.1, interface=None, c=comm, theta=30.0, push=0.2):
    """A rigid V wedge (faces theta from the horizontal, apex down) pushed `push` m into an
    elastic block 0.8 m deep at 0.2 m/s with fm.ExplicitContact's `interface` (None: its
    default); returns the deepest soil particle domain inside the wedge [m] (> 0: inside)."""
    from dolfinx import mesh
    import fenicsmpm as fm
    msh = mesh.create_rectangle(c, [[0, 0], [2.0, 1.6]], [round(2.0 / h), round(1.6 / h)],
                                mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    t, y0, xc, v = np.tan(np.radians(theta)), 0.8, 1.0, 0.2
    soil, rigid = (fm.LinearElastic(E=1e6, nu=0.3, density=1000.0) for _ in range(2))
    top = y0 + 0.01 + 0.5 * t + 0.3
    p = (fm.Particles.fill(grid, soil, per_cell=2, region=lambda x: x[:, 1] < y0)
         + fm.Particles.fill(grid, rigid, per_cell=2, region=lambda x: (
             x[:, 1] > y0 + 0.01 + np.abs(x[:, 0] - xc) * t) & (x[:, 1] < top)
             & (np.abs(x[:, 0] - xc) < 0.5)))
    kw = {} if interface is None else dict(interface=interface)
    sim = fm.Simulation(grid, p, fm.ExplicitContact("MUSL", rigid={1: (0.0, -v)}, **kw), dt="auto")
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0))
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], 2.0), [0])
    sim.run(t_end=push / v, progress=False)
    q = sim.particles
    sel = q.material_id == 0
    apex = y0 + 0.01 - v * sim.t
    x = q.x[sel]
    depth = (((x[:, 1] - apex) - np.abs(x[:, 0] - xc) * t) * np.cos(np.radians(theta))
             - 0.5 * np.sqrt(q.V[sel]))
    return c.allreduce(float(depth.max(initial=-1.0)), op=MPI.MAX)


def test_auto_takes_boxes_on_cells_of_any_aspect_ratio():
    """interface="auto" scales the corrections against a rigid box by its coverage also on
    cells of unequal spacings (0.1 x 0.05 m: the particle domains are boxes of the cell's
    aspect ratio, as Particles.fill makes them), not against a rigid wedge there."""
    from dolfinx import mesh
    import fenicsmpm as fm
    msh = mesh.create_rectangle(comm, [[0, 0], [2.0, 1.6]], [20, 32], mesh.CellType.quadrilateral)
    grid = fm.Grid(msh)
    chosen = []
    for wedge_shaped in (False, True):
        soil, rigid = (fm.LinearElastic(E=1e6, nu=0.3, density=1000.0) for _ in range(2))
        body = ((lambda x: (x[:, 1] > 0.8 + np.abs(x[:, 0] - 1.0) * 0.5) & (x[:, 1] < 1.4))
                if wedge_shaped else (lambda x: (x[:, 1] > 0.8) & (x[:, 1] < 1.2)
                                      & (np.abs(x[:, 0] - 1.0) < 0.3)))
        p = (fm.Particles.fill(grid, soil, per_cell=2, region=lambda x: x[:, 1] < 0.8)
             + fm.Particles.fill(grid, rigid, per_cell=2, region=body))
        sim = fm.Simulation(grid, p, fm.ExplicitContact("MUSL", rigid={1: (0.0, -0.1)}),
                            dt="auto")
        sim.run(steps=1, progress=False)
        chosen.append(sim.integrator._interface_bodies(sim))
    assert chosen == [((1,), (1,)), ((), ())], chosen


def test_wedge_default_interface_keeps_the_soil_out():
    deepest = wedge()
    print(f"\nrigid 30 deg wedge, default interface: deepest soil domain {1e3 * deepest:+.1f} mm")
    assert deepest < 0.0, deepest


if __name__ == "__main__":
    h, interface = float(sys.argv[1]), sys.argv[2]
    deepest = wedge(h, interface)
    if comm.rank == 0:
        print(f"wedge, h = {h} m, interface={interface!r}: deepest soil particle domain inside "
              f"the wedge {1e3 * deepest:+.1f} mm")
