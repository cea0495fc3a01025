"""A single self-rewriting progress line for long runs (rank 0, TTY only)."""
from __future__ import annotations

import sys
import time

__all__ = ["Progress", "format_duration"]


def format_duration(seconds: float) -> str:
    """``mm:ss`` below one hour, ``h:mm:ss`` above, ``--:--`` if unknown."""
    if seconds is None or not seconds == seconds or seconds < 0 or seconds > 1e8:
        return "--:--"
    s = int(round(seconds))
    h, rem = divmod(s, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except Exception:
        return False


class Progress:
    """Progress line ``step i/N (p %)  t = ..  wall mm:ss  ETA mm:ss``.

    Prints on rank 0 only; only to a TTY unless ``force=True``
    (``force=False`` never prints). Silent for the first ``delay`` seconds,
    then refreshed at most every ``min_interval`` seconds. ``update`` makes no
    MPI calls. ``comm`` may be None (serial).
    """

    def __init__(self, total_steps, t_end, comm, stream=None, min_interval=0.5,
                 force=None, delay=3.0, note=""):
        self.total_steps = int(total_steps) if total_steps else 0
        self.t_end = float(t_end) if t_end else 0.0
        self.stream = sys.stderr if stream is None else stream
        self.min_interval = float(min_interval)
        self.delay = float(delay)
        self.note = f"  {note}" if note else ""
        rank = comm.Get_rank() if comm is not None else 0
        if force is None:
            self.enabled = rank == 0 and _isatty(self.stream)
        else:
            self.enabled = rank == 0 and bool(force)
        self._t0 = time.monotonic()
        self._last = None
        self._width = 0
        self.printed = False
        self.closed = False

    def _fraction(self, step, t):
        if self.t_end > 0 and t is not None:
            return min(max(float(t) / self.t_end, 0.0), 1.0)
        if self.total_steps > 0:
            return min(max(step / self.total_steps, 0.0), 1.0)
        return None

    def format(self, step, t, elapsed) -> str:
        """The progress line for ``step`` / ``t`` after ``elapsed`` wall seconds."""
        frac = self._fraction(step, t)
        if self.total_steps > 0:
            head = f"step {step}/{self.total_steps}"
        else:
            head = f"step {step}"
        if frac is not None:
            head += f" ({100.0 * frac:.1f} %)"
        eta = elapsed * (1.0 - frac) / frac if frac else None
        return (f"{head}  t = {float(t):.1e} s  wall {format_duration(elapsed)}"
                f"  ETA {format_duration(eta)}{self.note}")

    def update(self, step, t):
        """Maybe rewrite the progress line (cheap no-op when disabled)."""
        if not self.enabled or self.closed:
            return
        now = time.monotonic()
        elapsed = now - self._t0
        if elapsed < self.delay:
            return
        if self._last is not None and now - self._last < self.min_interval:
            return
        self._last = now
        line = self.format(step, t, elapsed)
        pad = max(self._width - len(line), 0)
        self._width = len(line)
        self.stream.write("\r" + line + " " * pad)
        self.stream.flush()
        self.printed = True

    def close(self):
        """End the line with a newline if anything was printed."""
        if self.closed:
            return
        self.closed = True
        if self.printed:
            self.stream.write("\n")
            self.stream.flush()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
