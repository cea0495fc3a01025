"""The limit-equilibrium factor of safety of a slope: Bishop's simplified method of slices
over circular slip surfaces (Bishop 1955), the reference for the strength-reduction factor at
which an MPM slope fails (demos/slope_failure.py, BENCHMARKS L4).

For a circle of centre (x_c, y_c) and radius R the sliding mass lies between the circle's
lower arc y_b(x) = y_c - sqrt(R^2 - (x - x_c)^2) and the ground surface; cut into vertical
slices of width b, weight W = gamma b (y_s - y_b) and base angle alpha (sin alpha =
(x - x_c) / R, with x measured in the direction the slope rises), Bishop's moment balance
with the inter-slice shear forces neglected is

    F = sum[(c b + W tan phi) / m_alpha] / sum[W sin alpha],
    m_alpha = cos alpha + sin alpha tan phi / F,

solved by fixed-point iteration. F divides c and tan phi alike, so it is the same factor as
the MPM's strength reduction (fm.MohrCoulomb.reduced(F): tan phi / F, c / F). The minimum
over circles is searched on a grid of centres and radii, then refined around the best three
times; circles that cut below the firm base, leave the domain, or have m_alpha < 0.2 on a
loaded slice (the usual guard against Bishop's exit-slice singularity) are skipped. No pore
pressure, no surcharge, one soil.

Checked against the published Bishop factor of code_aster's SSNP006 slope (Verruijt's
simplified Bishop, 1.534; Plaxis strength reduction 1.54; tests/test_slope_stability.py)."""
import numpy as np

M_ALPHA_MIN = 0.2


def _factors(xc, yc, R, surface, x_lo, x_hi, base, unit_weight, c, tan_phi, slices):
    """Bishop's F for arrays of circles (xc, yc, R, same shape); inf where not admissible."""
    xc, yc, R = (np.asarray(a, dtype=float).ravel() for a in (xc, yc, R))
    lo = np.maximum(xc - R, x_lo)
    hi = np.minimum(xc + R, x_hi)
    s = (np.arange(slices) + 0.5) / slices
    x = lo[:, None] + (hi - lo)[:, None] * s[None, :]          # slice centres
    b = (hi - lo)[:, None] / slices
    dx = np.clip((x - xc[:, None]) / R[:, None], -1.0, 1.0)
    yb = yc[:, None] - R[:, None] * np.sqrt(1.0 - dx * dx)
    h = np.maximum(surface(x) - yb, 0.0)
    loaded = h > 0.0
    W = unit_weight * h * b
    sa, ca = dx, np.sqrt(1.0 - dx * dx)
    drive = np.sum(W * sa, axis=1)
    ok = (hi - lo > 0.0) & (drive > 0.0) & loaded.any(axis=1)
    ok &= ~np.any(loaded & (yb < base - 1e-12), axis=1)
    # the mass must not reach the domain's ends (the slip surface would leave it there)
    ok &= ~(loaded[:, 0] & (xc - R < x_lo)) & ~(loaded[:, -1] & (xc + R > x_hi))
    resist = np.where(loaded, c * b + W * tan_phi, 0.0)
    F = np.ones_like(drive)
    for _ in range(100):
        m = ca + sa * tan_phi / F[:, None]
        ok &= ~np.any(loaded & (m < M_ALPHA_MIN), axis=1)
        F_new = np.sum(resist / np.where(loaded, m, 1.0), axis=1) / np.where(ok, drive, 1.0)
        F_new = np.where(ok, F_new, 1.0)
        if np.max(np.abs(F_new - F)) < 1e-10:
            F = F_new
            break
        F = F_new
    return np.where(ok, F, np.inf)


