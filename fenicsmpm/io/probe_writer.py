"""Probe time series written as CSV by the single rank that owns the probe."""
from __future__ import annotations

import math
import os

import numpy as np

__all__ = ["ProbeWriter", "read_probe_csv"]


def _fmt(v) -> str:
    """Format one value with round-trip precision."""
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    f = float(v)
    if math.isnan(f):
        return "nan"
    if math.isinf(f):
        return "inf" if f > 0 else "-inf"
    return "%.17g" % f


class ProbeWriter:
    """Append rows of a probe time series to a CSV file.

    No collective calls anywhere: the file is created lazily by the first
    ``write_row`` on whichever rank calls it (normally ``root``, the probe's
    owner). ``comm`` is only used to know the calling rank. Rows are
    line-buffered, so a crash loses at most the row being written.
    """

    def __init__(self, path, columns, comm=None, root=0, append=False):
        self.path = os.fspath(path)
        self.columns = [str(c) for c in columns]
        if not self.columns:
            raise ValueError("ProbeWriter needs at least one column")
        if any("," in c or "\n" in c for c in self.columns):
            raise ValueError("column names must not contain ',' or newlines")
        self.comm = comm
        self.root = root
        self.rank = comm.Get_rank() if comm is not None else 0
        self._file = None
        self.append = bool(append)       # add rows to an existing file (header written before)
        self.rows_written = 0

    @property
    def is_root(self) -> bool:
        return self.rank == self.root

    def _open(self):
        parent = os.path.dirname(self.path)
        if parent:
            os.makedirs(parent, exist_ok=True)
        self._file = open(self.path, "a" if self.append else "w", buffering=1, encoding="ascii",
                          newline="\n")
        if not self.append:
            self._file.write(",".join(self.columns) + "\n")

    def write_row(self, values):
        """Write one row: a sequence in column order, or a dict column -> value."""
        if isinstance(values, dict):
            missing = [c for c in self.columns if c not in values]
            if missing:
                raise KeyError(f"missing probe columns {missing}")
            values = [values[c] for c in self.columns]
        else:
            values = list(np.ravel(np.asarray(values, dtype=object)))
        if len(values) != len(self.columns):
            raise ValueError(f"expected {len(self.columns)} values, got {len(values)}")
        if self._file is None:
            self._open()
        self._file.write(",".join(_fmt(v) for v in values) + "\n")
        self._file.flush()
        self.rows_written += 1

    def rewrite(self, rows):
        """Start the file afresh (header, then `rows`, each a sequence or a dict) and keep it
        open for more rows, e.g. after a restore (this rank only; not collective)."""
        self.close()
        append, self.append = self.append, False
        self._open()
        self.append = append
        for row in rows:
            self.write_row(row)

    def close(self):
        """Close the file if this rank opened it (not collective)."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_probe_csv(path) -> dict[str, np.ndarray]:
    """Read a probe CSV into ``{column: float64 array}``; skips a truncated last line."""
    with open(path, "r", encoding="ascii") as f:
        header = f.readline().strip()
        if not header:
            return {}
        columns = header.split(",")
        rows = []
        for line in f:
            if not line.endswith("\n"):
                break  # incomplete row from an interrupted run
            parts = line.strip().split(",")
            if len(parts) != len(columns):
                continue
            rows.append([float(p) for p in parts])
    data = np.array(rows, dtype=np.float64).reshape(len(rows), len(columns))
    return {c: data[:, i].copy() for i, c in enumerate(columns)}
