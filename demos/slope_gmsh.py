"""A slope drawn and meshed with gmsh, collapsing under gravity (Mohr-Coulomb, explicit).

    python3 demos/slope_gmsh.py [--out DIR] [--quick]
    mpirun -n 2 python3 demos/slope_gmsh.py

How a geotechnical model usually starts: the geometry is drawn in gmsh (here with its Python
API, Debian's python3-gmsh), meshed with triangles, and read into dolfinx with
`dolfinx.io.gmshio.model_to_mesh` (rank 0 builds the model, dolfinx distributes the mesh).
That mesh is the MPM background grid; particles fill the soil.

Geometry (metres): a domain [0, 30] x [0, 12]. The soil is a base layer 3 m thick under a
slope 6 m high at 1V:1H (45 degrees) with its toe at x = 8 and its crest at x = 14, and a
plateau to x = 30. The slope surface is a line of the gmsh model shared by two surfaces,
"soil" (physical group 1) and "air" (physical group 2), so the mesh follows the surface
exactly: every cell is entirely soil or air, and `Particles.fill` with a region given by the
cell tags places 9 particles (per_cell=3: the centroids of 9 congruent sub-triangles) in
every soil cell and none in the air, where the soil can run out. Element size 1.0 m
(--quick: 1.5 m).

Soil: fm.MohrCoulomb(E = 10 MPa, nu = 0.3, rho = 2000 kg/m^3, phi = 20 deg, c = 2 kPa,
psi = 0), from a K0 state (fenicsmpm.materials.initial_stress.k0_stress below the ground
surface). A 45 degree slope of this soil is not stable (its infinite-slope factor
tan 20 / tan 45 = 0.36, plus 2 kPa of cohesion over 6 m of height), so it slides as soon
as gravity acts. Explicit MUSL with dt="auto" (cfl 0.5 of the smallest cell), gravity in
full from t = 0, default shape functions ("mpm"). Supports: rollers on the sides (u_x = 0),
the base fixed. The run lasts T_END = 1.5 s (--quick: 0.6 s).

Printed and returned (same dict on every rank):
  toe_advance   how far the front of the slope moved out over the base layer: the smallest x
                of the particles above y = BASE + 0.25 m at the start minus at the end
                (> 0: the slope slid out, towards -x),
  crest_drop    settlement of the particle nearest the crest (probe, [m]),
  mass          total particle mass at the start and the end (conserved exactly),
  finite        whether every particle position and stress is finite at the end.

Writes to DIR (default results/slope_gmsh/):
    slope_gmsh.png     the mesh (read back from slope_gmsh.msh on rank 0) with the squares of
                       h / 2.5 that hold particles at the start, and the final plastic
                       deviatoric strain (MohrCoulomb state column 0) as a raster of the same
                       squares (fenicsmpm.io.particle_raster: reduced over the ranks)
    slope_gmsh.msh     the gmsh mesh (open it with `gmsh slope_gmsh.msh`)
"""
import argparse
import os
import time

import numpy as np
from mpi4py import MPI

import fenicsmpm as fm
from fenicsmpm.io import particle_raster
from fenicsmpm.materials.initial_stress import k0_stress

comm = MPI.COMM_WORLD
L, HEIGHT = 30.0, 12.0                 # domain [m]
BASE, SLOPE_H = 3.0, 6.0               # base layer thickness and slope height [m]
X_TOE, X_CREST = 8.0, 14.0             # toe and crest of the 45 degree slope
RHO, E, NU, PHI, C, PSI = 2000.0, 10e6, 0.3, 20.0, 2e3, 0.0
G = 9.81
SOIL, AIR = 1, 2                       # gmsh physical groups (cell tags)


def surface(x):
    """Height of the initial ground surface at x."""
    return BASE + SLOPE_H * np.clip((x - X_TOE) / (X_CREST - X_TOE), 0.0, 1.0)


