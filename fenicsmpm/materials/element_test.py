"""Element tests without a mesh: one material point driven along a strain or mixed
strain/stress path through the material's own `stress` kernel (any fenicsmpm material).

Conventions: tension positive, axis 1 (y) is the axial/vertical direction, axes 0 and 2 the
lateral ones; increments are symmetric (no spin: dF = I + deps).  Stress-controlled diagonal
components are found by Newton iterations on the unknown strain components, with the Jacobian
by forward differences of the stress update; the step is committed only when the stress
residual is below `tol` (1e-7) of the stress scale.  Invariants: p = -tr sigma / 3,
q = sqrt(3/2 s:s) (s the deviator), eps_v = tr eps (compaction negative), eps_a = eps_yy.
"""
import numpy as np

__all__ = ["Element", "isotropic", "oedometer", "triaxial", "biaxial", "cyclic_shear",
           "invariants"]

_UNIT = {k: np.zeros((3, 3)) for k in range(3)}
for _k in range(3):
    _UNIT[_k][_k, _k] = 1.0


def invariants(sigma):
    """(p, q) of stresses (..., 3, 3): p = -tr sigma / 3, q = sqrt(3/2 s:s)."""
    sigma = np.asarray(sigma)
    p = -np.trace(sigma, axis1=-2, axis2=-1) / 3.0
    s = sigma + p[..., None, None] * np.eye(3)
    return p, np.sqrt(1.5 * np.einsum("...ij,...ij->...", s, s))


class Element:
    """One material point: stress (3 x 3), history `state`, accumulated strain.

    stress: the initial stress (3 x 3), or a number p > 0 for the isotropic state -p I.
    e, delta: initial void ratio and intergranular strain of a Hypoplastic material (default
    its e_0, delta_0; e is checked against [e_d(p), e_i(p)]); other materials ignore them.
    The record (`history()`) holds strain, stress and state after every committed step."""

    def __init__(self, material, stress, e=None, delta=None):
        self.material = material
        s = np.asarray(stress, dtype=float)
        self.sigma = (-float(s) * np.eye(3) if s.ndim == 0 else s.copy()).reshape(1, 3, 3)
        self.state = np.zeros((1, material.n_state))
        if hasattr(material, "check_void_ratio"):
            ev = material.params["e_0"] if e is None else float(e)
            material.check_void_ratio(ev, max(-np.trace(self.sigma[0]) / 3.0, 0.0), name="e")
            self.state[0, 0] = ev
            d = material.delta_0 if delta is None else np.asarray(delta, dtype=float)
            self.state[0, 1:7] = d[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]]
        self.eps = np.zeros((3, 3))
        self._idx = np.zeros(1, dtype=np.int64)
        self._F = np.eye(3).reshape(1, 3, 3)
        self._rec = dict(eps=[self.eps.copy()], sigma=[self.sigma[0].copy()],
                         state=[self.state[0].copy()])

    def trial(self, deps):
        """(stress, state) after the symmetric strain increment deps, not committed."""
        dF = (np.eye(3) + np.asarray(deps, dtype=float)).reshape(1, 3, 3)
        out = np.empty_like(self.sigma)
        st = self.state.copy()
        self.material.stress(self._idx, dF, self._F, self.sigma, out, st)
        return out[0], st[0]

    def step(self, deps, targets=None, unknowns=None, tol=1e-7, max_iter=30):
        """Commit one increment.  deps: prescribed strain increment (3 x 3).  targets: None, or
        a dict {(i, i): sigma_ii} of stress-controlled diagonal components; unknowns: list of
        3 x 3 strain directions B_k (one per target) added as sum_k x_k B_k to deps, x found
        by Newton with forward-difference Jacobian until |residual| <= tol x the stress scale, or
        until it stagnates below 1000 tol x the scale (the sub-stepped stress update is smooth
        only to its own tolerance).  Returns the new stress."""
        deps = np.asarray(deps, dtype=float)
        if targets:
            keys = list(targets)
            goal = np.array([targets[k] for k in keys])
            B = [np.asarray(b, dtype=float) for b in unknowns]
            scale = max(np.max(np.abs(self.sigma)), np.max(np.abs(goal)), 1e-300)
            x = getattr(self, "_x_prev", None)
            x = np.zeros(len(B)) if x is None or len(x) != len(B) else x.copy()
            hfd = 1e-6 * max(np.linalg.norm(deps), 1e-12)

            def res(xv):
                s, _ = self.trial(deps + sum(xi * b for xi, b in zip(xv, B)))
                return np.array([s[k] for k in keys]) - goal

            r = res(x)
            for _ in range(max_iter):
                if np.max(np.abs(r)) <= tol * scale:
                    break
                J = np.empty((len(B), len(B)))
                for j in range(len(B)):
                    xp = x.copy()
                    xp[j] += hfd
                    J[:, j] = (res(xp) - r) / hfd
                x = x - np.linalg.solve(J, r)
                r_old, r = np.max(np.abs(r)), res(x)
                if np.max(np.abs(r)) <= 1e3 * tol * scale and np.max(np.abs(r)) > 0.5 * r_old:
                    break             # stagnation at the noise level of the sub-stepped update
            else:
                raise RuntimeError(f"Element.step: mixed control did not converge (residual "
                                   f"{np.max(np.abs(r)):.3g} Pa)")
            self._x_prev = x
            deps = deps + sum(xi * b for xi, b in zip(x, B))
        s, st = self.trial(deps)
        self.sigma[0] = s
        self.state[0] = st
        self.eps = self.eps + deps
        self._rec["eps"].append(self.eps.copy())
        self._rec["sigma"].append(s.copy())
        self._rec["state"].append(st.copy())
        return s

    def history(self):
        """Arrays eps (n, 3, 3), sigma (n, 3, 3), state (n, n_state), p, q, eps_v, eps_a and,
        for a Hypoplastic material, e (n,)."""
        h = {k: np.array(v) for k, v in self._rec.items()}
        h["p"], h["q"] = invariants(h["sigma"])
        h["eps_v"] = np.trace(h["eps"], axis1=1, axis2=2)
        h["eps_a"] = h["eps"][:, 1, 1]
        if h["state"].shape[1]:
            h["e"] = h["state"][:, 0]
        return h


