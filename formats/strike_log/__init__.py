"""Reader and writer of strike logs, format v1 (formats/SPEC.md).

``schema``: names, layout, the records (``SensorInfo``, ``SensorErrors``, ``Shots``, ...) and the
shared checks; ``writer``: ``StrikeLogWriter``; ``reader``: ``StrikeLog``, and ``follow`` for a
log being written.
"""

from formats.strike_log.reader import LiveStrikeLog, StrikeLog, follow
from formats.strike_log.schema import (
    COMPRESSIONS,
    DEFAULT_COMPRESSION,
    FORMAT_NAME,
    FORMAT_VERSION,
    LIVE_COMMITTED,
    LOG_SUFFIXES,
    QUATERNION_NORM_TOLERANCE,
    READ_CHUNK_ROWS,
    SHOT_CHUNK_ROWS,
    SIGMA3_PER_SIGMA,
    STRIKE_CHUNK_ROWS,
    SensorErrors,
    SensorInfo,
    Shots,
    StrikeChunk,
    TruthStrikes,
    angles_to_directions,
    compression_filters,
    directions_to_angles,
    estimate_log_bytes,
    sigma_from_sigma3,
)
from formats.strike_log.writer import StrikeLogWriter

__all__ = [
    "COMPRESSIONS",
    "DEFAULT_COMPRESSION",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "LIVE_COMMITTED",
    "LOG_SUFFIXES",
    "QUATERNION_NORM_TOLERANCE",
    "READ_CHUNK_ROWS",
    "SHOT_CHUNK_ROWS",
    "SIGMA3_PER_SIGMA",
    "STRIKE_CHUNK_ROWS",
    "LiveStrikeLog",
    "SensorErrors",
    "SensorInfo",
    "Shots",
    "StrikeChunk",
    "StrikeLog",
    "StrikeLogWriter",
    "TruthStrikes",
    "angles_to_directions",
    "compression_filters",
    "directions_to_angles",
    "estimate_log_bytes",
    "follow",
    "sigma_from_sigma3",
]
