"""The strike-log format (SPEC.md) and mesh and point-cloud IO.

The bottom layer of recon: it imports none of the other packages.
"""

from formats.errors import MeshFormatError, ReconError, StrikeLogError
from formats.geometry import Cloud, Mesh
from formats.strike_log import (
    FORMAT_NAME,
    FORMAT_VERSION,
    SIGMA3_PER_SIGMA,
    SensorErrors,
    SensorInfo,
    Shots,
    StrikeChunk,
    StrikeLog,
    StrikeLogWriter,
    TruthStrikes,
    sigma_from_sigma3,
)

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
