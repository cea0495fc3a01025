"""demos/site_response.py builds its column with the public API (issue 20); it is the scene of
fenicsmpm.problems.soil_column (rigid base, gravity at t = 0): the first 40 steps agree bit for
bit with it, for an explicit and an implicit integrator."""
import numpy as np
import pytest

import fenicsmpm as fm
from fenicsmpm.problems import soil_column as sr

from demo_helpers import load_demo


@pytest.mark.parametrize("make", [fm.Explicit, fm.Newmark], ids=["explicit", "newmark"])
def test_demo_scene_is_the_soil_column(make):
    demo = load_demo("site_response")
    runs = []
    for build in (lambda: demo.build(make(), 0.5, 2.0),
                  lambda: sr.soil_column(make(), h=0.5, gravity="sudden", t_end=2.0)):
        sim, info = build()
        sim.run(steps=40, progress=False)
        d = info["probes"]["top"].data()
        runs.append((sim.dt, d["velocity_x"], d["velocity_y"]))
    assert runs[0][0] == runs[1][0]
    assert np.array_equal(runs[0][1], runs[1][1]) and np.array_equal(runs[0][2], runs[1][2])
    assert np.max(np.abs(runs[0][1])) > 0.0                  # the base motion arrived
