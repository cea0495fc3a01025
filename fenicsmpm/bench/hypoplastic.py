"""Benchmark case `hypoplastic`: element tests of fm.Hypoplastic (seed 004 Table 3.1 in SI
units) through the mesh-free driver fenicsmpm.materials.element_test: drained triaxial
compression of a dense and a loose sample (critical-state errors), undrained triaxial, the
seed's biaxial test (Figure 3.3: plane strain, sigma0 = -100 kPa, dense e0 = 0.65), isotropic
compression, oedometric loading-unloading, cyclic simple shear and the stiffness after 180 and
90 degree strain reversals (m_R, m_T).  Writes out/hypoplastic.json and out/hypoplastic.png."""
import os
import time

import numpy as np

from . import common
from ..materials.element_test import (Element, biaxial, cyclic_shear, isotropic, oedometer,
                                      triaxial)
from ..materials.hypoplastic import Hypoplastic

CASE = "hypoplastic"
TABLE_3_1 = dict(phi_c=30.0, h_s=5.8e9, n=0.28, e_d0=0.53, e_c0=0.84, e_i0=1.0, alpha=0.13,
                 beta=1.0, m_R=10.0, m_T=2.0, R=5e-5, beta_r=0.3, chi=1.0, density=2600.0,
                 e_0=0.65, p_t=1600.0)


def _critical(m, h):
    """Relative errors of q/(p + p_t) against M_c and of e against e_c(p) at the path's end."""
    _, ec, _ = m.characteristic_void_ratios(h["p"][-1])
    return (float(h["q"][-1] / (h["p"][-1] + m.p_t) / m.M_c - 1.0),
            float(h["e"][-1] / ec - 1.0))


def _reversal(m):
    """Tangent stiffness after 100 R of oedometric loading, for increments R/1e4 reversed by 180
    degrees (+e_yy) and turned by 90 degrees (e_xx), as multiples of L of eq 3.5 (yy and xx
    components)."""
    el = Element(m, 100e3, e=0.7)
    for _ in range(200):
        el.step(np.diag([0.0, -2.5e-5, 0.0]))
    L, _ = m.tensors(el.sigma, el.state[:, 0])
    h = m.R * 1e-4
    out = {}
    for key, k in (("m_R_measured", 1), ("m_T_measured", 0)):
        E = np.zeros((3, 3))
        E[k, k] = 1.0
        s, _ = el.trial(h * E)
        out[key] = float((s[k, k] - el.sigma[0, k, k]) / h / L[0, k, k, k, k])
    return out


