"""Site response (BENCHMARKS.md P1; seed 003 §3): the soil-column model, post-processing
(Fourier amplitude spectra, transfer functions, Arias intensity, peak picking, vertical
noise) and matplotlib plots. Shared by tests/test_site_response.py,
demos/site_response.py and the `site-response` benchmark case.

P1 column (`soil_column`): H = 10 m, linear elastic E = 1e4 kPa, nu = 0.33, unit weight
18.5 kN/m^3 (rho = 18.5e3 / 9.81 = 1885.8 kg/m^3), so V_s = sqrt(G / rho) = 44.65 m/s,
natural frequencies f_n = (2n+1) V_s / (4H) = 1.116, 3.349, 5.581 Hz. Plane strain,
structured quadrilaterals of size h, `width` wide (default one cell), 2x2 particles per
cell, periodic sides (Simulation.set_periodic, on_leave="periodic").
Bases:
  "rigid"      fm.rigid_base: base nodes fixed, relative frame body force -m a_g(t);
               absolute top motion = relative + input (boundaries.base_motion);
  "compliant"  fm.compliant_base: dashpots of an elastic rock with impedance ratio
               alpha_z = rho_s V_s / (rho_r V_r) (rock density rho_s, V_r = V_s / alpha_z,
               nu_r = nu) and the incident-wave traction; the outcrop motion is 2 v_in.
Input (`gabor`): the Gabor wavelet a(t) = A exp(-(2 pi f0 (t - t_s) / gamma)^2)
cos(2 pi f0 (t - t_s) + phase) at the column's f0 (seed 003 eq 17, whose parameters are
not printed): A = 0.1 m/s^2, gamma = 0.5 (broadband enough to excite f_1 and f_2),
t_s = 1 s, phase = pi/2, baseline-corrected (order 1).
Gravity (optional, `gravity=True`): g = 9.81 m/s^2 switched on at t = 0 on a stress-free
column (no K0 initialisation): the column settles dynamically, which excites the vertical
(P-wave) modes of every wavelength the grid carries; their acceleration at the top is the
"vertical acceleration noise" that the explicit generalized-alpha scheme damps
(`noise_rms`).

Histories (`column_histories`, collective): t, top absolute horizontal acceleration /
velocity / displacement (accelerations by central differences of the probe velocity, the
same for every integrator), vertical acceleration at the top, and the base (input, rigid)
or outcrop (2 v_in, compliant) motion."""
import math

import numpy as np
from mpi4py import MPI

from ..boundaries.base_motion import InputMotion, compliant_base, rigid_base
from ..grid import Grid
from ..materials import LinearElastic
from ..particles import Particles
from ..simulation import Simulation

H, E, NU, GAMMA_UNIT = 10.0, 1.0e7, 0.33, 18.5e3
RHO = GAMMA_UNIT / 9.81
G_MOD = E / (2.0 * (1.0 + NU))
VS = math.sqrt(G_MOD / RHO)


def natural_frequencies(n=3, vs=VS, height=H):
    """f_k = (2k+1) V_s / (4H), k = 0..n-1."""
    return np.array([(2 * k + 1) * vs / (4.0 * height) for k in range(n)])


def rigid_transfer(f, vs=VS, height=H, damping=0.0):
    """|H(f)| = 1 / |cos(2 pi f H / V_s*)| (V_s* = V_s sqrt(1 + 2 i xi) with damping xi)."""
    k = 2 * np.pi * np.asarray(f) * height / (vs * np.sqrt(1 + 2j * damping))
    return 1.0 / np.maximum(np.abs(np.cos(k)), 1e-12)


def elastic_bedrock_transfer(f, alpha_z, vs=VS, height=H):
    """Top over outcrop: 1 / sqrt(cos^2 kH + (alpha_z sin kH)^2), k = 2 pi f / V_s."""
    kH = 2 * np.pi * np.asarray(f) * height / vs
    return 1.0 / np.sqrt(np.cos(kH) ** 2 + (alpha_z * np.sin(kH)) ** 2)


def gabor(f0=None, amplitude=0.1, gamma=0.5, t_s=1.0, phase=math.pi / 2):
    """The Gabor wavelet a(t) (module docstring) as a callable."""
    f0 = natural_frequencies(1)[0] if f0 is None else f0

    def a(t):
        s = 2 * np.pi * f0 * (t - t_s)
        return amplitude * np.exp(-(s / gamma) ** 2) * np.cos(s + phase)
    return a


# ---------------------------------------------------------------------------- spectra
def fourier_amplitude(t, x, n_fft=None):
    """One-sided Fourier amplitude spectrum |X(f)| = dt |FFT(x)| of a uniformly sampled
    record, zero-padded to n_fft points (default: the next power of two above 8 len(x)).
    Returns (f, |X|)."""
    t, x = np.asarray(t), np.asarray(x)
    dt = float(np.mean(np.diff(t)))
    n = n_fft or 1 << int(math.ceil(math.log2(8 * len(x))))
    return np.fft.rfftfreq(n, dt), dt * np.abs(np.fft.rfft(x, n))


