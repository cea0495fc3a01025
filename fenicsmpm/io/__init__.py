"""Input/output: Probe (a particle's time series) and Output (VTU/XDMF) of a run, and their
writers: particle VTU clouds, probe CSVs, progress line; particle rasters and profiles for
plots (reduced over the ranks, never gathered)."""
from .particle_writer import ParticleWriter
from .probe_writer import ProbeWriter, read_probe_csv
from .progress import Progress
from .probe import Probe
from .output import Output
from .raster import particle_raster, particle_profile, raster_shape

__all__ = ["ParticleWriter", "ProbeWriter", "read_probe_csv", "Progress", "Probe", "Output",
           "particle_raster", "particle_profile", "raster_shape"]
