"""fm.ExplicitContact(interface="coverage"): the node-wise projection against a rigid body,
each node's correction scaled by the body's coverage of the node (contact.multi_velocity,
module docstring "Coverage interface"), serially and on 2 ranks.

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
"""
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
