"""Particle fields binned onto a fixed raster for plots, reduced over the MPI ranks.

particle_raster bins the local particles' values into the cells of a fixed nx x ny raster of
a rectangle and reduces the raster over the ranks: per cell the mean (sum / count), the
maximum, the minimum or the particle count. particle_profile does the same with n bins along
one coordinate (a row or column profile, e.g. the free-surface height: max y per x bin). Only
the raster travels (one MPI Reduce to rank 0), so memory and traffic are O(raster), whatever
the number of particles: a plot never gathers the particles on one rank."""
import numpy as np
from mpi4py import MPI

__all__ = ["particle_raster", "particle_profile", "raster_shape"]

REDUCE = ("mean", "max", "min", "count")


def _check_bounds(pair, what, bounds):
    """(lo, hi) of pair as floats; a ValueError naming 'bounds' (laid out as `what`) unless
    finite with lo < hi."""
    try:
        lo, hi = (float(b) for b in pair)
    except (TypeError, ValueError):
        lo = hi = np.nan
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"'bounds' must be {what}, finite with min < max, got {bounds!r}")
    return lo, hi


def _positive_int(n):
    return not isinstance(n, bool) and isinstance(n, (int, np.integer)) and n >= 1


def _bin(coord, lo, hi, n):
    """Bin index of each coordinate in n equal bins of [lo, hi] (hi in the last bin) and
    whether it lies inside (NaN lies outside)."""
    inside = (coord >= lo) & (coord <= hi)
    k = np.minimum(((np.where(inside, coord, lo) - lo) * (n / (hi - lo))).astype(np.int64), n - 1)
    return k, inside


def _reduce(comm, flat, values, size, reduce):
    """Per-bin reduction of values at the bin indices flat, over the ranks, on rank 0."""
    if reduce in ("mean", "count"):                 # row 0: counts, row 1: sums
        rows = [np.bincount(flat, minlength=size).astype(np.float64)]
        if reduce == "mean":
            rows.append(np.bincount(flat, weights=values, minlength=size))
        local = np.stack(rows)
        op = MPI.SUM
    else:
        fill = -np.inf if reduce == "max" else np.inf
        local = np.full(size, fill)
        (np.maximum if reduce == "max" else np.minimum).at(local, flat, values)
        op = MPI.MAX if reduce == "max" else MPI.MIN
    out = np.empty_like(local) if comm.rank == 0 else None
    comm.Reduce(local, out, op=op, root=0)
    if comm.rank != 0:
        return None
    if reduce == "count":
        return out[0]
    if reduce == "mean":
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(out[0] > 0, out[1] / out[0], np.nan)
    return np.where(np.isinf(out), np.nan, out)


def _check_values(comm, values, n, reduce):
    """values as a float array of length n (None allowed with reduce="count"). The check is
    reduced over the ranks, so a length mismatch on one rank raises on every rank."""
    if reduce not in REDUCE:
        raise ValueError(f"'reduce' must be one of {REDUCE}, got {reduce!r}")
    if values is None and reduce == "count":
        return np.zeros(n)
    values = None if values is None else np.asarray(values, dtype=np.float64).reshape(-1)
    bad = values is None or len(values) != n
    if comm.allreduce(int(bad), op=MPI.MAX):
        got = "None" if values is None else f"{len(values)} values"
        raise ValueError(f"'values' must hold one value per particle ({n} here; None only with "
                         f"reduce='count'), got {got}" + ("" if bad else " on another rank"))
    return values


def raster_shape(bounds, size):
    """(nx, ny): the cell counts of a raster of `bounds` ((xmin, xmax), (ymin, ymax)) with
    cells of about `size` on a side (at least one per axis), for particle_raster."""
    return tuple(max(1, int(round((hi - lo) / size))) for lo, hi in bounds)


def particle_raster(comm, x, values, bounds, shape, reduce="mean"):
    """The particles' values binned onto a fixed raster: an (nx, ny) array on rank 0, None on
    the other ranks. Collective: every rank of comm calls it with its local particles.

    x       (n, d) local particle positions, d >= 2; the raster uses x[:, 0] and x[:, 1]
    values  (n,) local values (may be None with reduce="count")
    bounds  ((xmin, xmax), (ymin, ymax)): the rectangle, cut into nx x ny equal cells;
            cell [i, j] spans xmin + i dx <= x < xmin + (i + 1) dx (dx = (xmax - xmin) / nx)
            and the same in y; the upper bounds belong to the last cells, and particles
            outside the rectangle are left out
    shape   (nx, ny), positive integers
    reduce  per cell, over all particles of all ranks in it:
              "mean"   sum of values / number of particles (sums and counts reduced with
                       MPI.SUM)
              "max"    largest value (MPI.MAX), "min" smallest (MPI.MIN)
              "count"  number of particles (0 where empty, never NaN): `> 0` is the mask
                       of the cells that hold material
            Empty cells are NaN for "mean", "max" and "min".

    Index [i, j] is x bin i, y bin j, so plot it transposed:
        ax.imshow(r.T, origin="lower", extent=(xmin, xmax, ymin, ymax))
    (NaN cells are not drawn). Memory and MPI traffic are O(nx ny), independent of the
    number of particles. Bad input raises a ValueError naming the parameter, on every rank."""
    try:
        nx, ny = shape
    except (TypeError, ValueError):
        nx = ny = None
    if not (_positive_int(nx) and _positive_int(ny)):
        raise ValueError(f"'shape' must be two positive integers (nx, ny), got {shape!r}")
    nx, ny = int(nx), int(ny)
    what = "((xmin, xmax), (ymin, ymax))"
    try:
        bx, by = bounds
    except (TypeError, ValueError):
        bx = by = None
    (x0, x1), (y0, y1) = _check_bounds(bx, what, bounds), _check_bounds(by, what, bounds)
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] < 2:
        raise ValueError(f"'x' must be an (n, d) array of positions with d >= 2, "
                         f"got shape {x.shape}")
    values = _check_values(comm, values, len(x), reduce)
    i, in_x = _bin(x[:, 0], x0, x1, nx)
    j, in_y = _bin(x[:, 1], y0, y1, ny)
    keep = in_x & in_y
    out = _reduce(comm, (i * ny + j)[keep], values[keep], nx * ny, reduce)
    return None if out is None else out.reshape(nx, ny)


def particle_profile(comm, s, values, bounds, n, reduce="mean"):
    """The particles' values binned along one coordinate s: an (n,) array on rank 0, None on
    the other ranks (collective, like particle_raster, with the same `reduce` and NaN rules).

    s       (n_p,) local coordinates (x[:, 0] for columns, a height for rows)
    values  (n_p,) local values (may be None with reduce="count")
    bounds  (smin, smax), cut into n equal bins (the upper bound in the last, particles
            outside left out)
    Example: the free-surface height per x column,
        particle_profile(comm, x[:, 0], x[:, 1], (xmin, xmax), nx, reduce="max")."""
    if not _positive_int(n):
        raise ValueError(f"'n' must be a positive integer, got {n!r}")
    n = int(n)
    lo, hi = _check_bounds(bounds, "(smin, smax)", bounds)
    s = np.asarray(s, dtype=np.float64)
    if s.ndim != 1:
        raise ValueError(f"'s' must be a 1D array of coordinates, got shape {s.shape}")
    values = _check_values(comm, values, len(s), reduce)
    k, keep = _bin(s, lo, hi, n)
    return _reduce(comm, k[keep], values[keep], n, reduce)
