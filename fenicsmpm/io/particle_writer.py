"""Particle clouds for ParaView: one VTU piece per rank per step, plus PVTU/PVD.

Serial output for base path ``out/particles``::

    out/particles_000000.vtu, out/particles_000001.vtu, ..., out/particles.pvd

Parallel output (``comm.size > 1``)::

    out/particles_000000_r0.vtu, out/particles_000000_r1.vtu, ...
    out/particles_000000.pvtu (rank 0), out/particles.pvd (rank 0)

Only a few bytes of metadata per rank are exchanged (one ``allgather`` per
``write``); particle data is never gathered.
"""
from __future__ import annotations

import os
import sys
import xml.etree.ElementTree as ET

import numpy as np

__all__ = ["ParticleWriter", "normalize_point_array", "VTU_TYPES"]

# numpy dtype -> VTK XML type name (same table as meshio's VTU writer).
VTU_TYPES = {
    np.dtype(np.float32): "Float32",
    np.dtype(np.float64): "Float64",
    np.dtype(np.int8): "Int8",
    np.dtype(np.int16): "Int16",
    np.dtype(np.int32): "Int32",
    np.dtype(np.int64): "Int64",
    np.dtype(np.uint8): "UInt8",
    np.dtype(np.uint16): "UInt16",
    np.dtype(np.uint32): "UInt32",
    np.dtype(np.uint64): "UInt64",
}

_BYTE_ORDER = "LittleEndian" if sys.byteorder == "little" else "BigEndian"


def _norm_dtype(dtype) -> np.dtype:
    """Map an input dtype to one VTK understands (bool -> uint8, other floats -> float64)."""
    dtype = np.dtype(dtype)
    if dtype.kind == "b":
        return np.dtype(np.uint8)
    if dtype.kind in "iu":
        return np.dtype(dtype.name)  # native byte order
    if dtype.kind == "f":
        return np.dtype(np.float32) if dtype.itemsize == 4 else np.dtype(np.float64)
    raise TypeError(f"unsupported field dtype {dtype}")


def normalize_point_array(a, n: int) -> np.ndarray:
    """Return ``a`` as an (n,) or (n, k) array ready for VTU point data.

    (n,) scalars are kept, (n, 2) vectors are padded with zeros to (n, 3),
    (n, d, d) tensors with d <= 3 are embedded in 3x3 and flattened to (n, 9);
    other shapes are flattened to (n, -1).
    """
    a = np.asarray(a)
    dtype = _norm_dtype(a.dtype)
    if a.ndim == 0:
        raise ValueError("point field must have one row per particle, got a scalar")
    if a.shape[0] != n:
        raise ValueError(f"point field has {a.shape[0]} rows, expected {n}")
    a = np.ascontiguousarray(a, dtype=dtype)
    if a.ndim == 1:
        return a
    if a.ndim == 2:
        if a.shape[1] == 2:
            out = np.zeros((n, 3), dtype=dtype)
            out[:, :2] = a
            return out
        return a
    if a.ndim == 3 and a.shape[1] == a.shape[2] and a.shape[1] <= 3:
        d = a.shape[1]
        if d < 3:
            full = np.zeros((n, 3, 3), dtype=dtype)
            full[:, :d, :d] = a
            a = full
        return a.reshape(n, 9)
    return a.reshape(n, -1)


def _ncomp(a: np.ndarray) -> int:
    return 1 if a.ndim == 1 else int(a.shape[1])


def _write_xml(path: str, root: ET.Element) -> None:
    """Write an XML tree atomically (temp file + rename)."""
    if hasattr(ET, "indent"):
        ET.indent(root)
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(b'<?xml version="1.0"?>\n')
        f.write(ET.tostring(root))
        f.write(b"\n")
    os.replace(tmp, path)


class _SerialComm:
    """Stand-in used when ``comm`` is None."""

    rank = 0
    size = 1

    def Get_rank(self):
        return 0

    def Get_size(self):
        return 1

    def barrier(self):
        pass

    def allgather(self, obj):
        return [obj]


