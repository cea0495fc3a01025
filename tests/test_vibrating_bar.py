"""V1 (BENCHMARKS.md): axially vibrating bar, fixed at x = 0, free at x = L = 1.

Exact: v(x, t) = v0 cos(w t) sin(pi x / 2L), w = (pi / 2L) sqrt(E / rho), period T = 2 pi / w,
total energy E0 = rho v0^2 L h / 4 (per unit thickness, bar height h).

Explicit (MUSL, USF) at cfl = 0.1 over 5 periods: period within 1 % (from the zero crossings
of the velocity of the particle nearest the free end), max |E - E0| / E0 < 1 %, net drift
(mean over the last period vs the first) < 0.2 %, RMS velocity error vs exact < 3 % of v0.
Implicit Newmark at dt = 5 h / c (5x the explicit limit): energy never above 1.01 E0 and
period within 3 %.
"""
import numpy as np
import pytest

import fenicsmpm as fm
from fenicsmpm.problems.elastic import vibrating_bar

V0 = 0.1
N_PERIODS = 5
PROBE_POINT = (0.9875, 0.0125)     # the particle nearest the free end (20 cells, 2 per cell)


def run_bar(integrator, **kw):
    sim, exact = vibrating_bar(integrator, v0=V0, **kw)
    probe = sim.probe(PROBE_POINT, fields=("velocity", "position"))
    e = sim.energy()
    E = [e["kinetic"] + e["strain"]]
    t = [0.0]
    steps = int(np.ceil(N_PERIODS * exact["period"] / sim.dt))
    for _ in range(steps):
        sim.step()
        e = sim.energy()
        E.append(e["kinetic"] + e["strain"])
        t.append(sim.t)
    return dict(sim=sim, exact=exact, probe=probe.data(), E=np.array(E), t=np.array(t))


def measured_period(t, v):
    """Period from a straight-line fit of the (linearly interpolated) zero crossings of v:
    consecutive crossings are half a period apart."""
    s = np.sign(v)
    i = np.flatnonzero(s[:-1] * s[1:] < 0)
    tz = t[i] - v[i] * (t[i + 1] - t[i]) / (v[i + 1] - v[i])
    assert len(tz) >= 2 * N_PERIODS - 1, f"only {len(tz)} zero crossings in {N_PERIODS} periods"
    slope = np.polyfit(np.arange(len(tz)), tz, 1)[0]
    return 2.0 * slope


@pytest.fixture(scope="module", params=["MUSL", "USF"])
def explicit_run(request):
    return request.param, run_bar(fm.Explicit(request.param), cfl=0.1)


@pytest.fixture(scope="module")
def newmark_run():
    return run_bar(fm.Newmark())


def test_initial_energy(explicit_run):
    """The particle quadrature of rho v^2 / 2 over the bar is exact for this profile."""
    _, r = explicit_run
    E0, exact = r["E"][0], r["exact"]["energy"]
    assert abs(E0 - exact) < 1e-12 * exact, f"E0 = {E0!r}, exact rho v0^2 L h / 4 = {exact!r}"


def test_explicit_period(explicit_run):
    scheme, r = explicit_run
    d = r["probe"]
    T = measured_period(d["t"], d["velocity_x"])
    err = abs(T / r["exact"]["period"] - 1.0)
    assert err < 0.01, (f"{scheme}: period {T:.6g} vs exact {r['exact']['period']:.6g}: "
                        f"error {100 * err:.3f} % (tol 1 %)")


def test_explicit_energy(explicit_run):
    scheme, r = explicit_run
    E, t, T = r["E"], r["t"], r["exact"]["period"]
    E0 = E[0]
    max_dev = np.max(np.abs(E - E0)) / E0
    first = np.mean(E[t <= T])
    last = np.mean(E[t >= t[-1] - T])
    drift = abs(last - first) / E0
    assert max_dev < 0.01, f"{scheme}: max |E - E0| / E0 = {100 * max_dev:.3f} % (tol 1 %)"
    assert drift < 0.002, (f"{scheme}: energy drift (mean over last period vs first) "
                           f"{100 * drift:.4f} % (tol 0.2 %)")


def test_explicit_velocity_history(explicit_run):
    """RMS of v_probe(t) - v_exact(X, t) over 5 periods, X the particle's initial position."""
    scheme, r = explicit_run
    d = r["probe"]
    X = d["position_x"][0]
    v_exact = r["exact"]["velocity"](X, d["t"])
    rms = np.sqrt(np.mean((d["velocity_x"] - v_exact) ** 2)) / V0
    assert abs(X - PROBE_POINT[0]) < 1e-12, f"probe particle at X = {X}, expected {PROBE_POINT[0]}"
    assert rms < 0.03, f"{scheme}: RMS velocity error {100 * rms:.3f} % of v0 (tol 3 %)"


def test_newmark_large_step(newmark_run):
    r = newmark_run
    sim, exact = r["sim"], r["exact"]
    assert abs(sim.dt - 5.0 * exact["h"] / exact["wave_speed"]) < 1e-15, (
        f"dt = {sim.dt}, expected 5 h / c = {5.0 * exact['h'] / exact['wave_speed']}")
    assert sim.dt > 4.99 * sim.dt_critical
    E, E0 = r["E"], r["E"][0]
    d = r["probe"]
    T = measured_period(d["t"], d["velocity_x"])
    err = abs(T / exact["period"] - 1.0)
    assert np.max(E) <= 1.01 * E0, f"Newmark energy grew to {np.max(E) / E0:.5f} E0 (tol 1.01 E0)"
    assert np.min(E) >= 0.95 * E0, f"Newmark energy fell to {np.min(E) / E0:.5f} E0 (tol 0.95 E0)"
    assert err < 0.03, (f"Newmark: period {T:.6g} vs exact {exact['period']:.6g}: "
                        f"error {100 * err:.3f} % (tol 3 %)")
