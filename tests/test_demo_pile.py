"""demos/pile_jacking.py --quick (h = 0.3 m, 0.6 s): an axisymmetric rigid pile jacked into
Mohr-Coulomb sand with multi-velocity frictional contact (mu = 0.2) and a viscous base.

- geostatic sigma_v of the base particles within 1 % of -rho g (H - h/4) (K0 state);
- the tip penetration equals the prescribed push, 0.5 m/s (t - 0.05 s), within 3 %;
- the tip loads the soil: the largest vertical stress within 1 m below the tip is more than
  twice the geostatic stress 1 m below the tip (measured -286 kPa against -25 kPa; -223 kPa
  at h = 0.15 m and 1 s). The pile resistance is printed, not asserted: at --quick's h = 0.3 m
  the pile is half a cell wide (the demo's default h = 0.075 m converges with its default
  interface="coverage": 31.0 / 31.2 kN at h = 0.075 / 0.0375 m; the demo docstring and
  tests/test_coverage_contact.py);
- JSON and PNG are written. Serial and under mpirun -n 2."""
import os

from demo_helpers import exist_on_rank0, load_demo


def test_pile_jacking_demo(shared_module_tmp_path):
    out = os.path.join(shared_module_tmp_path, "pile")
    demo = load_demo("pile_jacking")
    r = demo.main(["--quick", "--out", out])
    assert abs(r["sigma_v_base"] / r["sigma_v_base_exact"] - 1) < 0.01, r
    push = demo.V_PUSH * (0.6 - demo.T_RAMP / 2)
    assert abs(r["penetration"] / push - 1) < 0.03, (r["penetration"], push)
    geostatic = -demo.RHO * demo.G * (r["penetration"] + 1.0)
    assert r["sigma_zz_below_tip"] < 2 * geostatic, r
    assert exist_on_rank0(os.path.join(out, "pile_jacking.json"), os.path.join(out, "pile_jacking.png"))


def test_resistance_table_windows():
    """The resistance table's windows tile the penetration and hold the mean of the force
    recorded in them."""
    import numpy as np
    demo = load_demo("pile_jacking")
    d = np.linspace(0.0, 0.2, 201)
    F = 1e3 * (1.0 + d)
    rows = demo.resistance_table(d, F, width=0.075)
    assert [(round(a, 3), round(b, 3)) for a, b, _ in rows] == [(0.0, 0.075), (0.075, 0.15),
                                                               (0.15, 0.225)]
    for a, b, r in rows:
        w = (d >= a) & (d < b)
        assert abs(r - F[w].mean()) < 1e-9 * r