def isotropic(material, p0, p1, e0=None, deps_v=-1e-4, max_steps=100000):
    """Isotropic compression (strain controlled, eps = deps_v/3 I per step) from p0 until p >= p1
    [Pa]; returns Element.history()."""
    el = Element(material, p0, e=e0)
    inc = deps_v / 3.0 * np.eye(3)
    for _ in range(max_steps):
        if -np.trace(el.sigma[0]) / 3.0 >= p1:
            break
        el.step(inc)
    return el.history()


def oedometer(material, sigma0, e0=None, K0=None, strain=-0.02, unload_to=None, n=400):
    """Oedometric (1D) loading to the axial strain `strain` in n steps, then unloading by
    strain until sigma_yy >= unload_to (default: back to the initial sigma_yy) or the strain
    is recovered.  Initial stress: sigma_yy = -sigma0, lateral K0 sigma_yy (K0 default 1 -
    sin phi_c for a Hypoplastic material, else 1)."""
    if K0 is None:
        K0 = 1.0 - np.sin(np.radians(material.params["phi_c"])) if hasattr(material, "params") else 1.0
    s0 = np.diag([-K0 * sigma0, -sigma0, -K0 * sigma0])
    el = Element(material, s0, e=e0)
    inc = np.zeros((3, 3))
    inc[1, 1] = strain / n
    for _ in range(n):
        el.step(inc)
    target = -sigma0 if unload_to is None else unload_to
    for _ in range(4 * n):
        if el.sigma[0, 1, 1] >= target or el.eps[1, 1] >= 0.0:
            break
        el.step(-inc)
    return el.history()


def triaxial(material, p0, e0=None, axial_strain=-0.2, n=2000, drained=True):
    """Triaxial compression from the isotropic state -p0 I: axial strain increments
    axial_strain / n; drained: constant lateral stress -p0 (Newton on the lateral strain,
    eps_xx = eps_zz); undrained: isochoric (eps_xx = eps_zz = -eps_yy / 2)."""
    el = Element(material, p0, e=e0)
    da = axial_strain / n
    for _ in range(n):
        if drained:
            el.step(np.diag([0.0, da, 0.0]), targets={(0, 0): -p0},
                    unknowns=[np.diag([1.0, 0.0, 1.0])])
        else:
            el.step(np.diag([-0.5 * da, da, -0.5 * da]))
    return el.history()


def biaxial(material, sigma0, e0=None, axial_strain=-0.1, n=1000, drained=True):
    """Plane-strain (biaxial) compression (eps_zz = 0) from the isotropic state -sigma0 I
    (seed 004 Figure 3.3: sigma0 = 100 kPa): drained: constant sigma_xx = -sigma0; undrained:
    isochoric, eps_xx = -eps_yy."""
    el = Element(material, sigma0, e=e0)
    da = axial_strain / n
    for _ in range(n):
        if drained:
            el.step(np.diag([0.0, da, 0.0]), targets={(0, 0): -sigma0},
                    unknowns=[np.diag([1.0, 0.0, 0.0])])
        else:
            el.step(np.diag([-da, da, 0.0]))
    return el.history()


def cyclic_shear(material, sigma_v, e0=None, K0=None, gamma=1e-3, cycles=3, n=200,
                 drained=True):
    """Cyclic simple shear: engineering shear strain gamma_xy between +-gamma (eps_xy =
    gamma / 2), n steps per quarter cycle, from sigma_yy = -sigma_v, lateral K0 sigma_yy.
    drained: constant vertical stress (Newton on eps_yy); undrained: constant volume (only
    eps_xy changes)."""
    if K0 is None:
        K0 = 1.0 - np.sin(np.radians(material.params["phi_c"])) if hasattr(material, "params") else 1.0
    el = Element(material, np.diag([-K0 * sigma_v, -sigma_v, -K0 * sigma_v]), e=e0)
    dg = 0.5 * gamma / n
    path = [1] * n + ([-1] * (2 * n) + [1] * (2 * n)) * cycles
    for sgn in path:
        inc = np.zeros((3, 3))
        inc[0, 1] = inc[1, 0] = sgn * dg
        if drained:
            el.step(inc, targets={(1, 1): -sigma_v}, unknowns=[_UNIT[1]])
        else:
            el.step(inc)
    return el.history()
