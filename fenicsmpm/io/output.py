"""Output: periodic particle (VTU) and grid (XDMF) output of a run (Simulation.run(output=...))."""
import numpy as np

from .particle_writer import ParticleWriter


class Output:
    """Periodic output: particles as VTU (+ .pvd/.pvtu) and nodal fields as XDMF."""

    def __init__(self, path, every=10, particle_fields=("v", "u", "stress", "mass", "V", "id"),
                 grid_fields=True):
        if not (isinstance(every, (int, np.integer)) and every >= 1):
            raise ValueError(f"Output: 'every' must be a positive integer, got {every!r}")
        self.path, self.every = str(path), int(every)
        self.particle_fields, self.grid_fields = particle_fields, grid_fields
        self._pw = self._xdmf = None
        self._mode = "w"

    def open(self, sim):
        import os
        err = None
        if sim.comm.rank == 0:
            try:
                os.makedirs(self.path, exist_ok=True)
                probe = os.path.join(self.path, ".write_test")
                open(probe, "w").close()
                os.remove(probe)
            except OSError as e:
                err = str(e)
        if sim.comm.size > 1:
            err = sim.comm.bcast(err, root=0)
        if err is not None:
            raise ValueError(f"Output: 'path' {self.path!r} cannot be written ({err})")
        if self._pw is None:
            self._pw = ParticleWriter(os.path.join(self.path, "particles"), sim.comm)
        if self.grid_fields and self._xdmf is None:
            from dolfinx import fem, io
            self._xdmf = io.XDMFFile(sim.comm, os.path.join(self.path, "grid.xdmf"), self._mode)
            if self._mode == "w":
                self._xdmf.write_mesh(sim.grid.mesh)
            self._mode = "a"
            self._vel = fem.Function(sim.grid.V, name="velocity")
            self._dens = fem.Function(fem.FunctionSpace(sim.grid.mesh, ("Lagrange", 1)), name="mass")

    def write(self, sim):
        p = sim.particles
        smooth = sim.smoothed_stress() if "stress_smoothed" in self.particle_fields else None
        fields = {f: smooth if f == "stress_smoothed" else getattr(p, f) for f in self.particle_fields}
        self._pw.write(sim.t, p.x, fields)            # after smoothing (it may migrate particles)
        if self._xdmf is not None and "velocity" in sim.nodal:
            self._vel.x.array[:] = sim.nodal["velocity"].ravel()
            self._dens.x.array[:] = sim.nodal["mass"]
            self._xdmf.write_function(self._vel, sim.t)
            self._xdmf.write_function(self._dens, sim.t)

    def close(self):
        if self._xdmf is not None:
            self._xdmf.close()
            self._xdmf = None

    @property
    def pvd(self):
        import os
        return os.path.join(self.path, "particles.pvd")
