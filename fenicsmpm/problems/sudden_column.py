"""The elastic column under suddenly applied gravity (PEERS.md, "Accuracy, explicit"; the
set-up CB-Geo mpm was measured on): E = 10 MPa, nu = 0, rho = 2000 kg/m^3, H = 10 m,
g = 9.81 m/s^2 switched on at t = 0 on a stress-free column at rest, side rollers, fixed base,
2 x 2 particles per cell; meshes of nx x ny square cells (1 x 20: 0.5 m wide, 10 x 100: 1 m
wide), the column filling the mesh.

With nu = 0 and the sides on rollers the column is a 1D fixed-free bar (wave speed
c = sqrt(E / rho)). Exact solution (modal series of the suddenly loaded fixed-free bar,
y from the base, k_n = (2n - 1) pi / (2H), w_n = c k_n; e.g. Graff 1975, "Wave motion in
elastic solids", sect. 2.2, expansion in the free modes sin(k_n y)):
    u(y, t)       = -(g / c^2) [ H y - y^2 / 2 - sum_n 2 / (H k_n^3) sin(k_n y) cos(w_n t) ]
    sigma_yy(y,t) = -rho g     [ H - y       - sum_n 2 / (H k_n^2) cos(k_n y) cos(w_n t) ]
(the static part is rho g (H y - y^2 / 2) / E; u(y, 0) = 0 and sigma(y, 0) = 0 because the
series are the sine/cosine expansions of the static parts). The top settles between 0 and
2 rho g H^2 / (2E) = 0.196 m with the period 4H / c = 0.566 s."""
import math

import numpy as np
from mpi4py import MPI
from dolfinx import mesh as dmesh

from ..grid import Grid
from ..integrators import Explicit
from ..materials import LinearElastic
from ..particles import Particles
from ..simulation import Simulation

__all__ = ["PEERS", "SuddenColumnExact", "sudden_column"]

PEERS = dict(height=10.0, E=1e7, nu=0.0, density=2000.0, g=9.81, t_end=1.0)


class SuddenColumnExact:
    """Modal series of the suddenly loaded fixed-free bar (module docstring), `terms` modes.

    displacement(y, t), stress(y, t): arrays over y (one t) or over t (one y) by numpy
    broadcasting; static_top = rho g H^2 / (2E), peak_top = 2 static_top, period = 4H / c."""

    def __init__(self, height=PEERS["height"], E=PEERS["E"], density=PEERS["density"],
                 g=PEERS["g"], terms=4000):
        self.H, self.E, self.rho, self.g = float(height), float(E), float(density), float(g)
        self.c = math.sqrt(self.E / self.rho)
        self.k = (2.0 * np.arange(1, int(terms) + 1) - 1.0) * math.pi / (2.0 * self.H)
        self.w = self.c * self.k
        self.static_top = self.rho * self.g * self.H ** 2 / (2.0 * self.E)
        self.peak_top = 2.0 * self.static_top
        self.period = 4.0 * self.H / self.c

    def _series(self, y, t, power, fn):
        y = np.asarray(y, dtype=float)
        t = np.asarray(t, dtype=float)
        yy, tt = np.broadcast_arrays(y, t)
        out = np.zeros(yy.shape)
        flat_y, flat_t, flat = yy.ravel(), tt.ravel(), out.reshape(-1)
        for s in range(0, len(flat), 256):              # bounded memory: 256 points x terms
            ys, ts = flat_y[s:s + 256, None], flat_t[s:s + 256, None]
            flat[s:s + 256] = (2.0 / (self.H * self.k ** power)
                               * fn(self.k * ys) * np.cos(self.w * ts)).sum(axis=1)
        return out

    def displacement(self, y, t):
        """u_y(y, t) (negative: settlement)."""
        y = np.asarray(y, dtype=float)
        return -(self.g / self.c ** 2) * (self.H * y - 0.5 * y ** 2 - self._series(y, t, 3, np.sin))

    def stress(self, y, t):
        """sigma_yy(y, t) (negative: compression)."""
        y = np.asarray(y, dtype=float)
        return -self.rho * self.g * (self.H - y - self._series(y, t, 2, np.cos))

    def static_stress(self, y):
        return -self.rho * self.g * (self.H - np.asarray(y, dtype=float))


def sudden_column(cells=(1, 20), per_cell=2, shape="auto", scheme=None, integrator=None,
                  dt="auto", cfl=0.5, height=PEERS["height"], E=PEERS["E"], nu=PEERS["nu"],
                  density=PEERS["density"], g=PEERS["g"], terms=4000, comm=MPI.COMM_WORLD,
                  material=LinearElastic):
    """The PEERS.md column on an nx x ny grid of square cells (cells = (nx, ny), h = H / ny,
    width nx h), with the library defaults: fm.Simulation(grid, particles, fm.Explicit(),
    dt="auto", gravity=(0, -g)) and shape="auto" unless `shape` is given; `scheme` (e.g.
    "USF") or a ready `integrator` replace fm.Explicit()'s defaults; dt, cfl: as for
    fm.Simulation (dt="auto" is cfl * h / c_p, cfl 0.5 its default). Returns (sim, exact),
    exact a SuddenColumnExact with `h` and `cells` added. `material`: the elastic class
    (fm.LinearElastic; fm.BiotElastic follows the linear column at any amplitude)."""
    nx, ny = (int(n) for n in cells)
    h = height / ny
    msh = dmesh.create_rectangle(comm, [[0.0, 0.0], [nx * h, height]], [nx, ny],
                                 dmesh.CellType.quadrilateral)
    grid = Grid(msh)
    mat = material(E=E, nu=nu, density=density)
    pts = Particles.fill(grid, mat, per_cell=per_cell)
    if integrator is None:
        integrator = Explicit() if scheme is None else Explicit(scheme)
    sim = Simulation(grid, pts, integrator, dt=dt, gravity=(0.0, -g), shape=shape,
                     cfl=cfl)
    width = nx * h
    sim.fix(lambda x: np.isclose(x[:, 0], 0.0) | np.isclose(x[:, 0], width), [0])
    sim.fix(lambda x: np.isclose(x[:, 1], 0.0), [0, 1])
    exact = SuddenColumnExact(height, E, density, g, terms)
    exact.h, exact.cells = h, (nx, ny)
    return sim, exact
