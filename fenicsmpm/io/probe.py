"""Probe: the time series of fields at one particle (Simulation.probe)."""
import numpy as np
from mpi4py import MPI

from .probe_writer import ProbeWriter

PROBE_FIELDS = {"velocity": "v", "displacement": "u", "position": "x", "stress": "stress",
                "acceleration": "a"}


class Probe:
    """Time series of fields at one particle: the particle whose initial position is nearest
    to `point` (answered by the rank that owns it; made by Simulation.probe).

    The particle is chosen once, when the probe is made, and followed by its id as it moves and
    migrates between ranks. `particle_id`, `particle_x0` (its initial position) and `distance`
    (from `point`) say which one; `ties` counts the other particles at the same distance (a
    point on a cell face or between particle rows), the smallest id among them being chosen.
    `str(probe)` says all this in one line. A point outside the mesh raises a ValueError."""

    def __init__(self, sim, point, fields, path, every):
        p = sim.particles
        comm = sim.comm
        if isinstance(fields, str):
            fields = [fields]
        bad = [f for f in fields if f not in PROBE_FIELDS]
        if bad or not len(fields):
            raise ValueError(f"probe: unknown field(s) {bad}; 'fields' must name some of "
                             f"{sorted(PROBE_FIELDS)}")
        try:
            point = np.asarray(point, dtype=np.float64)
        except (TypeError, ValueError):
            point = np.zeros(0)
        if point.shape != (sim.gdim,) or not np.all(np.isfinite(point)):
            raise ValueError(f"probe: 'point' must be {sim.gdim} finite coordinates, got {point!r}")
        if not (isinstance(every, (int, np.integer)) and not isinstance(every, bool) and every >= 1):
            raise ValueError(f"probe: 'every' must be a positive integer, got {every!r}")
        cell, _ = sim.grid.locate(point[None, :])
        inside = int(cell[0] >= 0)
        if comm.size > 1:
            inside = comm.allreduce(inside)
        if not inside:
            raise ValueError(f"probe: 'point' {tuple(point.tolist())} lies outside the mesh")
        x0 = p.x - p.u
        dist = np.linalg.norm(x0 - point, axis=1)
        dmin = float(dist.min()) if len(p) else np.inf
        if comm.size > 1:
            dmin = comm.allreduce(dmin, op=MPI.MIN)
        if not np.isfinite(dmin):
            raise ValueError("probe: the simulation has no particles")
        near = np.flatnonzero(dist <= dmin + 1e-9 * sim.grid.h)      # ties: equal distance
        pid = int(p.id[near].min()) if len(near) else np.iinfo(np.int64).max
        n_near = len(near)
        if comm.size > 1:
            pid = comm.allreduce(pid, op=MPI.MIN)
            n_near = comm.allreduce(n_near)
        hit = np.flatnonzero(p.id == pid)
        k = int(hit[0]) if len(hit) else -1
        owner = comm.rank if k >= 0 else comm.size
        self.owner = comm.allreduce(owner, op=MPI.MIN) if comm.size > 1 else owner
        self.sim, self.fields, self.every = sim, list(fields), int(every)
        self.point = tuple(point.tolist())
        self.pid = self.particle_id = pid
        xk = x0[k].tolist() if k >= 0 else None
        self.particle_x0 = tuple(comm.bcast(xk, root=self.owner) if comm.size > 1 else xk)
        self.distance = dmin
        self.ties = n_near - 1
        self._idx = k if sim.comm.rank == self.owner else -1
        self._version = p.version
        self.rows = []
        cols = ["t"]
        for f in self.fields:
            cols += [f"{f}_{c}" for c in self._components(f)]
        self.columns = cols
        self.path = path
        # the CSV is streamed: rank 0 writes the header, then whichever rank owns the particle
        # appends its row (flushed), so a crashed run leaves every row up to its last step
        self.writer = None
        if path:
            self.rewrite_csv([])
            self.writer = ProbeWriter(path, cols, sim.comm, append=True)
        self.record()

    def __str__(self):
        tie = (f"; {self.ties} other particle(s) at the same distance, the smallest id chosen"
               if self.ties else "")
        x0 = ", ".join(f"{c:.6g}" for c in self.particle_x0)
        pt = ", ".join(f"{c:.6g}" for c in self.point)
        return (f"probe at ({pt}): particle {self.particle_id}, initial position ({x0}), "
                f"distance {self.distance:.3g}{tie}")

    def _components(self, f):
        if f == "stress":
            return ["xx", "yy", "zz", "xy", "yz", "xz"][: 6 if self.sim.gdim == 3 else 4]
        return "xyz"[: self.sim.gdim]

    def _value(self, f, i):
        arr = getattr(self.sim.particles, PROBE_FIELDS[f])[i]
        if f == "stress":
            s = arr
            vals = [s[0, 0], s[1, 1], s[2, 2], s[0, 1], s[1, 2], s[0, 2]]
            return vals[: 6 if self.sim.gdim == 3 else 4]
        return list(arr)

    def record(self):
        """Append the current values (every `every` steps; called by Simulation.step)."""
        if self.sim.step_count % self.every:
            return
        p = self.sim.particles
        if p.version != self._version:          # particles were reshuffled between ranks
            hit = np.flatnonzero(p.id == self.pid)
            self._idx = int(hit[0]) if len(hit) else -1
            self._version = p.version
        if self._idx < 0:
            return
        row = [self.sim.t]
        for f in self.fields:
            row += self._value(f, self._idx)
        self.rows.append(row)
        if self.writer is not None:
            self.writer.write_row(row)

    def data(self):
        """dict column -> array on every rank (collective; call outside the time loop)."""
        rows = self.rows
        if self.sim.comm.size > 1:
            rows = sorted(r for part in self.sim.comm.allgather(rows) for r in part)
        rows = np.array(rows).reshape(-1, len(self.columns))
        return {c: rows[:, j] for j, c in enumerate(self.columns)}

    def rewrite_csv(self, rows):
        """Start the CSV afresh with `rows` (rank 0; collective), e.g. after a restore."""
        comm = self.sim.comm
        if comm.rank == 0:
            w = ProbeWriter(self.path, self.columns, None)
            w.rewrite(list(r) for r in rows)
            w.close()
        if comm.size > 1:
            comm.barrier()


