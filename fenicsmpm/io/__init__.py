"""Lightweight output helpers: particle VTU clouds, probe CSVs, progress line."""
from .particle_writer import ParticleWriter
from .probe_writer import ProbeWriter, read_probe_csv
from .progress import Progress

__all__ = ["ParticleWriter", "ProbeWriter", "read_probe_csv", "Progress"]
