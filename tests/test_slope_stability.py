"""Bishop's simplified factor of safety (fenicsmpm.problems.slope_stability), the reference for
the L4 slope's strength-reduction factor (demos/slope_failure.py)."""
import numpy as np
import pytest

from fenicsmpm.problems.slope_stability import bishop


def _ssnp006(x, toe=4.5):
    """code_aster's SSNP006 slope: 4.5 m high at 1V:2H on 2 m of foundation, 18 m wide."""
    return 2.0 + 4.5 * np.clip((x - toe) / 9.0, 0.0, 1.0)


def test_published_bishop_factor():
    """SSNP006 (gamma = 16 kN/m^3, c = 5 kPa, phi = 20 deg): Verruijt's simplified Bishop
    gives 1.534 (Plaxis' strength reduction 1.54); measured 1.539, within 0.5 %, the critical
    circle leaving through the toe (4.50 m)."""
    r = bishop(_ssnp006, 16e3, 5e3, 20.0, (0.0, 18.0))
    assert r["factor"] == pytest.approx(1.534, rel=5e-3), r
    assert r["entry_exit"][0] == pytest.approx(4.5, abs=0.1), r


def test_cohesionless_slope_is_the_infinite_slope():
    """c = 0: the critical circle shrinks to the face, F = tan(phi) / tan(beta) (1V:2H,
    phi = 20 deg: 0.7279), within 1 %; mirrored (facing right) the same factor."""
    coarse = dict(centres=(32, 32), radii=40)
    F = np.tan(np.radians(20.0)) / 0.5
    left = bishop(_ssnp006, 16e3, 0.0, 20.0, (0.0, 18.0), **coarse)
    right = bishop(lambda x: _ssnp006(18.0 - x), 16e3, 0.0, 20.0, (0.0, 18.0), **coarse)
    assert left["factor"] == pytest.approx(F, rel=0.01), left
    assert right["factor"] == pytest.approx(left["factor"], rel=1e-9), (left, right)
    assert right["entry_exit"] == pytest.approx((18.0 - left["entry_exit"][1],
                                                 18.0 - left["entry_exit"][0])), (left, right)


@pytest.mark.parametrize("kw,match", [(dict(c=-1.0), "'c'"), (dict(phi=90.0), "'phi'"),
                                      (dict(unit_weight=0.0), "'unit_weight'"),
                                      (dict(x_range=(5.0, 5.0)), "'x_range'"),
                                      (dict(facing="up"), "'facing'")])
def test_bad_input(kw, match):
    args = dict(surface=_ssnp006, unit_weight=16e3, c=5e3, phi=20.0, x_range=(0.0, 18.0))
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        bishop(**args)
