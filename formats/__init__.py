"""The strike-log format (SPEC.md) and mesh and point-cloud IO.

The bottom layer of recon: it imports none of the other packages.
"""

from formats.errors import MeshFormatError, ReconError, StrikeLogError
from formats.geometry import Cloud, Mesh

# The strike-log names load h5py: they are imported on first use (PEP 562), so reading a mesh or
# a cloud file does not pay for HDF5.
_STRIKE_LOG_NAMES = ("FORMAT_NAME", "FORMAT_VERSION", "SIGMA3_PER_SIGMA", "SensorErrors",
                     "SensorInfo", "Shots", "StrikeChunk", "StrikeLog", "StrikeLogWriter",
                     "TruthStrikes", "sigma_from_sigma3")


def __getattr__(name: str):
    if name in _STRIKE_LOG_NAMES:
        from formats import strike_log

        return getattr(strike_log, name)
    raise AttributeError(f"module 'formats' has no attribute {name!r}")


__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "SIGMA3_PER_SIGMA",
    "Cloud",
    "Mesh",
    "MeshFormatError",
    "ReconError",
    "SensorErrors",
    "SensorInfo",
    "Shots",
    "StrikeChunk",
    "StrikeLog",
    "StrikeLogError",
    "StrikeLogWriter",
    "TruthStrikes",
    "sigma_from_sigma3",
]