class ReactionProbe(Probe):
    """Time series of the reaction force of the fixed (or moved) nodes at where(x) (all fixed
    nodes for where=None): columns t, reaction_x, reaction_y[, reaction_z], the value of
    Simulation.reaction(where) after each recorded step (made by Simulation.probe_reaction).
    Recording is collective (a sum over ranks); rank 0 keeps the rows and writes the CSV."""

    def __init__(self, sim, where, path, every):
        if not (isinstance(every, (int, np.integer)) and not isinstance(every, bool) and every >= 1):
            raise ValueError(f"probe_reaction: 'every' must be a positive integer, got {every!r}")
        if where is not None:
            sim.grid.nodes_where(where)               # checks the locator once
        self.sim, self.where, self.every = sim, where, int(every)
        self.fields = ["reaction"]
        self.columns = ["t"] + [f"reaction_{c}" for c in "xyz"[: sim.gdim]]
        self.rows, self.path, self.writer, self._version = [], path, None, 0
        if path:
            self.rewrite_csv([])
            self.writer = ProbeWriter(path, self.columns, sim.comm, append=True)

    def __str__(self):
        return f"reaction probe at {'all fixed nodes' if self.where is None else 'where(x)'}"

    def record(self):
        """Append t and the reaction of the last step (every `every` steps; collective)."""
        if self.sim.step_count % self.every or "reaction" not in self.sim.nodal:
            return
        r = self.sim.reaction(self.where)
        if self.sim.comm.rank == 0:
            row = [self.sim.t] + [float(v) for v in r]
            self.rows.append(row)
            if self.writer is not None:
                self.writer.write_row(row)
