"""Benchmark case `site-response`: P1 (BENCHMARKS.md section P; fenicsmpm.problems.soil_column).

The 10 m column (E = 1e4 kPa, nu = 0.33, 18.5 kN/m^3: V_s = 44.65 m/s), one cell wide with
periodic sides, 2x2 particles per cell, on a rigid base shaken by the Gabor wavelet at f0
(soil_column.gabor), gravity switched on at t = 0 on the stress-free column (the source of
vertical noise). Schemes: symplectic Euler (fm.Explicit(), MUSL), explicit generalized-alpha
rho_b = 0.5 and 0.8 (dt = "auto", cfl 0.5), implicit Newmark (beta = 1/4, gamma = 1/2) and
implicit generalized-alpha rho_inf = 0.8 at dt = h / c_p (Courant 1). Cell sizes 0.5 and
0.25 m (the full run adds 0.125 m for the explicit schemes); records of 20 s (--quick: 12 s,
cell sizes 0.5 and 0.25 m, no implicit generalized-alpha).

Metrics per run: f0_rel_error, f1_rel_error, f2_rel_error (peaks of
|FFT(a_top)| / |FFT(a_base)| against (2n+1) V_s / (4H)), amplification_f0 (the ratio at
f0), vertical_rms (RMS vertical acceleration at the top over the whole record),
vertical_rms_late (over the second half), arias_top, s_per_step. wall_s: the time-stepping
loop (after a 2-step warm-up run of each scheme), slowest rank.
Writes site-response.json and site-response.png (transfer functions over the analytical
1 / |cos(2 pi f H / V_s)|, one panel per cell size)."""
import os
import time

import numpy as np

from . import common
from ..problems import soil_column as sr

CASE = "site-response"


def _schemes(quick, h):
    import fenicsmpm as fm
    out = [("euler", "Explicit", lambda: fm.Explicit(), {}),
           ("ga-0.5", "ExplicitGeneralizedAlpha", lambda: fm.ExplicitGeneralizedAlpha(0.5), {"rho": 0.5}),
           ("ga-0.8", "ExplicitGeneralizedAlpha", lambda: fm.ExplicitGeneralizedAlpha(0.8), {"rho": 0.8})]
    if h >= 0.25:
        out.append(("newmark", "Newmark", lambda: fm.Newmark(), {}))
        if not quick:
            out.append(("implicit-ga-0.8", "ImplicitGeneralizedAlpha",
                        lambda: fm.ImplicitGeneralizedAlpha(0.8), {"rho": 0.8}))
    return out


def run_one(name, cls, make, extra, h, t_end, comm):
    warm, _ = sr.soil_column(make(), h=h, gravity="sudden", t_end=t_end, comm=comm)
    warm.run(steps=2, progress=False)
    sim, info = sr.soil_column(make(), h=h, gravity="sudden", t_end=t_end, comm=comm)
    t0 = time.perf_counter()
    sim.run(t_end=t_end, progress=False)
    wall = common.gmax(comm, time.perf_counter() - t0)
    hist = sr.column_histories(sim, info)
    peaks, err, (f, ratio) = sr.transfer_peaks(hist)
    t = hist["t"]
    metrics = dict(f0_rel_error=err[0], f1_rel_error=err[1], f2_rel_error=err[2],
                   f0=peaks[0], f1=peaks[1], f2=peaks[2],
                   amplification_f0=sr.amplification_at(hist, info["f_n"][0]),
                   vertical_rms=sr.noise_rms(t, hist["ay_top"]),
                   vertical_rms_late=sr.noise_rms(t, hist["ay_top"], 0.5 * t_end),
                   arias_top=float(sr.arias_intensity(t, hist["a_top"])[-1]),
                   s_per_step=wall / max(sim.step_count, 1))
    config = dict(integrator=cls, scheme=getattr(sim.integrator, "scheme", None), shape="mpm",
                  h=h, dt=sim.dt, ppc=4, cell_type="quadrilateral",
                  t_end=t_end, base="rigid", gravity="sudden", **extra)
    rec = common.make_record(f"{name}-h{h:g}", config, sim.particles.n_global(),
                             sim.grid.global_count(np.ones(sim.grid.n_owned_cells, bool)),
                             sim.step_count, wall, metrics)
    sel = f <= 8.0
    return rec, (name, f[sel], ratio[sel])


def plot(doc, curves, path, comm):
    sizes = sorted({h for h, _ in curves}, reverse=True)
    fig, axes = common.new_figure(ncols=len(sizes), size=(5.0, 4.2))
    ff = np.linspace(0.01, 8.0, 4000)
    for ax, h in zip(axes[0], sizes):
        ax.semilogy(ff, sr.rigid_transfer(ff), "k-", lw=1.4, label="analytical")
        for hh, (name, f, r) in curves:
            if hh == h:
                ax.semilogy(f, r, lw=0.8, label=name)
        for fk in sr.natural_frequencies(3):
            ax.axvline(fk, color="gray", ls=":", lw=0.7)
        ax.set_ylim(0.05, 1e3)
        ax.set_xlabel("f [Hz]")
        ax.set_ylabel("|a_top / a_base|")
        ax.set_title(f"h = {h} m", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    return common.save_figure(fig, path, comm, title=common.machine_title(doc["machine"]))


def run(quick=False, out="bench-results", comm=None, verbose=True, t_end=None):
    """Run the case, write out/site-response.json and out/site-response.png, print the
    table. t_end overrides the record length (a tiny run for tests)."""
    comm = common.world(comm)
    sizes = (0.5, 0.25) if quick else (0.5, 0.25, 0.125)
    t_end = t_end or (12.0 if quick else 20.0)
    runs, curves = [], []
    for h in sizes:
        for name, cls, make, extra in _schemes(quick, h):
            rec, curve = run_one(name, cls, make, extra, h, t_end, comm)
            runs.append(rec)
            curves.append((h, curve))
            if verbose:
                m = rec["metrics"]
                common.say(comm, f"  {rec['name']:22s} f-errors {m['f0_rel_error']:+.4f} "
                                 f"{m['f1_rel_error']:+.4f} {m['f2_rel_error']:+.4f}  "
                                 f"RMS a_y {m['vertical_rms']:.3g}  wall {rec['wall_s']:.1f} s")
    fn = sr.natural_frequencies(3)
    doc = common.result(CASE, runs, comm, quick=quick,
                        targets=dict(f_n=fn.tolist(), V_s=sr.VS, H=sr.H))
    json_path = common.write_result(doc, out, comm)
    png = plot(doc, curves, os.path.join(out, f"{CASE}.png"), comm)
    if verbose:
        common.print_table(runs, [("run", "name"), ("dt [s]", lambda r: r["config"]["dt"]),
                                  ("steps", "steps"), ("f0 err", lambda r: r["metrics"]["f0_rel_error"]),
                                  ("f1 err", lambda r: r["metrics"]["f1_rel_error"]),
                                  ("f2 err", lambda r: r["metrics"]["f2_rel_error"]),
                                  ("|H(f0)|", lambda r: r["metrics"]["amplification_f0"]),
                                  ("RMS a_y", lambda r: r["metrics"]["vertical_rms"]),
                                  ("RMS a_y late", lambda r: r["metrics"]["vertical_rms_late"]),
                                  ("wall [s]", "wall_s")],
                           comm=comm, title=f"site-response ({'quick' if quick else 'full'}), "
                                            f"{comm.size} rank(s); f_n = {np.round(fn, 3)} Hz")
        common.say(comm, f"wrote {json_path}\n      {png}")
    return doc