def draw(h, msh_path=None):
    """The gmsh model (on rank 0): soil and air surfaces sharing the slope line, meshed with
    triangles of size h. Returns the dolfinx mesh and its cell tags (distributed)."""
    import gmsh
    from dolfinx.io import gmshio
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    if comm.rank == 0:
        geo = gmsh.model.geo
        ground = [(0.0, BASE), (X_TOE, BASE), (X_CREST, BASE + SLOPE_H), (L, BASE + SLOPE_H)]
        pts = [geo.addPoint(0.0, 0.0, 0.0, h), geo.addPoint(L, 0.0, 0.0, h)]
        top = [geo.addPoint(x, y, 0.0, h) for x, y in ground]      # left to right
        sky = [geo.addPoint(L, HEIGHT, 0.0, h), geo.addPoint(0.0, HEIGHT, 0.0, h)]
        bottom = geo.addLine(pts[0], pts[1])
        right_soil = geo.addLine(pts[1], top[-1])
        ground_lines = [geo.addLine(top[k], top[k + 1]) for k in range(len(top) - 1)]
        left_soil = geo.addLine(top[0], pts[0])
        right_air = geo.addLine(top[-1], sky[0])
        ceiling = geo.addLine(sky[0], sky[1])
        left_air = geo.addLine(sky[1], top[0])
        soil = geo.addPlaneSurface([geo.addCurveLoop(
            [bottom, right_soil] + [-g for g in reversed(ground_lines)] + [left_soil])])
        air = geo.addPlaneSurface([geo.addCurveLoop(
            ground_lines + [right_air, ceiling, left_air])])
        geo.synchronize()
        gmsh.model.addPhysicalGroup(2, [soil], SOIL)
        gmsh.model.addPhysicalGroup(2, [air], AIR)
        gmsh.model.mesh.generate(2)                  # triangles (gmsh's default in 2D)
        if msh_path is not None:
            gmsh.write(msh_path)
    msh, cell_tags, _ = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=2)
    gmsh.finalize()
    return msh, cell_tags


def build(h, msh_path=None):
    """The scene: (sim, soil, crest probe)."""
    msh, cell_tags = draw(h, msh_path)
    grid = fm.Grid(msh)
    cmap = msh.topology.index_map(msh.topology.dim)
    soil_cells = np.zeros(cmap.size_local + cmap.num_ghosts, dtype=bool)   # local cells
    soil_cells[cell_tags.indices[cell_tags.values == SOIL]] = True

    def in_soil(x):
        cell = grid.locate(x)[0]
        return (cell >= 0) & soil_cells[np.maximum(cell, 0)]

    soil = fm.MohrCoulomb(E=E, nu=NU, density=RHO, phi=PHI, c=C, psi=PSI)
    # fill places per_cell^2 points in every owned triangle; the region keeps the points
    # whose cell is tagged soil
    pts = fm.Particles.fill(grid, soil, per_cell=3, region=in_soil)
    k0_stress(pts, gravity=G, surface=lambda x: surface(x[:, 0]))
    sim = fm.Simulation(grid, pts, fm.Explicit("MUSL"), dt="auto", gravity=(0.0, -G))
    tol = 1e-6 * L
    sim.fix(lambda x: (np.abs(x[:, 0]) < tol) | (np.abs(x[:, 0] - L) < tol), [0])
    sim.fix(lambda x: np.abs(x[:, 1]) < tol)
    crest = sim.probe((X_CREST + 0.5, BASE + SLOPE_H - 0.3), ["displacement"])
    return sim, soil, crest


def toe_front(p):
    """The front of the slope at the toe: the smallest x of the particles above the base
    layer (y > BASE + 0.25 m; global). The slope faces -x, so it moves left as it slides."""
    sel = p.x[:, 1] > BASE + 0.25
    return comm.allreduce(float(p.x[sel, 0].min()) if np.any(sel) else np.inf, op=MPI.MIN)


def mesh_triangles(path):
    """The triangles of the .msh file: node coordinates (n, 2) and triangles (m, 3), for
    triplot on rank 0. The file is rank 0's own (gmsh built the whole model there, see draw):
    the mesh is read back, not gathered from the ranks."""
    import gmsh
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(path)
    tags, xyz, _ = gmsh.model.mesh.getNodes()
    _, nodes = gmsh.model.mesh.getElementsByType(2)              # 3-node triangles
    gmsh.finalize()
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    return xyz.reshape(-1, 3)[:, :2], index[nodes.astype(np.int64)].reshape(-1, 3)


