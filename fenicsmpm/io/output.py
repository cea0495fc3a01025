"""Output: periodic particle (VTU) and grid (XDMF) output of a run (Simulation.run(output=...))."""
import os

import numpy as np

from .particle_writer import ParticleWriter


class Output:
    """Periodic output of a run, `sim.run(..., output=fm.Output(path, every))`: particles as
    VTU (path/particles.pvd, with .pvtu pieces in parallel) and the nodal velocity and mass
    as XDMF (path/grid.xdmf), every `every` steps. `particle_fields` names particle arrays
    (fenicsmpm.particles.FIELDS, history `state`, optional fields such as `body`, or
    "stress_smoothed"); they are checked when the run starts."""

    def __init__(self, path, every=10, particle_fields=("v", "u", "stress", "mass", "V", "id"),
                 grid_fields=True):
        if not (isinstance(every, (int, np.integer)) and every >= 1):
            raise ValueError(f"Output: 'every' must be a positive integer, got {every!r}")
        if not isinstance(path, (str, os.PathLike)):
            raise TypeError(f"Output: 'path' must be a directory name, got {type(path).__name__}")
        if isinstance(particle_fields, str) or not all(isinstance(f, str) for f in particle_fields):
            raise TypeError(f"Output: 'particle_fields' must be a sequence of field names, got "
                            f"{particle_fields!r}")
        self.path, self.every = str(path), int(every)
        self.particle_fields, self.grid_fields = particle_fields, grid_fields
        self._pw = self._xdmf = None
        self._mode = "w"

    def open(self, sim):
        """Create the directory and writers (collective; called by Simulation.run)."""
        known = set(sim.particles.field_names()) | {"stress_smoothed"}
        unknown = [f for f in self.particle_fields if f not in known]
        if unknown:
            raise ValueError(f"Output: 'particle_fields' {unknown} are not particle fields; "
                             f"choose from {sorted(known)}")
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
            if sim.step_count > 0 and self._exists(sim, self.pvd):
                # a run restored from a checkpoint (or a later stage) with a fresh Output:
                # continue the files there, dropping what was written after this time
                self._pw.resume(sim.t)
                if self.grid_fields and self._exists(sim, self.xdmf):
                    if sim.comm.rank == 0:
                        _trim_xdmf(self.xdmf, sim.t)
                    if sim.comm.size > 1:
                        sim.comm.barrier()
                    self._mode = "a"
        if self.grid_fields and self._xdmf is None:
            from dolfinx import fem, io
            self._xdmf = io.XDMFFile(sim.comm, os.path.join(self.path, "grid.xdmf"), self._mode)
            if self._mode == "w":
                self._xdmf.write_mesh(sim.grid.mesh)
            self._mode = "a"
            self._vel = fem.Function(sim.grid.V, name="velocity")
            self._dens = fem.Function(fem.FunctionSpace(sim.grid.mesh, ("Lagrange", 1)), name="mass")

    def write(self, sim):
        """Write the current particles and nodal fields (collective)."""
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
        """Close the grid XDMF file (the particle writer closes each file as it goes)."""
        if self._xdmf is not None:
            self._xdmf.close()
            self._xdmf = None

    @property
    def pvd(self):
        """The path of the particles' ParaView collection (particles.pvd)."""
        return os.path.join(self.path, "particles.pvd")

    @property
    def xdmf(self):
        """The path of the grid fields' XDMF file (grid.xdmf)."""
        return os.path.join(self.path, "grid.xdmf")

    @staticmethod
    def _exists(sim, path):
        there = os.path.isfile(path) if sim.comm.rank == 0 else None
        return sim.comm.bcast(there, root=0) if sim.comm.size > 1 else there


def _trim_xdmf(path, t_max):
    """Drop the time steps after t_max from the temporal collections of an XDMF file written
    by dolfinx, and their HDF5 data sets (dolfinx cannot write a data set that exists, and
    the redone run writes the same times again)."""
    import xml.etree.ElementTree as ET
    import h5py
    ET.register_namespace("xi", "http://www.w3.org/2001/XInclude")
    tree = ET.parse(path)
    dropped = []
    for coll in tree.getroot().iter("Grid"):
        if coll.get("CollectionType") != "Temporal":
            continue
        for g in list(coll.findall("Grid")):
            tm = g.find("Time")
            if tm is not None and float(tm.get("Value")) > t_max + 1e-12 * max(abs(t_max), 1.0):
                dropped += [d.text.strip() for d in g.iter("DataItem") if d.get("Format") == "HDF"]
                coll.remove(g)
    for ref in dropped:                         # "grid.h5:/Function/velocity/0_42"
        fname, _, name = ref.partition(":")
        with h5py.File(os.path.join(os.path.dirname(path), fname), "a") as h5:
            if name in h5:
                del h5[name]
    tmp = path + ".tmp"
    tree.write(tmp, xml_declaration=True, encoding="utf-8")
    os.replace(tmp, path)
