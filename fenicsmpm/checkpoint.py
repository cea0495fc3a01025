"""Checkpoint and restart: the complete state of a Simulation, written so that a run killed at
any moment leaves the previous checkpoint intact.

Layout of a checkpoint directory `path`:
    path/LATEST                    name of the newest complete checkpoint (replaced atomically)
    path/step_00001200/meta.json   time, step, stage, integrator, sizes (rank 0)
    path/step_00001200/energy.npz  the energy monitor's E_0 and history (rank 0; only with
                                   Simulation.monitor_energy; each rank file has its work)
    path/step_00001200/rank0.npz   this rank's particles (every migrating field, history
                                   variables included), its nodal state (Robin spring
                                   displacements, integrator arrays such as a^n, the contact
                                   status of frictional boundaries) keyed by global node
                                   index, and its probe records
Every file is written under a temporary name and renamed; LATEST is switched by rank 0 only
after all ranks have renamed their files, and older checkpoints are removed after that.

Rank r reads the particle files k with k % size == r (its own file on the same number of
ranks), locates the particles on its part of the mesh and hands the others to the ranks owning
their cells; nodal arrays are matched by node coordinates. dolfinx's graph partitioners
(SCOTCH/ParMETIS) do not cut a mesh the same way twice, so the restored run is bit for bit the
continuous one on one rank, or on several ranks when the mesh is built with a deterministic
partitioner (the particle order and the summation order are then the same); otherwise it
agrees to round-off."""
import json
import os
import shutil

import numpy as np

from .errors import CheckpointNotFoundError

FORMAT = 1


def _integrator_arrays(integrator):
    """Nodal arrays (n_nodes, ...) an integrator keeps between steps (`checkpoint_arrays`)."""
    get = getattr(integrator, "checkpoint_arrays", None)
    return dict(get()) if get is not None else {}