def plot(msh_xy, cells, start, eps, path):
    """start: the particle count raster at t = 0, eps: the final plastic strain raster, both
    over the domain."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7))
    extent = (0.0, L, 0.0, HEIGHT)
    ax1.imshow(np.where(start > 0, 1.0, np.nan).T, origin="lower", extent=extent, cmap="Oranges",
               vmin=0.0, vmax=2.0)
    ax1.triplot(msh_xy[:, 0], msh_xy[:, 1], cells, lw=0.4, color="0.4")
    ax1.set_title("gmsh mesh (triangles) and the squares holding particles at t = 0", fontsize=10)
    sc = ax2.imshow(eps.T, origin="lower", extent=extent, cmap="viridis", vmin=0.0,
                    vmax=max(np.nanpercentile(eps, 98), 1e-12))
    xs = np.linspace(0.0, L, 200)
    ax2.plot(xs, surface(xs), "k--", lw=0.8, label="initial surface")
    ax2.legend(loc="upper left", fontsize=8)
    fig.colorbar(sc, ax=ax2, label=r"plastic deviatoric strain", shrink=0.8)
    ax2.set_title("after the collapse", fontsize=10)
    for ax in (ax1, ax2):
        ax.set_aspect("equal")
        ax.set_xlim(0, L)
        ax.set_ylim(0, HEIGHT)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/slope_gmsh", help="output directory")
    parser.add_argument("--quick", action="store_true", help="coarse mesh, short run")
    args = parser.parse_args(argv)
    h, t_end = (1.5, 0.6) if args.quick else (1.0, 1.5)
    if comm.rank == 0:
        os.makedirs(args.out, exist_ok=True)
    msh_path = os.path.join(args.out, "slope_gmsh.msh")
    sim, soil, crest = build(h, msh_path)
    p = sim.particles
    mass0 = comm.allreduce(float(np.sum(p.mass)))
    n0 = p.n_global()
    bounds = ((0.0, L), (0.0, HEIGHT))                       # squares of h / 2.5
    shape = (int(round(2.5 * L / h)), int(round(2.5 * HEIGHT / h)))
    start = particle_raster(comm, p.x, None, bounds, shape, reduce="count")
    toe0 = toe_front(p)
    t0 = time.perf_counter()
    sim.run(t_end=t_end)
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    d = crest.data()
    mass1 = comm.allreduce(float(np.sum(p.mass)))
    finite = comm.allreduce(bool(np.all(np.isfinite(p.x)) and np.all(np.isfinite(p.stress))),
                            op=MPI.LAND)
    toe1 = toe_front(p)
    m = dict(h=h, t_end=float(sim.t), steps=sim.step_count, dt=sim.dt, n_particles=n0,
             n_cells=sim.grid.comm.allreduce(sim.grid.n_owned_cells),
             toe_initial=toe0, toe_final=toe1, toe_advance=toe0 - toe1,
             crest_drop=-float(d["displacement_y"][-1]), mass_initial=mass0,
             mass_final=mass1, finite=finite, wall_s=wall,
             png=os.path.join(args.out, "slope_gmsh.png"), msh=msh_path)
    eps = particle_raster(comm, p.x, p.state[:, 0], bounds, shape)
    if comm.rank == 0:
        plot(*mesh_triangles(msh_path), start, eps, m["png"])
        print(f"\nSlope from gmsh: {m['n_cells']} triangles (h = {h:g} m), {n0} particles, "
              f"dt = {sim.dt:.3g} s, {m['steps']} explicit MUSL steps to t = {sim.t:.2f} s, "
              f"{comm.size} rank(s), {wall:.1f} s wall")
        print(f"{'quantity':<30} {'value':>12}")
        print(f"{'toe advance [m]':<30} {m['toe_advance']:12.3f}")
        print(f"{'crest settlement [m]':<30} {m['crest_drop']:12.3f}")
        print(f"{'total mass start [kg/m]':<30} {mass0:12.1f}")
        print(f"{'total mass end [kg/m]':<30} {mass1:12.1f}")
        print(f"{'finite state':<30} {str(finite):>12}")
        print(f"wrote {m['png']} and {msh_path}")
    return m


if __name__ == "__main__":
    main()
