"""The softening Mohr-Coulomb slope of issue 19 (fenicsmpm.problems.softening_slope), serially
and under `mpirun -n 2`, at h = H/8 (248 particles, about 2 s a run).

Physics asserted: softening from the peak to the residual strength puts the run-out between
those of the perfectly plastic slopes at the peak and at the residual strength (measured at
H/8: 1.7 / 15.4 (regularised, l = 1.25 m) / 17.0 m), and every run comes to rest.  Run-out
convergence with h is measured by `python -m fenicsmpm.bench localisation` (H/32 in 30-45 s),
not here."""
from fenicsmpm.problems.softening_slope import runout, soil


def test_softening_runout_between_peak_and_residual(comm):
    peak = runout(8, soil(softening=False), comm=comm)
    res = runout(8, soil(residual=True), comm=comm)
    soft = runout(8, soil(1.25), comm=comm)
    for r in (peak, res, soft):
        assert r["finished"] and r["t_rest"] == r["t_rest"], r       # at rest, no error
    assert peak["runout"] < 0.5 * soft["runout"], (peak["runout"], soft["runout"])
    assert 0.5 * res["runout"] < soft["runout"] < res["runout"], (soft["runout"], res["runout"])
    assert soft["nonlocal_s"] > 0.0
