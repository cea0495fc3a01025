"""Probe: the time series of fields at one particle (Simulation.probe)."""
import numpy as np

from .probe_writer import ProbeWriter

PROBE_FIELDS = {"velocity": "v", "displacement": "u", "position": "x", "stress": "stress",
                "acceleration": "a"}


class Probe:
    """Time series of fields at the particle nearest to a point (answered by its owner rank)."""

    def __init__(self, sim, point, fields, path, every):
        p = sim.particles
        point = np.asarray(point, dtype=np.float64)
        bad = [f for f in fields if f not in PROBE_FIELDS]
        if bad:
            raise ValueError(f"probe: unknown field(s) {bad}; choose from {sorted(PROBE_FIELDS)}")
        if point.shape != (sim.gdim,):
            raise ValueError(f"probe: 'point' must have length {sim.gdim}, got {point.shape}")
        x0 = p.x - p.u
        dist = np.linalg.norm(x0 - point, axis=1) if len(p) else np.array([np.inf])
        k = int(np.argmin(dist))
        best = (float(dist[k]), sim.comm.rank)
        if sim.comm.size > 1:
            best = min(sim.comm.allgather(best))
        self.owner = best[1]
        self.sim, self.fields, self.every = sim, list(fields), every
        self.pid = int(p.id[k]) if sim.comm.rank == self.owner else -1
        if sim.comm.size > 1:
            self.pid = sim.comm.bcast(self.pid, root=self.owner)
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
            w._open()
            for row in rows:
                w.write_row(list(row))
            w.close()
        if comm.size > 1:
            comm.barrier()
