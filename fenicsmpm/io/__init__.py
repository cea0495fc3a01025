"""Input/output: Probe (a particle's time series) and Output (VTU/XDMF) of a run, and their
writers: particle VTU clouds, probe CSVs, progress line."""
from .particle_writer import ParticleWriter
from .probe_writer import ProbeWriter, read_probe_csv
from .progress import Progress
from .probe import Probe
from .output import Output

__all__ = ["ParticleWriter", "ProbeWriter", "read_probe_csv", "Progress", "Probe", "Output"]