def run(quick=False, out="bench-results", comm=None, verbose=True):
    """Every element test (quick: 4x larger strain increments), JSON, table and PNG; returns
    the result dict (common.result)."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD if comm is None else comm
    say = (lambda *a: common.say(comm, f"[{CASE}]", *a)) if verbose else (lambda *a: None)
    m = Hypoplastic(**TABLE_3_1)
    triaxial(m, 100e3, e0=0.7, axial_strain=-0.01, n=5)       # JIT warm-up
    k = 4 if quick else 1                                     # quick: 4x larger increments
    runs, paths = [], {}

    def record(name, fn, cfg, metrics=None):
        t0 = time.perf_counter()
        h = fn()
        wall = time.perf_counter() - t0
        mets = dict(p_end=float(h["p"][-1]), q_end=float(h["q"][-1]), e_end=float(h["e"][-1]),
                    steps=len(h["p"]) - 1, **(metrics(h) if metrics else {}))
        runs.append(common.make_record(name, dict(integrator="element-test", scheme="RK23",
                                                  shape="none", h=0.0, dt=0.0, ppc=1,
                                                  cell_type="none", **cfg), 1, 0,
                                       len(h["p"]) - 1, wall, mets))
        paths[name] = h
        say(f"{name}: " + ", ".join(f"{a} = {common.format_number(b)}" for a, b in mets.items()))

    def crit(h):
        a, b = _critical(m, h)
        return dict(critical_ratio_error=a, critical_void_error=b,
                    peak_ratio=float(np.max(h["q"] / (h["p"] + m.p_t)) / m.M_c),
                    eps_v_end=float(h["eps_v"][-1]))

    record("triaxial-dense", lambda: triaxial(m, 100e3, e0=0.60, axial_strain=-2.0, n=2000 // k),
           dict(test="drained triaxial", e0=0.60, p0=100e3, axial_strain=-2.0), crit)
    record("triaxial-loose", lambda: triaxial(m, 100e3, e0=0.80, axial_strain=-0.3, n=600 // k),
           dict(test="drained triaxial", e0=0.80, p0=100e3, axial_strain=-0.3), crit)
    record("triaxial-undrained", lambda: triaxial(m, 100e3, e0=0.80, axial_strain=-0.3,
                                                  n=600 // k, drained=False),
           dict(test="undrained triaxial", e0=0.80, p0=100e3, axial_strain=-0.3), crit)
    record("biaxial-seed", lambda: biaxial(m, 100e3, e0=0.65, axial_strain=-0.1, n=1000 // k),
           dict(test="drained biaxial (seed Fig. 3.3)", e0=0.65, sigma0=100e3, axial_strain=-0.1),
           lambda h: dict(q_peak=float(h["q"].max()),
                          eps_a_peak=float(h["eps_a"][np.argmax(h["q"])])))
    ed0, _, ei0 = m.characteristic_void_ratios(10e3)
    for name, e0 in (("isotropic-loose", ei0), ("isotropic-dense", ed0 + 0.01)):
        def iso(e0=e0):
            el = Element(m, 10e3, e=e0, delta=-m.R / np.sqrt(3.0) * np.eye(3))
            while -np.trace(el.sigma[0]) / 3.0 < 50e6:
                el.step(-2e-4 * k / 3.0 * np.eye(3))
            return el.history()

        def dist(h):
            ed, _, ei = m.characteristic_void_ratios(h["p"])
            r = (ei - h["e"]) / (ei - ed)
            return dict(r_start=float(r[0]), r_end=float(r[-1]))
        record(name, iso, dict(test="isotropic compression", e0=float(e0), p0=10e3, p1=50e6), dist)
    record("isotropic-fresh", lambda: isotropic(m, 10e3, 50e6, e0=0.9 * ei0, deps_v=-2e-4 * k),
           dict(test="isotropic compression, delta_0 = 0", e0=float(0.9 * ei0), p0=10e3, p1=50e6))
    record("oedometer", lambda: oedometer(m, 100e3, e0=0.7, strain=-0.02, n=400 // k),
           dict(test="oedometric loading-unloading", e0=0.7, sigma0=100e3, strain=-0.02),
           lambda h: dict(sigma_yy_max=float(-h["sigma"][:, 1, 1].min())))
    record("cyclic-shear", lambda: cyclic_shear(m, 100e3, e0=0.7, gamma=1e-3, cycles=3, n=100 // k),
           dict(test="drained cyclic simple shear", e0=0.7, sigma_v=100e3, gamma=1e-3, cycles=3),
           lambda h: dict(de=float(h["e"][-1] - h["e"][0])))
    t0 = time.perf_counter()
    rev = _reversal(m)
    runs.append(common.make_record("reversal", dict(integrator="element-test", scheme="RK23",
                                                    shape="none", h=0.0, dt=0.0, ppc=1,
                                                    cell_type="none", test="strain reversal"),
                                   1, 0, 200, time.perf_counter() - t0, rev))
    say(f"reversal: m_R measured {rev['m_R_measured']:.5f} (10), m_T {rev['m_T_measured']:.5f} (2)")
    doc = common.result(CASE, runs, comm, quick=quick,
                        notes=["Seed 004 Table 3.1 in Pa (h_s = 5.8e9, p_t = 1600); tension "
                               "positive; p, q of the true stress; critical state in terms of "
                               "q/(p + p_t) (the model sees sigma - p_t I)."])
    common.write_result(doc, out, comm)
    common.print_table([dict(name=r["name"], e=r["metrics"].get("e_end"),
                             p=r["metrics"].get("p_end"), q=r["metrics"].get("q_end"),
                             ce=r["metrics"].get("critical_ratio_error"),
                             cv=r["metrics"].get("critical_void_error"), wall=r["wall_s"])
                        for r in runs],
                       [("test", "name"), ("e end", "e"), ("p end Pa", "p"), ("q end Pa", "q"),
                        ("q/p err", "ce"), ("e/e_c err", "cv"), ("wall s", "wall")], comm=comm)
    _plot(m, paths, rev, doc, out, comm)
    return doc


def _plot(m, paths, rev, doc, out, comm):
    """Stress ratio and volumetric strain of the triaxial tests, the seed's biaxial q(eps_yy),
    isotropic paths with e_d, e_c, e_i (eq 3.15), oedometer, cyclic shear."""
    fig, ax = common.new_figure(3, 2, size=(4.6, 3.6))
    for name, c in (("triaxial-dense", "tab:red"), ("triaxial-loose", "tab:blue")):
        h = paths[name]
        ax[0, 0].semilogx(-h["eps_a"][1:], (h["q"] / (h["p"] + m.p_t))[1:], color=c, label=name)
        ax[1, 0].semilogx(-h["eps_a"][1:], h["eps_v"][1:], color=c, label=name)
    ax[0, 0].axhline(m.M_c, color="k", ls=":", label="M_c")
    ax[1, 0].set_xlabel("axial strain -eps_yy (sum of increments)")
    ax[0, 0].set_ylabel("q / (p + p_t)")
    ax[1, 0].set_ylabel("eps_v (dilation > 0)")
    h = paths["biaxial-seed"]
    ax[0, 1].plot(-100 * h["eps_a"], h["q"] / 1e3, color="tab:green")
    ax[0, 1].set_xlabel("vertical strain [%]")
    ax[0, 1].set_ylabel("deviatoric stress q [kPa]")
    ax[0, 1].set_title("seed biaxial test (Fig. 3.3), sigma0 = -100 kPa, e0 = 0.65", fontsize=8)
    pp = np.logspace(4, np.log10(5e7), 100)
    ed, ec, ei = m.characteristic_void_ratios(pp)
    for arr, lab in ((ed, "e_d"), (ec, "e_c"), (ei, "e_i")):
        ax[1, 1].semilogx(pp, arr, "k:", lw=0.8)
        ax[1, 1].text(pp[-1], arr[-1], lab, fontsize=7)
    for name in ("isotropic-loose", "isotropic-dense", "isotropic-fresh"):
        ax[1, 1].semilogx(paths[name]["p"], paths[name]["e"], label=name)
    ax[1, 1].set_xlabel("p [Pa]")
    ax[1, 1].set_ylabel("e")
    h = paths["oedometer"]
    ax[0, 2].plot(-100 * h["eps_a"], -h["sigma"][:, 1, 1] / 1e3, label="oedometer")
    ax[0, 2].set_xlabel("vertical strain [%]")
    ax[0, 2].set_ylabel("-sigma_yy [kPa]")
    ax[0, 2].set_title(f"reversal: m_R {rev['m_R_measured']:.4f} (10), "
                       f"m_T {rev['m_T_measured']:.4f} (2)", fontsize=8)
    h = paths["cyclic-shear"]
    ax[1, 2].plot(2 * h["eps"][:, 0, 1], h["sigma"][:, 0, 1] / 1e3, lw=0.8)
    ax[1, 2].set_xlabel("gamma_xy")
    ax[1, 2].set_ylabel("tau_xy [kPa]")
    ax[1, 2].set_title("drained cyclic simple shear, sigma_v = 100 kPa", fontsize=8)
    for a in ax.ravel():
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=7)
    common.save_figure(fig, os.path.join(out, f"{CASE}.png"), comm,
                       title=common.machine_title(doc["machine"]))
