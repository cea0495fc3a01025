"""demos/pile_jacking.py --quick (h = 0.3 m, 0.6 s): an axisymmetric rigid pile jacked into
Mohr-Coulomb sand with multi-velocity frictional contact (mu = 0.2) and a viscous base.

- geostatic sigma_v of the base particles within 1 % of -rho g (H - h/4) (K0 state);
- the tip penetration equals the prescribed push, 0.5 m/s (t - 0.05 s), within 3 %;
- the soil resistance on the pile is between 0.5 and 3 times the closed-form shaft + tip
  estimate at that depth (measured 9.1 kN against 7.1 kN: ratio 1.28);
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
    ratio = r["resistance"] / (r["shaft_estimate"] + r["tip_estimate"])
    assert 0.5 < ratio < 3.0, r
    assert exist_on_rank0(os.path.join(out, "pile_jacking.json"), os.path.join(out, "pile_jacking.png"))
