"""Dirichlet conditions: a geometric locator plus components, resolved to a dof mask."""
import numpy as np


def fixed_dofs(grid, where, components):
    """Boolean mask (n_nodes, gdim) of the dofs fixed by where(x) on the given components.

    where(x) takes node coordinates of shape (n, gdim) and returns one bool per node.
    Raises ValueError if the locator matches no node anywhere (on any rank)."""
    if not callable(where):
        raise TypeError(f"fix: 'where' must be callable where(x) -> bool, got {type(where).__name__}")
    comps = list(range(grid.gdim)) if components is None else list(np.atleast_1d(components))
    for c in comps:
        if not (isinstance(c, (int, np.integer)) and 0 <= c < grid.gdim):
            raise ValueError(f"fix: 'components' must be integers in [0, {grid.gdim}), got {components!r}")
    nodes = grid.nodes_where(where)
    if grid.global_count(nodes[: grid.n_owned_nodes]) == 0:
        raise ValueError("fix: the Dirichlet locator 'where' matches no grid node")
    mask = np.zeros((grid.n_nodes, grid.gdim), dtype=bool)
    mask[np.ix_(nodes, comps)] = True
    return mask


class PrescribedMotion:
    """The motion of the dofs of one `Simulation.fix(where, components, displacement=... or
    velocity=...)`: `mask` (n_nodes, gdim) the dofs, `components` their indices, and either
    displacement u(t) (a number or one value per component, measured from any fixed origin:
    only its increments u(t1) - u(t0) move the dofs) or velocity (a constant, or v(t),
    integrated at the step's midpoint: v((t0 + t1)/2) (t1 - t0))."""

    def __init__(self, mask, components, displacement=None, velocity=None):
        if displacement is not None and velocity is not None:
            raise ValueError("fix: give at most one of 'displacement' and 'velocity'")
        if displacement is not None and not callable(displacement):
            raise TypeError(f"fix: 'displacement' must be a function u(t) of time (for a "
                            f"constant velocity v pass velocity=v), got {displacement!r}")
        self.mask, self.components = mask, list(components)
        self.displacement, self.velocity = displacement, velocity
        if velocity is not None and not callable(velocity):
            self.value(velocity, "velocity")          # a constant: check it now

    def value(self, raw, name):
        """raw (a number or one value per component) as a finite (len(components),) array."""
        v = np.asarray(raw, dtype=float)
        k = len(self.components)
        if v.ndim == 0:
            v = np.full(k, float(v))
        if v.shape != (k,) or not np.all(np.isfinite(v)):
            raise ValueError(f"fix: '{name}' must give a finite number or {k} values (one per "
                             f"component {self.components}), got {raw!r}")
        return v

    def increment(self, t0, t1):
        """The dofs' displacement over [t0, t1], one value per component."""
        if self.displacement is not None:
            return (self.value(self.displacement(t1), "displacement")
                    - self.value(self.displacement(t0), "displacement"))
        v = self.velocity(0.5 * (t0 + t1)) if callable(self.velocity) else self.velocity
        return self.value(v, "velocity") * (t1 - t0)

    def rates(self, t, dt):
        """(velocity, acceleration) of the dofs at t, one value per component, by central
        differences over dt (implicit Newmark's start-of-step kinematics): from u(t) or v(t);
        a constant velocity has zero acceleration."""
        if self.displacement is not None:
            u = [self.value(self.displacement(s), "displacement") for s in (t - dt, t, t + dt)]
            return (u[2] - u[0]) / (2.0 * dt), (u[2] - 2.0 * u[1] + u[0]) / (dt * dt)
        if not callable(self.velocity):
            v = self.value(self.velocity, "velocity")
            return v, np.zeros_like(v)
        v = [self.value(self.velocity(s), "velocity") for s in (t - dt, t, t + dt)]
        return v[1], (v[2] - v[0]) / (2.0 * dt)


def _scatter(out, motions, values):
    """out[dofs of motion m, component c] = values[m][k], c = m.components[k] (a later motion
    wins)."""
    for m, val in zip(motions, values):
        for k, c in enumerate(m.components):
            out[m.mask[:, c], c] = val[k]
    return out


def prescribed_rates(shape, motions, t, dt):
    """(moving (n_nodes, gdim) bool, velocity, acceleration) of the dofs moved by `motions`
    at t (PrescribedMotion.rates)."""
    rates = [m.rates(t, dt) for m in motions]
    moving = _scatter(np.zeros(shape, dtype=bool), motions, [[True] * len(m.components)
                                                             for m in motions])
    return (moving, _scatter(np.zeros(shape), motions, [r[0] for r in rates]),
            _scatter(np.zeros(shape), motions, [r[1] for r in rates]))


def prescribed_increment(node_x, fixed, motions, t0, t1, u=None, fixed_only=True):
    """(n_nodes, gdim) displacement increments of the fixed dofs over [t0, t1], zero elsewhere:
    the integrator's u(x, t) on every fixed dof where given (u(x, t1) - u(x, t0); with
    fixed_only=False on every dof, fm.QuasiStatic's Newton start), then each PrescribedMotion
    on its own dofs (a later fix wins); None when nothing moves."""
    if u is None and not motions:
        return None
    du = np.zeros(node_x.shape)
    if u is not None:
        du = (np.asarray(u(node_x, t1), dtype=float) - np.asarray(u(node_x, t0), dtype=float))
        if du.shape != node_x.shape or not np.all(np.isfinite(du)):
            raise ValueError(f"'displacement' u(x, t) must return finite values of shape "
                             f"{node_x.shape} for the node coordinates, got shape {du.shape}")
    _scatter(du, motions, [m.increment(t0, t1) for m in motions])
    return np.where(fixed, du, 0.0) if fixed_only else du
