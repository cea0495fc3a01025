"""Prescribed motion of fixed dofs in explicit runs (fm.Explicit(displacement=u(x, t)),
issue 21) and the reactions (sim.reaction): a displacement-controlled oedometric element."""
import numpy as np
import pytest
from mpi4py import MPI

import fenicsmpm as fm

E, NU = 1e6, 0.3                                  # scenes.oedometric_block
M = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))     # constrained modulus
DELTA, T = 1e-3, 0.5                              # top settlement and loading time


def _oedometer(scheme):
    """A 1 m x 1 m elastic block on a fixed base, rollers on its sides, its top nodes pushed
    down by DELTA (1 - cos(pi t / T)) / 2 (starts and ends at rest)."""
    from scenes import oedometric_block, top

    def u(x, t):
        d = np.zeros_like(x)
        d[:, 1] = -DELTA * 0.5 * (1 - np.cos(np.pi * min(t, T) / T)) * top(x)
        return d

    sim, m = oedometric_block(fm.Explicit(scheme, displacement=u), cells=10, nu=NU, dt="auto")
    assert m == M
    return sim, top


@pytest.mark.parametrize("scheme", ["MUSL", "USL"])
def test_displacement_controlled_oedometer(scheme):
    """At t = T (the element at rest at strain DELTA): the particles' sigma_yy equals
    -M DELTA within 1 % (measured: 0.000 %, MUSL and USL), the top reaction pushes down with
    M DELTA per metre within 2 % (measured -0.72 %, -0.78 %) and the base carries the same
    force upwards (+0.46 %, +0.44 %); the top particles followed the nodes."""
    sim, top = _oedometer(scheme)
    sim.run(t_end=T)
    p = sim.particles
    syy = p.total(p.V * p.stress[:, 1, 1]) / p.total(p.V)
    r_top = sim.reaction(top)
    r_base = sim.reaction(lambda x: np.isclose(x[:, 1], 0.0))
    if MPI.COMM_WORLD.rank == 0:
        print(f"\n{scheme}: sigma_yy {syy / (-M * DELTA) - 1:+.3%}, top {r_top[1] / (-M * DELTA) - 1:+.3%}, "
              f"base {r_base[1] / (M * DELTA) - 1:+.3%}")
    assert abs(syy / (-M * DELTA) - 1) < 0.01, syy
    assert abs(r_top[1] / (-M * DELTA) - 1) < 0.02, r_top
    assert abs(r_base[1] / (M * DELTA) - 1) < 0.02, r_base
    top_p = p.x[:, 1] > 0.95
    u_top = p.total(p.u[top_p, 1]) / p.total(np.ones(np.count_nonzero(top_p)))
    assert u_top < -0.9 * DELTA                       # the top particles followed the nodes


def test_displacement_input_validation():
    with pytest.raises(TypeError, match="'displacement' must be None or u"):
        fm.Explicit(displacement=1.0)
    sim, _ = _oedometer("MUSL")
    with pytest.raises(ValueError, match="reaction: .*no step has run yet"):
        sim.reaction()


def test_reaction_probe_records_the_load_curve(shared_tmp_path):
    """sim.probe_reaction(top, path, every=10) on the oedometer (MUSL): the recorded top
    reaction follows -M d(t) (d the prescribed settlement) within 6 % of M DELTA over the
    whole push (measured 4.5 %: the load takes 0.5 s, about nine periods 2 L / c_p = 0.054 s
    of the element's first mode, so the inertia of its top shows), its last row is
    sim.reaction(top), the same series on every rank, and the CSV holds the same rows."""
    import os
    from fenicsmpm.io import read_probe_csv
    sim, top = _oedometer("MUSL")
    path = os.path.join(shared_tmp_path, "reaction.csv")
    pr = sim.probe_reaction(top, path=path, every=10)
    sim.run(t_end=T)
    sim.run(steps=10 - sim.step_count % 10)           # end on a recorded step
    d = pr.data()
    t, ry = d["t"], d["reaction_y"]
    settle = DELTA * 0.5 * (1 - np.cos(np.pi * np.minimum(t, T) / T))
    t, ry, settle = t[t <= T], ry[t <= T], settle[t <= T]
    dev = np.abs(ry + M * settle).max() / (M * DELTA)
    if MPI.COMM_WORLD.rank == 0:
        print(f"\nreaction probe: {len(t)} rows, largest deviation from -M d(t): {dev:.2%}")
    assert len(d["t"]) == sim.step_count // 10 and np.all(np.diff(d["t"]) > 0)
    assert dev < 0.06, dev
    assert d["reaction_y"][-1] == sim.reaction(top)[1]
    allr = MPI.COMM_WORLD.allgather(d["reaction_y"][-1])
    assert all(v == allr[0] for v in allr)
    if MPI.COMM_WORLD.rank == 0:
        csv = read_probe_csv(path)
        assert np.allclose(csv["reaction_y"], d["reaction_y"], rtol=1e-12)
    with pytest.raises(ValueError, match="probe_reaction: 'every'"):
        sim.probe_reaction(top, every=0)