def bishop(surface, unit_weight, c, phi, x_range, base=0.0, facing=None, slices=200,
           centres=(48, 48), radii=60, refinements=3):
    """Bishop's simplified factor of safety of the slope whose ground surface is y =
    surface(x) (vectorised callable) on x_range = (x_lo, x_hi) above a firm base y = base,
    soil of unit weight [N/m^3], cohesion c [Pa] and friction angle phi [deg]; the minimum
    over circular slip surfaces (module docstring). facing: "left" (the ground rises with x,
    the mass slides towards -x) or "right"; None: from the surface's ends. Returns a dict:
    factor, centre (x_c, y_c), radius, the circle's entry and exit x on the surface."""
    x_lo, x_hi = map(float, x_range)
    if not x_hi > x_lo:
        raise ValueError(f"bishop: 'x_range' must be (x_lo, x_hi) with x_hi > x_lo, got {x_range!r}")
    for name, value in (("unit_weight", unit_weight), ("slices", slices)):
        if not value > 0:
            raise ValueError(f"bishop: '{name}' must be > 0, got {value!r}")
    if not c >= 0.0:
        raise ValueError(f"bishop: 'c' must be >= 0, got {c!r}")
    if not 0.0 <= phi < 90.0:
        raise ValueError(f"bishop: 'phi' must be in [0, 90) degrees, got {phi!r}")
    if facing is None:
        facing = "left" if surface(np.array([x_hi]))[0] >= surface(np.array([x_lo]))[0] else "right"
    if facing not in ("left", "right"):
        raise ValueError(f"bishop: 'facing' must be 'left', 'right' or None, got {facing!r}")
    if facing == "right":                 # mirror: the ground rises with x
        f = surface
        surface = lambda x: f(x_lo + x_hi - x)
    tan_phi = np.tan(np.radians(phi))
    xs = np.linspace(x_lo, x_hi, 401)
    top = float(np.max(surface(xs)))
    span = x_hi - x_lo
    height = top - base

    def search(xc, yc, r_lo, r_hi, n_r=radii):
        XC, YC = np.meshgrid(xc, yc, indexing="ij")
        XC, YC = XC.ravel(), YC.ravel()
        best = (np.inf, None)
        for R in np.linspace(r_lo, r_hi, n_r):
            F = _factors(XC, YC, np.full_like(XC, R), surface, x_lo, x_hi, base, unit_weight,
                         c, tan_phi, slices)
            k = int(np.argmin(F))
            if F[k] < best[0]:
                best = (float(F[k]), (XC[k], YC[k], R))
        return best

    F, (xc, yc, R) = search(np.linspace(x_lo, x_hi, centres[0]),
                            np.linspace(base + 0.05 * height, top + 2.0 * span, centres[1]),
                            0.01 * span, 2.0 * span + height)
    if not np.isfinite(F):
        raise ValueError("bishop: no admissible slip circle found (check the surface and x_range)")
    # refine: 13 x 13 centres and 13 radii over +-1.5 of the last grid's steps, 4x finer
    dxc = span / (centres[0] - 1)
    dyc = (top + 2.0 * span - base - 0.05 * height) / (centres[1] - 1)
    dR = (2.0 * span + height) / (radii - 1)
    for _ in range(refinements):
        F2, circle = search(np.linspace(xc - 1.5 * dxc, xc + 1.5 * dxc, 13),
                            np.linspace(yc - 1.5 * dyc, yc + 1.5 * dyc, 13),
                            max(R - 1.5 * dR, 1e-6 * span), R + 1.5 * dR, n_r=13)
        if F2 <= F:
            F, (xc, yc, R) = F2, circle
        dxc, dyc, dR = dxc / 4, dyc / 4, dR / 4
    x = np.linspace(max(xc - R, x_lo), min(xc + R, x_hi), 4001)
    inside = x[surface(x) > yc - np.sqrt(np.maximum(R * R - (x - xc) ** 2, 0.0))]
    ends = (float(inside.min()), float(inside.max())) if len(inside) else (np.nan, np.nan)
    if facing == "right":
        xc = x_lo + x_hi - xc
        ends = (x_lo + x_hi - ends[1], x_lo + x_hi - ends[0])
    return dict(factor=F, centre=(float(xc), float(yc)), radius=float(R), entry_exit=ends)
