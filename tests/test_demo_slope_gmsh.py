"""demos/slope_gmsh.py --quick (issue 20): a slope drawn with the gmsh Python API, meshed with
triangles, read with dolfinx.io.gmshio.model_to_mesh, collapses (serially and on 2 ranks)."""
import os

import pytest

from demo_helpers import exist_on_rank0, load_demo

pytest.importorskip("gmsh")


def test_slope_gmsh_demo(shared_module_tmp_path):
    """Quick run (h = 1.5 m, 0.6 s, 131 steps): the slope slides out at the toe (measured
    0.118 m) while the crest settles (measured 0.209 m), no mass is lost (408000 kg/m = rho
    times the 204 m^2 of soil), and the state stays finite."""
    out = os.path.join(shared_module_tmp_path, "slope_gmsh")
    m = load_demo("slope_gmsh").main(["--quick", "--out", out])
    assert exist_on_rank0(m["png"], m["msh"])
    assert m["steps"] == 131 and m["finite"]
    assert m["mass_initial"] == pytest.approx(2000.0 * 204.0, rel=1e-12)
    assert m["mass_final"] == pytest.approx(m["mass_initial"], rel=1e-12)
    assert 0.08 < m["toe_advance"] < 0.16, m["toe_advance"]
    assert 0.15 < m["crest_drop"] < 0.27, m["crest_drop"]
