"""The geomechanics demos (issue 7) in --quick mode, in-process, serially and under
`mpirun -n 2`, and the `plasticity` benchmark case in a tiny mode.

Assertions and their reasons:
  column collapse (L3, h = 0.8 m, to t = 2 s): the run completes (the guards would raise on a
    non-finite state, an inverted particle or one leaving the mesh), every position and stress
    is finite, min det F > 0 over the run, the total mass is conserved to round-off (particle
    masses never change; no splitting), no particle was lost, the runout is reported and
    positive (the unsupported column spreads: > 1 m) and the deposit is lower than the column
    (H = 8 m), the mean speed rose from rest and is below its peak at the end, and plastic
    strain developed (max eps_d^p > 0.1).
  slope (L4, 20 x 11 cells): the unreduced phi = 18 deg, c = 5 kPa slope is reported and
    fails (the seed's slide; Bishop's simplified method gives F = 0.598 < 1, reported by the
    demo, within 0.5 % of that), the bisection bracket is valid (stable at its lower end,
    failed at its upper end), lies in (0, 1], is 0.25 wide and holds Bishop's factor
    (measured (0.5, 0.75], with the standard family and with cpGIMP); the failed runs moved
    the crest by more than the stable ones.
  strip footing (W5, dx = 0.25 m, first pulse, fixed and viscous bases): the geostatic
    sigma_yy of the bottom particle row matches -rho g d within 2 % and the surface settles
    by the 1D elastic closed form rho g (H y0 - y0^2/2) / M within 1 % (the quasi-static
    gravity stage is elastic: the geostatic deviator stays below sqrt(3) c_u); the pulse pushes the footing down (settlement > 0) and the
    surface particle's peak velocity is positive and below the 1D plane-wave bound
    p / (rho c_p) = 0.587 m/s (2D spreading under a B/2 = 0.25 m load only lowers it: the
    seed measures 0.52 m/s at dx = 0.0625 m); the fixed base reflects the pulse, so its
    dynamic bottom stress exceeds the viscous base's. No closed form applies to the settlement
    (a finite layer with softening under a dynamic load); the Prandtl load (2 + pi) c_u =
    51.4 kPa is above the 40 kPa pulse, so the footing must not fail in the first pulse:
    settlement < 0.1 m.
  bench `plasticity` (tiny: t_end = 0.05 s, quick sizes): JSON schema, PNG, four runs with
    finite runouts, Newton iterations reported for the implicit runs only.
"""
import json
import os

from mpi4py import MPI

from demo_helpers import exist_on_rank0, load_demo

comm = MPI.COMM_WORLD


def test_column_collapse_demo(shared_module_tmp_path):
    out = os.path.join(shared_module_tmp_path, "collapse")
    m = load_demo("column_collapse").main(["--quick", "--out", out])
    assert exist_on_rank0(m["png"], m["csv"]), f"missing output in {out}"
    assert m["finite"] and m["min_det_F"] > 0.0, m
    assert m["t_end"] >= 2.0 - 1e-9 or m["t_stop"] == m["t_end"], m
    assert m["n_particles_final"] == m["n_particles"] == 450, m
    assert abs(m["mass_final"] - m["mass_initial"]) <= 1e-12 * m["mass_initial"], m
    assert m["runout"] > 1.0 and m["runout_left"] > 1.0 and m["runout_right"] > 1.0, m
    assert m["height"] < 8.0, m
    assert m["max_plastic_strain"] > 0.1, m
    v = m["mean_speed"]["v"]
    assert v[0] == 0.0 and m["peak_mean_speed"] > 0.5 and v[-1] < m["peak_mean_speed"], m


def test_slope_failure_demo(shared_module_tmp_path):
    out = os.path.join(shared_module_tmp_path, "slope")
    m = load_demo("slope_failure").main(["--quick", "--out", out])
    assert exist_on_rank0(m["png"]), f"missing output in {out}"
    base = m["unreduced"]
    assert base["factor"] == 1.0 and abs(base["phi"] - 18.0) < 1e-12 and base["c"] == 5.0e3
    assert base["failed"], base
    assert m["bracket_valid"], m
    lo, hi = m["bracket"]
    assert 0.0 < lo < hi <= 1.0 and abs(hi - lo - 0.25) < 1e-12, m
    assert abs(m["bishop_factor"] / 0.598 - 1.0) < 5e-3, m["bishop_factor"]
    assert lo < m["bishop_factor"] <= hi, m          # measured (0.5, 0.75]
    by_f = {r["factor"]: r for r in m["runs"]}
    assert not by_f[lo]["failed"] and by_f[hi]["failed"], m["runs"]
    stable = [r["crest_u_hold"] for r in m["runs"] if not r["failed"]]
    failed = [r["crest_u_hold"] for r in m["runs"] if r["failed"]]
    assert max(stable) < m["u_fail"] < min(failed), m["runs"]


def test_strip_footing_demo(shared_module_tmp_path):
    out = os.path.join(shared_module_tmp_path, "footing")
    m = load_demo("strip_footing").main(["--quick", "--out", out])
    assert exist_on_rank0(m["png"]), f"missing output in {out}"
    runs = m["runs"]
    assert set(runs) == {"fixed", "viscous"}
    assert abs(m["c_p"] - 68.2) < 0.1 and abs(m["prandtl"] - 51.4e3) < 0.1e3
    for r in runs.values():
        assert r["sigma_v_error"] < 0.02, r
        assert r["static_settlement_error"] < 0.01, r
        assert 0.0 < r["settlement"][0] < 0.1, r
        assert 0.0 < r["v_first"] < m["v_estimate"], r
    assert runs["fixed"]["sigma_bottom"] > runs["viscous"]["sigma_bottom"], runs


def test_bench_plasticity_tiny(shared_module_tmp_path):
    from fenicsmpm.bench import plasticity
    out = os.path.join(shared_module_tmp_path, "bench")
    doc = plasticity.run(quick=True, out=out, t_end=0.05, verbose=False)
    assert exist_on_rank0(os.path.join(out, "plasticity.json"), os.path.join(out, "plasticity.png"))
    if comm.rank == 0:
        with open(os.path.join(out, "plasticity.json")) as f:
            data = json.load(f)
        assert data["case"] == "plasticity" and data["quick"] is True
        assert set(data) >= {"case", "quick", "machine", "runs", "errors"}
        names = [r["name"] for r in data["runs"]]
        assert names == ["collapse-explicit", "collapse-implicit", "slope-explicit",
                         "slope-implicit"]
        for r in data["runs"]:
            assert set(r["config"]) >= {"integrator", "scheme", "shape", "h", "dt", "ppc",
                                        "cell_type"}
            assert r["n_particles"] > 0 and r["steps"] >= 1 and r["wall_s"] > 0
            mt = r["metrics"]
            assert mt["finite"] == 1 and mt["completed"] == 1, r
            assert mt["runout"] is not None
            if r["config"]["integrator"] == "Newmark":
                assert mt["newton_mean"] >= 1 and mt["newton_max"] >= 1, r
            else:
                assert mt["newton_mean"] == 0, r
    assert len(doc["runs"]) == 4