def _rows(x):
    """Rows of a float array as opaque byte strings (exact matching of coordinates)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    return x.view(np.dtype((np.void, x.dtype.itemsize * x.shape[1]))).ravel()


def _write_atomic(fname, write):
    tmp = fname + ".tmp"
    with open(tmp, "wb") as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, fname)


def write(sim, path, keep=1):
    """Write a checkpoint of `sim` under directory `path` (collective); returns its folder."""
    comm, p, grid = sim.comm, sim.particles, sim.grid
    name = f"step_{sim.step_count:08d}"
    folder = os.path.join(path, name)
    if comm.rank == 0:
        os.makedirs(folder, exist_ok=True)
    if comm.size > 1:
        comm.barrier()
    arrays = {f"p.{f}": getattr(p, f) for f in p.field_names()}
    arrays["node_x"] = grid.node_x[: grid.n_owned_nodes]
    n = grid.n_owned_nodes
    arrays["node.robin_u"] = sim.robin_u[:n]
    for k, a in _integrator_arrays(sim.integrator).items():
        arrays[f"node.integrator.{k}"] = a[:n]
    for j, fr in enumerate(sim.frictions):     # contact status of the frictional boundaries
        for k, a in fr.checkpoint_arrays().items():
            arrays[f"node.friction{j}.{k}"] = a[:n]
    if sim.monitoring_work:
        arrays["energy.work"] = sim._work      # this rank's share of the monitored work
    for k, pr in enumerate(sim.probes):
        arrays[f"probe.{k}"] = np.array(pr.rows, dtype=np.float64).reshape(-1, len(pr.columns))
    _write_atomic(os.path.join(folder, f"rank{comm.rank}.npz"), lambda f: np.savez(f, **arrays))
    meta = dict(format=FORMAT, t=sim.t, step_count=sim.step_count, dt=sim.dt,
                stage_start=sim.stage_start, initial_stress=sim.initial_stress,
                gravity=sim.gravity.tolist(), integrator=type(sim.integrator).__name__,
                ranks=comm.size, gdim=sim.gdim, n_particles=p.n_global(),
                n_nodes=grid.V.dofmap.index_map.size_global,
                materials=[type(m).__name__ for m in p.materials],
                optional=list(p.optional), n_probes=len(sim.probes),
                split_count=0 if sim.splitting is None else sim.splitting.count,
                removed_mass=sim.removed_mass, removed_count=sim.removed_count)
    shared = getattr(sim.integrator, "checkpoint_state", lambda: {})()
    if shared and comm.rank == 0:               # replicated on every rank: written once
        _write_atomic(os.path.join(folder, "integrator.npz"), lambda f: np.savez(f, **shared))
    energy = sim._energy_state()
    if energy is not None and comm.rank == 0:   # the same on every rank
        _write_atomic(os.path.join(folder, "energy.npz"), lambda f: np.savez(f, **energy))
    if comm.size > 1:
        comm.barrier()                         # every rank file is complete
    if comm.rank == 0:
        _write_atomic(os.path.join(folder, "meta.json"),
                      lambda f: f.write(json.dumps(meta, indent=1).encode()))
        _write_atomic(os.path.join(path, "LATEST"), lambda f: f.write(name.encode()))
        old = sorted(d for d in os.listdir(path) if d.startswith("step_") and d != name)
        for d in old[: max(0, len(old) - (keep - 1))]:
            shutil.rmtree(os.path.join(path, d), ignore_errors=True)
    if comm.size > 1:
        comm.barrier()
    return folder


def _latest(path, comm):
    name = None
    if comm.rank == 0:
        try:
            with open(os.path.join(path, "LATEST")) as f:
                name = f.read().strip()
        except OSError:
            name = None
    if comm.size > 1:
        name = comm.bcast(name, root=0)
    if name is None:
        raise CheckpointNotFoundError(f"restore: no checkpoint in {path!r} (missing "
                                      f"{os.path.join(path, 'LATEST')})")
    folder = os.path.join(path, name)
    meta = os.path.join(folder, "meta.json")
    if not os.path.isfile(meta):
        raise CheckpointNotFoundError(f"restore: the checkpoint {folder!r} named by "
                                      f"{os.path.join(path, 'LATEST')} is incomplete (missing {meta})")
    with open(meta) as f:
        return folder, json.load(f)


def _check(sim, meta):
    p = sim.particles
    have = dict(integrator=type(sim.integrator).__name__, gdim=sim.gdim,
                n_nodes=sim.grid.V.dofmap.index_map.size_global,
                materials=[type(m).__name__ for m in p.materials], n_probes=len(sim.probes))
    bad = {k: (meta[k], v) for k, v in have.items() if meta[k] != v}
    if meta.get("format") != FORMAT:
        bad["format"] = (meta.get("format"), FORMAT)
    if bad:
        detail = ", ".join(f"{k}: checkpoint {a!r}, simulation {b!r}" for k, (a, b) in bad.items())
        raise ValueError(f"restore: the simulation is not set up like the checkpointed one ({detail}); "
                         f"build it as for the original run (same mesh, materials in the same "
                         f"order, same integrator and stage, same probes) before restoring")


def read(sim, path):
    """Restore `sim` from the newest checkpoint under `path` (collective)."""
    comm, p, grid = sim.comm, sim.particles, sim.grid
    folder, meta = _latest(path, comm)
    _check(sim, meta)
    files = [np.load(os.path.join(folder, f"rank{r}.npz"))
             for r in range(comm.rank, meta["ranks"], comm.size)]
    for name in meta["optional"]:
        a = files[0][f"p.{name}"] if files else None
        if not hasattr(p, name):
            p.add_field(name, () if a is None else a.shape[1:], np.float64 if a is None else a.dtype)
    for name in p.field_names():
        key = f"p.{name}"
        parts = [f[key] for f in files if key in f.files]
        if parts:
            arr = np.ascontiguousarray(np.concatenate(parts))
        else:                                  # no particles read on this rank
            arr = np.zeros((0,) + getattr(p, name).shape[1:], dtype=getattr(p, name).dtype)
        setattr(p, name, arr)
    p.version += 1
    p.cell, p.xi = grid.locate(p.x)            # the partition may differ from the saved one
    out_ids, _ = p.send_to_owners()
    if len(out_ids):
        raise RuntimeError(f"restore: particles {out_ids[:5].tolist()} lie outside the mesh")
    # nodal state (owned rows of every rank file), matched by node coordinates, ghosts included
    mine = _rows(grid.node_x)
    order = np.argsort(mine)
    targets = {"node.robin_u": sim.robin_u}
    targets.update({f"node.integrator.{k}": a for k, a in _integrator_arrays(sim.integrator).items()})
    for r in range(meta["ranks"]):
        f = np.load(os.path.join(folder, f"rank{r}.npz"))
        theirs = _rows(f["node_x"])
        pos = np.minimum(np.searchsorted(mine[order], theirs), len(mine) - 1)
        ok = mine[order][pos] == theirs
        local = order[pos[ok]]
        for key in f.files:                    # frictional boundaries: arrays per body
            if key.startswith("node.friction") and key not in targets:
                targets[key] = np.full(grid.n_nodes, -1, dtype=f[key].dtype)
        for key, target in targets.items():
            if key in f.files:
                target[local] = f[key][ok]
    for j, fr in enumerate(sim.frictions):
        prefix = f"node.friction{j}."
        fr.restore_arrays({k[len(prefix):]: a for k, a in targets.items() if k.startswith(prefix)})
    # probes: records so far (kept by the rank that recorded them; rewritten by serial writers)
    for k, pr in enumerate(sim.probes):
        rows = [r for f in files for r in f[f"probe.{k}"].tolist()]
        pr.rows = sorted(rows)
        pr._version = -1
        if pr.writer is not None:
            d = pr.data()
            pr.writer.close()
            pr.rewrite_csv(np.column_stack([d[c] for c in pr.columns]))
    sim.t, sim.step_count, sim.dt = meta["t"], meta["step_count"], meta["dt"]
    sim.stage_start, sim.initial_stress = meta["stage_start"], meta["initial_stress"]
    sim.gravity = np.asarray(meta["gravity"], dtype=np.float64)
    sim.removed_mass = meta.get("removed_mass", 0.0)     # on_leave="remove" (global sums)
    sim.removed_count = meta.get("removed_count", 0)
    if sim.splitting is not None:
        sim.splitting.sync_ids(sim)
        sim.splitting.count = meta.get("split_count", 0)
    restore = getattr(sim.integrator, "restore_arrays", None)
    if restore is not None:
        restore(sim)
    shared = os.path.join(folder, "integrator.npz")
    if hasattr(sim.integrator, "restore_state") and os.path.isfile(shared):
        with np.load(shared) as f:
            sim.integrator.restore_state({k: f[k] for k in f.files})
    for bc in sim.boundaries:                  # time-dependent boundary data (CompliantBase)
        if hasattr(bc, "on_restore"):
            bc.on_restore(sim)
    energy = os.path.join(folder, "energy.npz")
    if os.path.isfile(energy):                  # the monitor's work, E_0 and history
        work = sum((f["energy.work"] for f in files if "energy.work" in f.files), np.zeros(2))
        with np.load(energy) as f:
            sim._restore_energy({k: f[k] for k in f.files}, work)
    sim._n_alloc = -1                          # per-particle work arrays are re-sized
    return sim


class CheckpointMixin:
    """checkpoint, restore and restart of fenicsmpm.Simulation (inherited)."""

    def checkpoint(self, path, keep=1):
        """Save the complete state under directory `path` (collective; see fenicsmpm.checkpoint):
        particles with history variables, integrator and boundary state, stage, time, step and
        probe records. Written atomically; the `keep` newest checkpoints are kept."""
        if isinstance(keep, bool) or not (isinstance(keep, (int, np.integer)) and keep >= 1):
            raise ValueError(f"checkpoint: 'keep' must be a positive integer, got {keep!r}")
        return write(self, str(path), keep)

    def restore(self, path):
        """Load the newest checkpoint under `path` into this simulation, which must be set up
        as the checkpointed one (mesh, materials, integrator, stage, boundaries, probes)."""
        return read(self, str(path))

    @classmethod
    def restart(cls, path, build):
        """`build()` sets a simulation up as for the original run; it is restored from the
        newest checkpoint under `path` and returned, ready to `run` on."""
        sim = build()
        if not isinstance(sim, cls):
            raise TypeError(f"restart: 'build' must return a Simulation, got {type(sim).__name__}")
        return sim.restore(path)