def transfer_function(t, top, base, n_fft=None, floor=1e-3):
    """|FFT(top)| / |FFT(base)| (f, ratio); NaN where the base amplitude is below `floor`
    times its peak (no input there)."""
    f, A = fourier_amplitude(t, top, n_fft)
    _, B = fourier_amplitude(t, base, n_fft)
    ratio = np.full_like(A, np.nan)
    ok = B > floor * B.max()
    ratio[ok] = A[ok] / B[ok]
    return f, ratio


def arias_intensity(t, a, g=9.81):
    """Arias intensity I_a(t) = pi / (2 g) int_0^t a^2 dt (m/s), cumulative (trapezium)."""
    t, a = np.asarray(t), np.asarray(a)
    out = np.zeros_like(a, dtype=float)
    out[1:] = np.cumsum(0.5 * (a[1:] ** 2 + a[:-1] ** 2) * np.diff(t))
    return np.pi / (2 * g) * out


def peak_frequencies(f, ratio, guesses, window=0.25):
    """The frequency of the largest `ratio` within guess * (1 -/+ window) of each guess,
    refined by a parabola through the top three samples (of log ratio)."""
    out = []
    for g in guesses:
        sel = np.flatnonzero((f >= g * (1 - window)) & (f <= g * (1 + window)) & np.isfinite(ratio))
        k = sel[int(np.argmax(ratio[sel]))]
        fk = f[k]
        if 0 < k < len(f) - 1 and np.all(np.isfinite(ratio[k - 1:k + 2])):
            y0, y1, y2 = np.log(ratio[k - 1:k + 2])
            den = y0 - 2 * y1 + y2
            if den < 0:
                fk = f[k] + 0.5 * (y0 - y2) / den * (f[k + 1] - f[k])
        out.append(float(fk))
    return np.array(out)


def differentiate(t, y):
    """Central differences (one-sided at the ends)."""
    return np.gradient(np.asarray(y), np.asarray(t))


def noise_rms(t, a, t_start=0.0):
    """RMS of a (vertical) acceleration record after t_start (its mean removed)."""
    t, a = np.asarray(t), np.asarray(a)
    sel = t >= t_start
    return float(np.sqrt(np.mean((a[sel] - a[sel].mean()) ** 2)))


# ---------------------------------------------------------------------------- model
def soil_column(integrator, h=0.25, width=None, per_cell=2, base="rigid", motion=None,
                alpha_z=0.5, gravity=False, dt=None, cfl=0.5, t_end=10.0, comm=MPI.COMM_WORLD,
                partitioner=None):
    """The P1 column (module docstring). Returns (sim, info): info holds the probes
    ("top", "base"), the InputMotion ("motion": the base acceleration for "rigid", the
    incident velocity for "compliant"), V_s, f_n, H, h and the base object.

    motion: an InputMotion or a callable acceleration a(t) (default `gabor()`), sampled on
    [0, t_end] at 1 ms; for the compliant base the incident velocity is the integral of
    a / 2, so that the outcrop motion 2 v_in has the acceleration a.
    dt: None -> "auto" (explicit, cfl * the integrator's critical step) or the explicit
    critical step h / c_p (implicit runs: Courant 1)."""
    from dolfinx import mesh as dmesh
    width = h if width is None else width
    ny, nx = int(round(H / h)), int(round(width / h))
    extra = {} if partitioner is None else {"partitioner": partitioner}
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [width, H]], [nx, ny],
                                 dmesh.CellType.quadrilateral, **extra)
    grid = Grid(msh)
    soil = LinearElastic(E=E, nu=NU, density=RHO)
    pts = Particles.fill(grid, soil, per_cell=per_cell)
    if dt is None:
        dt = "auto" if integrator.explicit else h / soil.p_wave_speed
    if gravity not in (None, False, "sudden", "k0"):
        raise ValueError(f"soil_column: 'gravity' must be None, 'sudden' or 'k0', got {gravity!r}")
    if gravity == "k0":
        from ..materials.initial_stress import k0_stress
        k0_stress(pts, K0=0.5)
    sim = Simulation(grid, pts, integrator, dt=dt, cfl=cfl, on_leave="periodic",
                     gravity=(0.0, -9.81) if gravity else None)
    sim.set_periodic(0)
    if motion is None:
        motion = gabor()
    if not isinstance(motion, InputMotion):
        motion = InputMotion.from_callable(motion, t_end, 1e-3)
    tol = 1e-8 * H

    def base_where(x):
        return np.abs(x[:, 1]) < tol

    if base == "rigid":
        bc = rigid_base(sim, base_where, motion, component=0)
        inp = motion
    elif base == "compliant":
        inp = InputMotion(motion.t, 0.5 * motion.a, baseline=1)    # v_in: half the outcrop
        rock_vs = VS / alpha_z
        nu_fac = soil.p_wave_speed / soil.s_wave_speed
        bc = compliant_base(sim, base_where, inp, density=RHO, s_wave_speed=rock_vs,
                            p_wave_speed=rock_vs * nu_fac, component=0)
    else:
        raise ValueError(f"soil_column: 'base' must be 'rigid' or 'compliant', got {base!r}")
    x_mid = 0.5 * width
    probes = dict(top=sim.probe([x_mid, H], ["velocity", "displacement"]),
                  base=sim.probe([x_mid, 0.0], ["velocity", "displacement"]))
    info = dict(probes=probes, motion=motion, incident=inp, base=base, bc=bc, V_s=VS,
                f_n=natural_frequencies(3), H=H, h=h, width=width, dt=sim.dt, alpha_z=alpha_z,
                material=soil)
    return sim, info


