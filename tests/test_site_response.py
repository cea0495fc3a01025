"""Site response (BENCHMARKS.md P1; fenicsmpm.problems.soil_column, boundaries.base_motion).
Serial and `mpirun -n 2`.

P1 column: H = 10 m, E = 1e4 kPa, nu = 0.33, unit weight 18.5 kN/m^3 (V_s = 44.65 m/s,
f_n = (2n+1) V_s / (4H) = 1.116, 3.349, 5.581 Hz), one cell wide with periodic sides, cell
size 0.25 m (P1), 2x2 particles per cell, shaken by the Gabor wavelet of
soil_column.gabor (A = 0.1 m/s^2 at f0, gamma = 0.5, baseline-corrected), 20 s records
(frequency resolution of the zero-padded spectra 0.006 Hz).
Symplectic Euler is fm.Explicit() (MUSL, FLIP), explicit generalized-alpha
fm.ExplicitGeneralizedAlpha(0.5); both at dt = "auto" (cfl 0.5)."""
import math

import numpy as np
import pytest
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.problems import soil_column as sr

comm = MPI.COMM_WORLD
T_END, DX = 20.0, 0.25


@pytest.fixture(scope="module")
def rigid_runs():
    """Rigid base, with gravity switched on at t = 0 on the stress-free column (the source
    of vertical noise, site_response docstring)."""
    out = {}
    for name, integ in (("euler", fm.Explicit()), ("ga", fm.ExplicitGeneralizedAlpha(0.5))):
        sim, info = sr.soil_column(integ, h=DX, gravity="sudden", t_end=T_END)
        sim.run(t_end=T_END, progress=False)
        out[name] = sr.column_histories(sim, info)
    return out


@pytest.mark.parametrize("name", ["euler", "ga"])
@pytest.mark.heavy
def test_rigid_base_transfer_peaks(rigid_runs, name):
    """The first three peaks of |FFT(a_top)| / |FFT(a_base)| lie at (2n+1) V_s / (4H)
    within 3 %."""
    peaks, err, _ = sr.transfer_peaks(rigid_runs[name])
    assert np.all(np.abs(err) < 0.03), (peaks, err)


def test_generalized_alpha_damps_vertical_noise(rigid_runs):
    """Vertical acceleration at the top (RMS over the whole 20 s record): explicit
    generalized-alpha (rho_b = 0.5) at least 3x lower than symplectic Euler."""
    rms = {k: sr.noise_rms(h["t"], h["ay_top"]) for k, h in rigid_runs.items()}
    assert rms["euler"] > 3.0 * rms["ga"], rms


def test_compliant_base_elastic_bedrock():
    """Compliant base, alpha_z = 0.5: top over outcrop (2 v_in) at f0 within 10 % of
    1 / alpha_z = 2 (the elastic-bedrock transfer function at kH = pi / 2); cell size 0.5 m, 10 s."""
    alpha_z = 0.5
    sim, info = sr.soil_column(fm.Explicit(), h=0.5, base="compliant", alpha_z=alpha_z, t_end=10.0)
    sim.run(t_end=10.0, progress=False)
    h = sr.column_histories(sim, info)
    A = sr.amplification_at(h, info["f_n"][0])
    assert abs(A * alpha_z - 1.0) < 0.10, A


def test_input_motion_baseline_and_arias(tmp_path):
    """Baseline correction (order 1): a constant acceleration offset is removed to
    round-off; on sin(2 pi t) + 0.05 it cuts the final displacement from 1.42 m to 0.20 m
    (the rest is the sine's own mean velocity 1 / (2 pi)); a two-column file gives the same
    record; a velocity record is differentiated back; Arias intensity of sin(2 pi t) over
    5 s is pi 5 / (4 g); the Fourier amplitude of a 1.5 Hz sine peaks at 1.5 Hz."""
    t = np.linspace(0.0, 5.0, 5001)
    c = fm.InputMotion(t, np.full_like(t, 0.05))
    assert np.abs(c.a).max() < 1e-12 and np.abs(c.u).max() < 1e-12
    a = np.sin(2 * np.pi * t) + 0.05
    m = fm.InputMotion(t, a)
    raw = fm.InputMotion(t, a, baseline=0)
    assert abs(m.u[-1]) < 0.2 * abs(raw.u[-1]), (m.u[-1], raw.u[-1])
    path = tmp_path / "motion.txt"                     # tmp_path is per rank
    np.savetxt(path, np.column_stack([t, a]), header="t a")
    m2 = fm.InputMotion.from_file(path)
    assert np.allclose(m2.a, m.a) and np.allclose(m2.u, m.u)
    mv = fm.InputMotion(t, m.v, kind="velocity", baseline=0)
    assert np.allclose(mv.v, m.v, atol=1e-4 * np.abs(m.v).max())
    ia = sr.arias_intensity(t, np.sin(2 * np.pi * t))
    assert abs(ia[-1] / (math.pi * 5.0 / (4 * 9.81)) - 1.0) < 1e-4
    f, A = sr.fourier_amplitude(t, np.sin(2 * np.pi * 1.5 * t))
    assert abs(f[np.argmax(A)] - 1.5) < 0.01