class ParticleWriter:
    """Write local particle clouds as VTU pieces with a PVD time collection.

    ``path`` is a base path without extension (``results/run/particles``).
    ``fields``: optional list of field names to write; None writes every field
    passed to :meth:`write`. ``write`` and the constructor are collective.
    """

    def __init__(self, path, comm, fields=None):
        self.comm = comm if comm is not None else _SerialComm()
        self.rank = self.comm.Get_rank()
        self.size = self.comm.Get_size()
        path = os.fspath(path)
        self.directory = os.path.dirname(path) or "."
        self.stem = os.path.basename(path)
        if not self.stem:
            raise ValueError(f"path {path!r} has no file stem")
        self.field_names = None if fields is None else [str(f) for f in fields]
        self.step = 0
        self.times: list[float] = []
        self.files: list[str] = []
        self.closed = False
        self._layout = None  # [(name, ncomp, dtype str)] of the last write
        if self.rank == 0:
            os.makedirs(self.directory, exist_ok=True)
        self.comm.barrier()

    # -- paths -------------------------------------------------------------
    @property
    def pvd_path(self) -> str:
        return os.path.join(self.directory, self.stem + ".pvd")

    def piece_name(self, step: int, rank: int | None = None) -> str:
        """File name (no directory) of one rank's piece for ``step``."""
        if self.size == 1:
            return f"{self.stem}_{step:06d}.vtu"
        r = self.rank if rank is None else rank
        return f"{self.stem}_{step:06d}_r{r}.vtu"

    def step_name(self, step: int) -> str:
        """File name (no directory) listed in the PVD for ``step``."""
        if self.size == 1:
            return self.piece_name(step)
        return f"{self.stem}_{step:06d}.pvtu"

    # -- writing -----------------------------------------------------------
    def write(self, t, x, fields):
        """Write one step: local points ``x`` (n, gdim) and point ``fields`` at time ``t``."""
        if self.closed:
            raise RuntimeError("ParticleWriter is closed")
        error = None
        arrays: dict[str, np.ndarray] = {}
        points = None
        try:
            points = self._points(x)
            n = points.shape[0]
            names = list(fields) if self.field_names is None else self.field_names
            for name in names:
                if name not in fields:
                    raise KeyError(f"field {name!r} missing")
                arrays[str(name)] = normalize_point_array(fields[name], n)
        except (ValueError, KeyError, TypeError) as e:
            error = f"rank {self.rank}: {e}"
        n = 0 if points is None else points.shape[0]
        local_sig = (n, [(k, _ncomp(a), a.dtype.str) for k, a in arrays.items()], error)
        sigs = self.comm.allgather(local_sig) if self.size > 1 else [local_sig]
        layout = self._check_layout(sigs)  # raises on every rank alike

        # Empty ranks adopt the common layout so all pieces declare the same arrays.
        if n == 0:
            arrays = {
                k: np.zeros((0,) if nc == 1 else (0, nc), dtype=np.dtype(dt))
                for k, nc, dt in layout
            }
        else:
            arrays = {k: arrays[k] for k, _, _ in layout}

        step = self.step
        piece = os.path.join(self.directory, self.piece_name(step))
        if n == 0:
            self._write_empty_piece(piece, arrays)
        else:
            self._write_piece(piece, points, arrays)

        self.times.append(float(t))
        self.files.append(self.step_name(step))
        if self.rank == 0:
            if self.size > 1:
                self._write_pvtu(step, layout)
            self._write_pvd()
        self.step += 1

    def _points(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.ndim == 1:
            x = x.reshape(-1, 1) if x.size else x.reshape(0, 3)
        if x.ndim != 2 or x.shape[1] > 3:
            raise ValueError(f"x must have shape (n, gdim<=3), got {x.shape}")
        if x.shape[1] == 3:
            return np.ascontiguousarray(x)
        pts = np.zeros((x.shape[0], 3))
        pts[:, : x.shape[1]] = x
        return pts

    def _check_layout(self, sigs):
        errors = [s[2] for s in sigs if s[2]]
        if errors:
            raise ValueError("ParticleWriter.write: " + "; ".join(errors))
        ref_rank = next((r for r, s in enumerate(sigs) if s[0] > 0), None)
        if ref_rank is None:
            # Every rank is empty: shapes are unknown, reuse the previous layout if
            # the names still match, else take rank 0's declaration.
            ref_rank, ref = 0, sigs[0][1]
            prev = self._layout
            if prev is not None and sorted(k for k, _, _ in prev) == sorted(k for k, _, _ in ref):
                ref = prev
        else:
            ref = sigs[ref_rank][1]
        ref_names = [k for k, _, _ in ref]
        for r, (n, sig, _) in enumerate(sigs):
            if sorted(k for k, _, _ in sig) != sorted(ref_names):
                raise ValueError(
                    f"ParticleWriter.write: field names differ between rank {ref_rank} "
                    f"{sorted(ref_names)} and rank {r} {sorted(k for k, _, _ in sig)}"
                )
            if n > 0 and sorted(sig) != sorted(ref):
                raise ValueError(
                    f"ParticleWriter.write: field shapes/dtypes differ between rank "
                    f"{ref_rank} {ref} and rank {r} {sig}"
                )
        self._layout = ref
        return ref

    @staticmethod
    def _write_piece(fname, points, arrays):
        import meshio

        n = points.shape[0]
        cells = [("vertex", np.arange(n, dtype=np.int64).reshape(n, 1))]
        mesh = meshio.Mesh(points, cells, point_data=arrays)
        meshio.write(fname, mesh, file_format="vtu")

    @staticmethod
    def _write_empty_piece(fname, arrays):
        # meshio cannot round-trip empty VTUs, so write a minimal valid one by hand.
        root = ET.Element("VTKFile", type="UnstructuredGrid", version="0.1",
                          byte_order=_BYTE_ORDER)
        grid = ET.SubElement(root, "UnstructuredGrid")
        piece = ET.SubElement(grid, "Piece", NumberOfPoints="0", NumberOfCells="0")
        pts = ET.SubElement(piece, "Points")
        ET.SubElement(pts, "DataArray", type="Float64", Name="Points",
                      NumberOfComponents="3", format="ascii").text = ""
        cells = ET.SubElement(piece, "Cells")
        for name, typ in (("connectivity", "Int64"), ("offsets", "Int64"), ("types", "UInt8")):
            ET.SubElement(cells, "DataArray", type=typ, Name=name, format="ascii").text = ""
        pd = ET.SubElement(piece, "PointData")
        for name, a in arrays.items():
            da = ET.SubElement(pd, "DataArray", type=VTU_TYPES[a.dtype], Name=name,
                               format="ascii")
            if a.ndim == 2:
                da.set("NumberOfComponents", str(a.shape[1]))
            da.text = ""
        _write_xml(fname, root)

    def _write_pvtu(self, step, layout):
        root = ET.Element("VTKFile", type="PUnstructuredGrid", version="0.1",
                          byte_order=_BYTE_ORDER)
        grid = ET.SubElement(root, "PUnstructuredGrid", GhostLevel="0")
        ppd = ET.SubElement(grid, "PPointData")
        for name, nc, dt in layout:
            ET.SubElement(ppd, "PDataArray", type=VTU_TYPES[np.dtype(dt)], Name=name,
                          NumberOfComponents=str(nc))
        ppts = ET.SubElement(grid, "PPoints")
        ET.SubElement(ppts, "PDataArray", type="Float64", Name="Points",
                      NumberOfComponents="3")
        for r in range(self.size):
            ET.SubElement(grid, "Piece", Source=self.piece_name(step, r))
        _write_xml(os.path.join(self.directory, self.step_name(step)), root)

    def _write_pvd(self):
        root = ET.Element("VTKFile", type="Collection", version="0.1",
                          byte_order=_BYTE_ORDER)
        coll = ET.SubElement(root, "Collection")
        for t, f in zip(self.times, self.files):
            ET.SubElement(coll, "DataSet", timestep=repr(t), group="", part="0", file=f)
        _write_xml(self.pvd_path, root)

    def resume(self, t_max):
        """Continue the collection already in `pvd_path` (collective): keep its data sets up to
        time t_max (those after it belong to a run that went on past a checkpoint and is being
        redone) and number the next step after the last kept one. Returns how many were kept."""
        kept = None
        if self.rank == 0:
            kept = ([], [], 0)
            try:
                coll = ET.parse(self.pvd_path).getroot().find("Collection")
            except (OSError, ET.ParseError):
                coll = None
            for ds in ([] if coll is None else coll.findall("DataSet")):
                t, f = float(ds.get("timestep")), ds.get("file")
                if t <= t_max + 1e-12 * max(abs(t_max), 1.0):
                    digits = f.rsplit(".", 1)[0].split("_")[-1]
                    kept[0].append(t)
                    kept[1].append(f)
                    kept = (kept[0], kept[1], max(kept[2], int(digits) + 1 if digits.isdigit() else 0))
        if self.size > 1:
            kept = self.comm.bcast(kept, root=0)
        self.times, self.files, self.step = list(kept[0]), list(kept[1]), int(kept[2])
        return len(self.times)

    def close(self):
        """Finish output (the PVD is already complete after every write)."""
        self.closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