def column_histories(sim, info):
    """Time histories of a finished soil_column run (collective; module docstring).
    Keys: t, a_top, v_top, u_top (absolute, horizontal), ay_top (vertical acceleration),
    a_in (rigid: the base input acceleration; compliant: the outcrop acceleration
    2 dv_in/dt), and for the compliant base v_base (the base particle's velocity)."""
    d = info["probes"]["top"].data()
    t = d["t"]
    v_rel, u_rel = d["velocity_x"], d["displacement_x"]
    out = dict(t=t, ay_top=differentiate(t, d["velocity_y"]))
    m = info["motion"]
    if info["base"] == "rigid":
        out.update(v_top=v_rel + m.velocity(t), u_top=u_rel + m.displacement(t),
                   a_in=m.acceleration(t))
    else:
        inc = info["incident"]
        out.update(v_top=v_rel, u_top=u_rel, a_in=2.0 * inc.acceleration(t))
        out["v_base"] = info["probes"]["base"].data()["velocity_x"]
    out["a_top"] = differentiate(t, out["v_top"])
    return out


def transfer_peaks(h, n=3, window=0.25):
    """Peak frequencies of |FFT(a_top)| / |FFT(a_in)| near the first n f_k, and their
    relative errors against (2k+1) V_s / (4H). Returns (peaks, errors, (f, ratio))."""
    f, ratio = transfer_function(h["t"], h["a_top"], h["a_in"])
    fn = natural_frequencies(n)
    pk = peak_frequencies(f, ratio, fn, window)
    return pk, (pk - fn) / fn, (f, ratio)


def amplification_at(h, f0, band=0.0):
    """|FFT(a_top)| / |FFT(a_in)| at f0 (linear interpolation)."""
    f, ratio = transfer_function(h["t"], h["a_top"], h["a_in"])
    return float(np.interp(f0, f, ratio))


# ---------------------------------------------------------------------------- plots
def plot_histories(h, path, title="", labels=None):
    """Top acceleration, velocity, displacement and vertical acceleration against time (one
    or several runs: `h` a dict or a list of dicts with `labels`)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    runs = h if isinstance(h, list) else [h]
    labels = labels or [None] * len(runs)
    fig, ax = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    for r, lab in zip(runs, labels):
        for a, key in zip(ax, ("a_top", "v_top", "u_top", "ay_top")):
            a.plot(r["t"], r[key], lw=0.8, label=lab)
    ax[0].plot(runs[0]["t"], runs[0]["a_in"], "k:", lw=0.8, label="input")
    for a, yl in zip(ax, ("a_x top [m/s²]", "v_x top [m/s]", "u_x top [m]", "a_y top [m/s²]")):
        a.set_ylabel(yl)
        a.grid(alpha=0.3)
    ax[-1].set_xlabel("t [s]")
    ax[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_transfer(curves, path, title="", fmax=8.0, alpha_z=None):
    """Transfer functions [(label, f, ratio), ...] over the analytical one (rigid base, or
    the elastic bedrock with alpha_z)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 5))
    ff = np.linspace(0.01, fmax, 4000)
    exact = rigid_transfer(ff) if alpha_z is None else elastic_bedrock_transfer(ff, alpha_z)
    ax.semilogy(ff, exact, "k-", lw=1.5, label="analytical" + ("" if alpha_z is None else
                                                                 f" (alpha_z = {alpha_z})"))
    for lab, f, r in curves:
        sel = f <= fmax
        ax.semilogy(f[sel], r[sel], lw=0.9, label=lab)
    for fk in natural_frequencies(3):
        ax.axvline(fk, color="gray", ls=":", lw=0.8)
    ax.set_xlabel("f [Hz]")
    ax.set_ylabel("|top / base|")
    ax.set_ylim(0.05, 1e3)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
