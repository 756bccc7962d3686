"""Point clouds with per-point attributes: written as PLY, LAS/LAZ and HDF5, read from those and
from the files other tools write (ASCII PLY, ``.xyz``/``.asc``/``.txt``, ``.pcd``, ``.e57``).

Attribute names recon uses (any others are kept as they are):

=====================  =========  ==============================================================
name                   dtype      meaning
=====================  =========  ==============================================================
``time``               float64    shot time [s] since the start of the campaign
``et``                 float64    shot time as SPICE ET [s, TDB past J2000] (altimetry products)
``shot``, ``beam``     uint32     shot and beam index in the source strike log
``range``              float64    measured range [m]
``azimuth``,           float64    measured beam direction in the sensor frame S [rad]
``elevation``                     (formats/SPEC.md: zero on the boresight)
``view_x/y/z``         float64    sensor position in the cloud's frame [m] (orients normals)
``nx``, ``ny``, ``nz`` float64    unit normal
=====================  =========  ==============================================================

Every file written says its frame (``body``, ``inertial`` or ``unknown``), units (metres), source
log and the recon version (``formats.geometry.file_metadata``), and the units of every attribute
column; reading gives the cloud that frame back. Files that record no frame (those of other
tools, text, PCD, E57) are read in the frame ``unknown``.

Formats written
---------------
``.ply``  binary little-endian; x, y, z, then nx, ny, nz, then every other attribute as the
    property ``scalar_NAME`` (CloudCompare's convention, which it imports as scalar fields; the
    reader strips the prefix); integers as int32 (formats/ply.py). Metadata in ``comment`` lines.
``.las``/``.laz``  LAS 1.4 point format 6 (ASPRS R15): coordinates quantised to ``LAS_SCALE_M``
    with zero offset; every point return 1 of 1; ``time`` in ``gps_time`` (seconds since the start
    of the campaign, not GPS time); ``beam`` in ``point_source_id``; ``azimuth`` in ``scan_angle``
    (0.006 degree steps); every attribute but ``time`` and ``beam`` also as a described
    extra-bytes dimension (lossless), its description ending in its unit (``range [m]``). The
    frame, as a WKT ``LOCAL_CS`` in metres (global encoding WKT bit set), and ``file_metadata``
    with the unit of every attribute (``units_of``) as JSON in the VLR ``recon``/1. Intensity
    stays 0: a strike log records no return amplitude.
``.h5``   HDF5 with root attributes ``format = "recon-point-cloud"``, ``format_version = 1`` and
    ``file_metadata``; dataset ``points`` (n, 3) float64 and one (n,) dataset per attribute under
    ``attributes/``, each with a ``units`` attribute (``unknown`` for an attribute recon does not
    know; ``frame`` too on coordinates), chunked and resizable.

Formats read as well
--------------------
``.xyz``, ``.asc``, ``.txt``  text, one point per line: x y z, optionally nx ny nz (6 columns),
    separated by spaces, tabs or commas; ``#`` and ``//`` lines are comments, and a comment line
    naming every column (CloudCompare's ``//X Y Z Nx Ny Nz``) names them. Other columns are kept
    as ``column_N`` (1-based), e.g. a HELIOS++ ``.xyz``'s intensity and GPS time.
``.xyzn``  text, exactly x y z nx ny nz per line (Open3D's point-with-normal format).
``.csv``  comma-separated with a header row naming the columns, ``x``, ``y``, ``z`` among them
    (any case, any order), ``nx``, ``ny``, ``nz`` read as normals and every other column kept
    under its name; a file whose first row is numbers is read as ``.xyz``.
``.pcd``  through Open3D's tensor reader (positions, normals and every scalar field).
``.e57``  through pye57 (libE57Format), every scan merged in the file's frame with its pose
    applied; intensity kept.
"""

from __future__ import annotations

import contextlib
import io
import json
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from formats.atomic import AtomicWriter
from formats.errors import InputError
from formats.geometry import (
    NORMAL_ATTRIBUTES,
    UNKNOWN,
    Cloud,
    check_extent,
    file_metadata,
    frame_of,
)
from formats.hdf5_check import check_hdf5, check_whole, trust
from formats.paths import check_source
from formats.ply import PlyWriter, binary_vertex_layout, read_ply

WRITE_SUFFIXES = (".ply", ".las", ".laz", ".h5")
TEXT_SUFFIXES = (".xyz", ".asc", ".txt", ".xyzn", ".csv")
CLOUD_SUFFIXES = (*WRITE_SUFFIXES, *TEXT_SUFFIXES, ".pcd", ".e57")
CLOUD_FORMAT_NAME = "recon-point-cloud"
CLOUD_FORMAT_VERSION = 1
# LAS stores int32 coordinates: 0.1 mm steps reach +-214 km, beyond any target we image.
LAS_SCALE_M = 1e-4
# LAS 1.4 scan_angle: int16 in steps of 0.006 degrees, -30000..30000 (ASPRS R15, point format 6).
LAS_SCAN_ANGLE_STEP_DEG = 0.006
# Units and a description of known attributes; a LAS extra-bytes description (32 characters)
# is the description and the unit in brackets (``_las_description``).
ATTRIBUTE_INFO = {
    "time": ("s", "shot time since start"),
    "et": ("s", "ET, TDB s past J2000"),
    "shot": ("1", "shot index in source log"),
    "beam": ("1", "beam index in source log"),
    "range": ("m", "measured range"),
    "azimuth": ("rad", "measured azimuth in S"),
    "elevation": ("rad", "measured elevation in S"),
    "view_x": ("m", "sensor x, cloud frame"),
    "view_y": ("m", "sensor y, cloud frame"),
    "view_z": ("m", "sensor z, cloud frame"),
    "nx": ("1", "unit normal x"),
    "ny": ("1", "unit normal y"),
    "nz": ("1", "unit normal z"),
}
# Attributes that are coordinates in the cloud's frame (HDF5 datasets say the frame too).
_FRAMED = ("view_x", "view_y", "view_z", *NORMAL_ATTRIBUTES)
# CloudCompare imports a PLY property as a scalar field when its name has this prefix.
_PLY_SCALAR_PREFIX = "scalar_"
# The WKT of a LAS file's frame: a local engineering frame in metres (not a map projection).
_LAS_WKT = ('LOCAL_CS["recon {frame} frame ({long})",LOCAL_DATUM["{long}",0],'
            'UNIT["metre",1,AUTHORITY["EPSG","9001"]],AXIS["X",OTHER],AXIS["Y",OTHER],'
            'AXIS["Z",OTHER]]')
_FRAME_NAMES = {"body": "target body frame B, origin at the target centre",
                "inertial": "target-centred inertial frame I",
                UNKNOWN: "frame not recorded by the source"}
_LAS_VLR_USER, _LAS_VLR_RECORD = "recon", 1
# Attribute -> the standard LAS dimension that holds it exactly (not repeated as extra bytes).
_LAS_STANDARD = {"time": "gps_time", "beam": "point_source_id"}
_CHUNK_ROWS = 65_536


def units_of(name: str) -> str:
    """The unit of attribute ``name`` (``ATTRIBUTE_INFO``), ``"unknown"`` for others."""
    return ATTRIBUTE_INFO.get(name, (UNKNOWN, ""))[0]


def _las_description(name: str) -> str:
    """A LAS extra-bytes description (at most 32 characters) that ends in the unit."""
    unit = f" [{units_of(name)}]"
    return ATTRIBUTE_INFO.get(name, ("", name))[1][:32 - len(unit)] + unit


def _suffix(path: Path, allowed: tuple[str, ...] = CLOUD_SUFFIXES) -> str:
    suffix = path.suffix.lower()
    if suffix not in allowed:
        raise InputError(f"{path}: unknown point-cloud suffix {path.suffix!r} (expected one "
                              f"of {', '.join(allowed)})")
    return suffix


# --------------------------------------------------------------------------- writers


def _ply_name(name: str) -> str:
    return name if name in NORMAL_ATTRIBUTES else _PLY_SCALAR_PREFIX + name


class _PlyCloud(PlyWriter):
    """Binary PLY: x, y, z then every attribute as a vertex property (``scalar_NAME``)."""

    def __init__(self, path, n_points: int, dtypes: dict[str, np.dtype], metadata: dict):
        xyz = {"x": np.float64, "y": np.float64, "z": np.float64}
        normals = {k: dtypes[k] for k in NORMAL_ATTRIBUTES if k in dtypes}
        rest = {_ply_name(k): v for k, v in dtypes.items() if k not in normals}
        super().__init__(path, n_points, xyz | normals | rest, metadata=metadata)

    def write(self, points: np.ndarray, attributes: dict[str, np.ndarray]) -> None:
        points = np.asarray(points, dtype=np.float64)
        super().write({"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}
                      | {_ply_name(k): v for k, v in attributes.items()})


class _H5Cloud(AtomicWriter):
    """recon's HDF5 cloud: ``points`` and one dataset per attribute, chunked and resizable."""

    missing_dir_error = InputError

    def __init__(self, path, n_points: int, dtypes: dict[str, np.dtype], metadata: dict):
        import h5py

        super().__init__(path, suffix=".h5")
        self.n_points, self.dtypes, self._written = int(n_points), dtypes, 0
        self._h5 = h5py.File(self.temporary, "w")
        self._h5.attrs.update({"format": CLOUD_FORMAT_NAME,
                               "format_version": np.int64(CLOUD_FORMAT_VERSION)} | metadata)
        rows = max(1, min(_CHUNK_ROWS, self.n_points))
        points = self._h5.create_dataset("points", shape=(0, 3), maxshape=(None, 3),
                                         dtype=np.float64, chunks=(rows, 3))
        points.attrs.update({"units": metadata["units"], "frame": metadata["frame"]})
        g = self._h5.create_group("attributes")
        # The datasets stay open: reopening one per write empties its chunk cache each time,
        # and after a full disk every dropped handle fails to flush and prints a traceback.
        self._datasets = [points]
        for name, dtype in dtypes.items():
            ds = g.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(rows,))
            ds.attrs["units"] = units_of(name)
            if name in _FRAMED:
                ds.attrs["frame"] = metadata["frame"]
            self._datasets.append(ds)

    def write(self, points: np.ndarray, attributes: dict[str, np.ndarray]) -> None:
        self._check()
        n = len(points)
        for ds, values in zip(self._datasets, [points, *(attributes[k] for k in self.dtypes)],
                              strict=True):
            ds.resize(self._written + n, axis=0)
            ds[self._written:] = values
        self._written += n
        self._wrote(n * (24 + sum(np.dtype(d).itemsize for d in self.dtypes.values())))

    def _flush(self) -> None:
        self._h5.flush()

    def _published(self) -> None:
        trust(self.path)   # our own file: readers need not walk it (formats/hdf5_check.py)

    def _finish(self) -> None:
        self._h5.close()
        if self._written != self.n_points:
            raise InputError(f"{self.path}: wrote {self._written} points, expected "
                                  f"{self.n_points}")

    def _release(self) -> None:
        self._h5.close()


class _LasCloud(AtomicWriter):
    """LAS 1.4 point format 6 (LAZ when the suffix says so), ASPRS conventions: see the module
    docstring."""

    missing_dir_error = InputError

    def __init__(self, path, n_points: int, dtypes: dict[str, np.dtype], metadata: dict):
        import laspy
        from laspy.vlrs.known import WktCoordinateSystemVlr

        suffix = Path(path).suffix.lower()
        super().__init__(path, suffix=suffix)
        self.n_points, self._written = int(n_points), 0
        header = laspy.LasHeader(point_format=6, version="1.4")
        header.scales = np.full(3, LAS_SCALE_M)
        header.offsets = np.zeros(3)
        header.global_encoding.wkt = True
        header.system_identifier = "recon strike-log registration"
        header.generating_software = f"recon {metadata['recon_version']}"[:32]
        extra = [laspy.ExtraBytesParams(name=k, type=v, description=_las_description(k))
                 for k, v in dtypes.items() if k not in _LAS_STANDARD]
        if extra:
            header.add_extra_dims(extra)
        frame = metadata["frame"]
        header.vlrs.append(WktCoordinateSystemVlr(
            _LAS_WKT.format(frame=frame, long=_FRAME_NAMES[frame])))
        described = metadata | {"dimensions": {v: k for k, v in _LAS_STANDARD.items()
                                               if k in dtypes},
                                "attribute_units": {k: units_of(k) for k in dtypes}}
        if "azimuth" in dtypes:
            described["dimensions"]["scan_angle"] = (
                f"azimuth in steps of {LAS_SCAN_ANGLE_STEP_DEG} deg")
        header.vlrs.append(laspy.VLR(_LAS_VLR_USER, _LAS_VLR_RECORD, "recon frame and units",
                                     json.dumps(described).encode()))
        self._las = laspy.open(self.temporary, mode="w", header=header,
                               do_compress=suffix == ".laz")

    def write(self, points: np.ndarray, attributes: dict[str, np.ndarray]) -> None:
        import laspy

        self._check()
        points = np.asarray(points, dtype=np.float64)
        if len(points) and np.abs(points).max() > np.iinfo(np.int32).max * LAS_SCALE_M:
            raise InputError(f"{self.path}: coordinates beyond +-214 km do not fit LAS at "
                                  f"{LAS_SCALE_M} m resolution")
        record = laspy.ScaleAwarePointRecord.zeros(len(points), header=self._las.header)
        record.x, record.y, record.z = points[:, 0], points[:, 1], points[:, 2]
        record.return_number[:] = 1
        record.number_of_returns[:] = 1
        if "beam" in attributes and len(points) and np.max(attributes["beam"]) > 65_535:
            raise InputError(f"{self.path}: beam indices beyond 65535 do not fit LAS "
                                  "point_source_id")
        if "azimuth" in attributes:
            steps = np.rad2deg(attributes["azimuth"]) / LAS_SCAN_ANGLE_STEP_DEG
            record.scan_angle = np.clip(np.round(steps), -30_000, 30_000).astype(np.int16)
        for name, values in attributes.items():
            record[_LAS_STANDARD.get(name, name)] = values
        self._las.write_points(record)
        self._written += len(points)

    def _finish(self) -> None:
        self._las.close()
        if self._written != self.n_points:
            raise InputError(f"{self.path}: wrote {self._written} points, expected "
                                  f"{self.n_points}")

    def _release(self) -> None:
        self._las.close()


_WRITERS = {".ply": _PlyCloud, ".h5": _H5Cloud, ".las": _LasCloud, ".laz": _LasCloud}


def open_cloud_writer(path, n_points: int, dtypes: dict[str, np.dtype], *, frame: str = "body",
                      source=None) -> AtomicWriter:
    """A streaming point-cloud writer; the suffix of ``path`` picks PLY, LAS, LAZ or HDF5.

    Use it as a context manager and call ``write(points, attributes)`` with blocks of
    ``(n, 3)`` float64 points [m] and their ``(n,)`` attribute values. The file appears, under
    ``path``, only when exactly ``n_points`` were written and the writer closed cleanly.

    Parameters
    ----------
    path : str or Path
    n_points : int
        Total number of points that will be written (PLY and LAS headers need it).
    dtypes : dict of str to numpy dtype
        The attribute columns, in order.
    frame : {"body", "inertial"}
        Frame of the points, recorded in the file.
    source : str or Path, optional
        The strike log the points come from, recorded in the file.
    """
    path = Path(path)
    writer = _WRITERS[_suffix(path, WRITE_SUFFIXES)]
    return writer(path, n_points, {k: np.dtype(v) for k, v in dtypes.items()},
                  file_metadata(frame, source=source))


def write_cloud(path, cloud: Cloud, *, source=None) -> Path:
    """Write a whole point cloud, recording its frame (and ``source``); the suffix of ``path``
    picks PLY, LAS, LAZ or HDF5."""
    dtypes = {k: np.asarray(v).dtype for k, v in cloud.attributes.items()}
    with open_cloud_writer(path, len(cloud), dtypes, frame=cloud.frame, source=source) as writer:
        writer.write(cloud.points, cloud.attributes)
    return Path(path)


# --------------------------------------------------------------------------- readers


def read_cloud(path) -> Cloud:
    """Read a point cloud with its attributes and recorded frame (PLY, LAS/LAZ, recon's HDF5
    cloud, ``.xyz``/``.asc``/``.txt``, ``.pcd``, ``.e57``).

    A PLY mesh is read as the cloud of its vertices. Files that record no frame (those of other
    tools) are read in the frame ``"unknown"``. Coordinates beyond ``MAX_COORDINATE_M`` are
    refused.
    """
    path = Path(path)
    kind = _suffix(path)
    check_source(path, InputError)
    try:
        if kind == ".ply":
            columns, _, metadata = read_ply(path)
            return cloud_from_ply_columns(path, columns, metadata)
        readers = {".h5": _read_h5, ".pcd": _read_pcd, ".e57": _read_e57}
        readers |= dict.fromkeys(TEXT_SUFFIXES, _read_text)
        return _within_reach(readers.get(kind, _read_las)(path), path)
    except InputError as exc:   # the cloud's own checks do not know the file: name it
        if str(exc).startswith(str(path)):
            raise
        raise InputError(f"{path}: {exc}") from None


def _within_reach(cloud: Cloud, path) -> Cloud:
    """``cloud``, once its points and view points are found within ``MAX_COORDINATE_M``."""
    check_extent(cloud.points, path)
    if cloud.view_points is not None:
        check_extent(cloud.view_points, f"{path}: view points")
    return cloud


def cloud_from_ply_columns(path, columns: dict[str, np.ndarray],
                           metadata: dict[str, str] | None = None) -> Cloud:
    """The cloud of a PLY file's vertex columns and header metadata (``formats.ply.read_ply``):
    x, y, z as points, every other column an attribute (``scalar_NAME`` as ``NAME``), in the
    frame the metadata names. ``path`` only names the file in errors."""
    missing = [k for k in "xyz" if k not in columns]
    if missing:
        raise InputError(f"{path}: PLY vertices lack {', '.join(missing)}")
    columns = dict(columns)
    points = np.stack([columns.pop(k).astype(np.float64) for k in "xyz"], axis=1)
    attributes = {}
    for name, values in columns.items():
        short = name.removeprefix(_PLY_SCALAR_PREFIX)
        attributes[short if short and short not in columns else name] = values
    return _within_reach(Cloud(points, attributes, frame=frame_of(metadata or {}, path)), path)


@contextlib.contextmanager
def _open_h5(path: Path):
    """recon's HDF5 cloud ``path`` checked and open: yields ``(file, metadata)``."""
    import h5py

    check_hdf5(path, InputError)   # no other files, no loops: formats/hdf5_check.py
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != CLOUD_FORMAT_NAME:
                raise InputError(f"{path}: not a recon point cloud (root attribute "
                                      f"'format' is {f.attrs.get('format')!r})")
            if int(f.attrs.get("format_version", -1)) != CLOUD_FORMAT_VERSION:
                raise InputError(f"{path}: point-cloud format version "
                                      f"{f.attrs.get('format_version')} is not supported")
            shape = f["points"].shape
            if len(shape) != 2 or shape[1] != 3:
                raise InputError(f"{path}: /points has shape {shape}, expected (n, 3)")
            yield f, {k: str(f.attrs[k]) for k in ("frame", "units") if k in f.attrs}
    except InputError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise InputError(f"{path}: unreadable HDF5 point cloud ({exc})") from None


def _read_h5(path: Path) -> Cloud:
    with _open_h5(path) as (f, metadata):
        try:
            stored = dict(f["attributes"].items())
            check_whole(path, [f["points"], *stored.values()], InputError)
            points = np.asarray(f["points"][()], dtype=np.float64)
            attributes = {k: np.asarray(v[()]) for k, v in stored.items()}
        except InputError:
            raise
        except (OSError, KeyError, ValueError, TypeError) as exc:
            raise InputError(f"{path}: unreadable HDF5 point cloud ({exc})") from None
    return Cloud(points, attributes, frame=frame_of(metadata, path))


def _las_header(path: Path):
    """The header of the LAS/LAZ file ``path``, checked: finite, non-zero scales and finite
    offsets (a zero scale puts every point at the offset), and for uncompressed files a point
    count the file's size can hold (checked before any point is read)."""
    import laspy

    try:
        with laspy.open(path) as reader:
            header = reader.header
    except Exception as exc:  # laspy raises its own and OS errors on bad files
        raise InputError(f"{path}: not a readable LAS/LAZ file ({exc})") from None
    scales, offsets = np.asarray(header.scales), np.asarray(header.offsets)
    if not (np.all(np.isfinite(scales)) and np.all(scales != 0)):
        raise InputError(f"{path}: LAS scale factors must be finite and non-zero, got "
                              f"{', '.join(f'{v:g}' for v in scales)}")
    if not np.all(np.isfinite(offsets)):
        raise InputError(f"{path}: LAS offsets must be finite, got "
                              f"{', '.join(f'{v:g}' for v in offsets)}")
    if not header.are_points_compressed:
        record = header.point_format.size
        held = (path.stat().st_size - header.offset_to_point_data) // max(record, 1)
        if header.point_count > held:
            raise InputError(f"{path}: the LAS header declares {header.point_count:,} "
                                  f"points but the file holds {max(held, 0):,}")
    return header


def _read_las(path: Path) -> Cloud:
    import laspy

    _las_header(path)
    try:
        las = laspy.read(path)
    except Exception as exc:  # laspy raises its own and OS errors on bad files
        raise InputError(f"{path}: not a readable LAS/LAZ file ({exc})") from None
    points = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    metadata = _las_metadata(path, las.header)
    standard = metadata.get("dimensions", {})
    if not metadata and np.any(np.asarray(las.gps_time) != 0):  # another tool's LAS with times
        standard = {"gps_time": "time"}
    attributes = {name: np.asarray(las[dim]) for dim, name in standard.items()
                  if dim in ("gps_time", "point_source_id")}
    for name in las.point_format.extra_dimension_names:
        attributes[name] = np.asarray(las[name])
    return Cloud(points, attributes, frame=frame_of(metadata, path))


def _las_metadata(path: Path, header) -> dict:
    """The recon VLR of a LAS header as a dict ({} in files of other tools)."""
    for vlr in header.vlrs:
        if (vlr.user_id, vlr.record_id) == (_LAS_VLR_USER, _LAS_VLR_RECORD):
            try:
                return json.loads(vlr.record_data)
            except (ValueError, UnicodeDecodeError):
                raise InputError(f"{path}: the recon VLR is not JSON") from None
    return {}


def _text_columns(path: Path) -> tuple[list[str] | None, str | None, int]:
    """The column names a comment line or a CSV header row gives (or None), the delimiter of
    a text cloud and the number of header rows to skip.

    Raises
    ------
    InputError
        The file has no data line (empty, or comments only).
    """
    names, delimiter, header = None, None, 0
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            text = line.strip()
            if not text:
                continue
            if text.startswith(("#", "//")):
                words = text.lstrip("#/").replace(",", " ").split()
                if words[:3] and [w.lower() for w in words[:3]] == ["x", "y", "z"]:
                    names = [w.lower() for w in words]
                continue
            delimiter = "," if "," in text else None
            first = text.split(delimiter)
            if path.suffix.lower() == ".csv" and not all(_is_number(w) for w in first):
                names, header = [w.strip().strip('"').lower() for w in first], 1
                missing = [k for k in "xyz" if k not in names]
                if missing or len(set(names)) != len(names):
                    raise InputError(
                        f"{path}: the header row must name columns x, y and z once each "
                        f"(found {', '.join(names)[:200]!r})")
            break
        else:
            raise InputError(f"{path}: holds no points (no line of numbers)")
    return names, delimiter, header


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def _read_text(path: Path) -> Cloud:
    names, delimiter, header = _text_columns(path)
    try:
        table = np.loadtxt(path, comments=("#", "//"), delimiter=delimiter, ndmin=2,
                           dtype=np.float64, skiprows=_header_line(path) if header else 0)
    except ValueError as exc:
        raise InputError(f"{path}: not a text point cloud of numbers "
                              f"({str(exc).splitlines()[0]})") from None
    if table.size == 0:
        raise InputError(f"{path}: holds no points")
    n_columns = table.shape[1]
    if n_columns < 3:
        raise InputError(f"{path}: needs at least 3 columns (x y z), found {n_columns}")
    if path.suffix.lower() == ".xyzn" and n_columns != 6:
        raise InputError(f"{path}: an .xyzn file has 6 columns (x y z nx ny nz), found "
                              f"{n_columns}")
    if header and len(names) != n_columns:
        raise InputError(f"{path}: the header names {len(names)} columns but the rows "
                              f"hold {n_columns}")
    if names is None or len(names) != n_columns:
        names = ["x", "y", "z"] + (list(NORMAL_ATTRIBUTES) if n_columns == 6 else
                                   [f"column_{i + 1}" for i in range(3, n_columns)])
    columns = dict(zip(names, table.T, strict=True))
    return Cloud(np.stack([columns.pop(k) for k in "xyz"], axis=1), columns, frame=UNKNOWN)


def _header_line(path: Path) -> int:
    """Lines up to and including a CSV's header row (blank and comment lines before it)."""
    with open(path, encoding="utf-8", errors="replace") as fh:
        for number, line in enumerate(fh, 1):
            if line.strip() and not line.strip().startswith(("#", "//")):
                return number
    return 0


# PCD header keys in the order the format (PCL's PCD v0.7) puts them.
_PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT",
             "POINTS", "DATA")
_PCD_MAX_HEADER_LINES = 64


def _pcd_int(path: Path, header: dict, key: str) -> int:
    words = header.get(key, [])
    if len(words) != 1 or not words[0].isdigit():
        raise InputError(f"{path}: PCD header {key} must be one non-negative integer, got "
                              f"{' '.join(words)[:40]!r}")
    return int(words[0])


def _pcd_header(path: Path) -> tuple[dict[str, list[str]], int]:
    """The header's key -> words, and the byte offset of the body (after the DATA line)."""
    header = {}
    with open(path, "rb") as fh:
        for _ in range(_PCD_MAX_HEADER_LINES):
            line = fh.readline(4096).decode("ascii", errors="replace").split("#", 1)[0]
            words = line.split()
            if not words:
                continue
            header[words[0].upper()] = words[1:]
            if words[0].upper() == "DATA":
                return header, fh.tell()
    raise InputError(f"{path}: not a readable PCD file (no DATA line in its header)")


def _pcd_fields(path: Path, header: dict) -> tuple[list[str], list[str]]:
    """Check FIELDS, SIZE, TYPE and COUNT; return the SIZE and COUNT words (one per field)."""
    missing = [k for k in ("FIELDS", "SIZE", "TYPE", "WIDTH", "POINTS", "DATA")
               if k not in header]
    if missing:
        raise InputError(f"{path}: PCD header lacks {', '.join(missing)}")
    fields = header["FIELDS"]
    counts = header.get("COUNT", ["1"] * len(fields))
    sizes, types = header["SIZE"], header["TYPE"]
    if not (len(fields) == len(sizes) == len(types) == len(counts)) or not fields:
        raise InputError(f"{path}: PCD header FIELDS, SIZE, TYPE and COUNT disagree "
                              f"({len(fields)}, {len(sizes)}, {len(types)}, {len(counts)} "
                              "entries)")
    if (any(s not in ("1", "2", "4", "8") for s in sizes)
            or any(t not in ("I", "U", "F") for t in types)
            or any(not c.isdigit() or int(c) < 1 for c in counts)):
        raise InputError(f"{path}: PCD header SIZE, TYPE or COUNT has a value the format "
                              "does not allow")
    return sizes, counts


def _pcd_points(path: Path, header: dict) -> int:
    """POINTS, checked against WIDTH x HEIGHT."""
    n = _pcd_int(path, header, "POINTS")
    width = _pcd_int(path, header, "WIDTH")
    height = _pcd_int(path, header, "HEIGHT") if "HEIGHT" in header else 1
    if width * height != n:
        raise InputError(f"{path}: PCD header declares {n:,} POINTS but WIDTH x HEIGHT is "
                              f"{width:,} x {height:,}")
    return n


def _check_pcd_ascii(path: Path, offset: int, n: int, values: int) -> None:
    """The ASCII body holds ``n`` rows of ``values`` numbers."""
    with open(path, "rb") as fh:
        fh.seek(offset)
        text = fh.read().decode("ascii", errors="replace")
    rows, columns = 0, values
    if text.strip():   # numpy warns on a body without data
        try:
            rows, columns = np.loadtxt(io.StringIO(text), ndmin=2, dtype=np.float64).shape
        except ValueError as exc:
            reason = str(exc).splitlines()[0].split(";")[0]
            raise InputError(f"{path}: PCD data rows do not match the "
                                  f"{values} values per point its header declares "
                                  f"({reason})") from None
    if columns != values or rows != n:
        raise InputError(f"{path}: the PCD header declares {n:,} points of {values} "
                              f"values but the body has {rows:,} rows of {columns}")


def _check_pcd(path: Path) -> None:
    """Refuse a PCD file whose header is malformed or whose body does not hold the declared
    points: ASCII rows with another number of values than the fields declare, or fewer rows;
    binary data shorter than POINTS records. Checked before Open3D reads it (Open3D reads a
    short row as a point)."""
    header, offset = _pcd_header(path)
    sizes, counts = _pcd_fields(path, header)
    n = _pcd_points(path, header)
    kind = header["DATA"][0].lower() if header["DATA"] else ""
    if kind == "binary":
        need = n * sum(int(s) * int(c) for s, c in zip(sizes, counts, strict=True))
        body = path.stat().st_size - offset
        if body < need:
            raise InputError(f"{path}: the PCD header declares {n:,} points ({need:,} "
                                  f"bytes) but the body holds {body:,} bytes")
    elif kind == "ascii":
        _check_pcd_ascii(path, offset, n, sum(int(c) for c in counts))
    elif kind != "binary_compressed":
        raise InputError(f"{path}: PCD DATA {kind[:20]!r} is not ascii, binary or "
                              "binary_compressed")


def _read_pcd(path: Path) -> Cloud:
    import open3d as o3d

    _check_pcd(path)
    try:
        pcd = o3d.t.io.read_point_cloud(str(path))
    except Exception as exc:  # Open3D raises RuntimeError and others on bad files
        raise InputError(f"{path}: not a readable PCD file ({exc})") from None
    if "positions" not in pcd.point:
        raise InputError(f"{path}: not a readable PCD file (no points)")
    fields = {k: pcd.point[k].numpy() for k in pcd.point}
    points = fields.pop("positions").astype(np.float64)
    attributes = {}
    for name, values in fields.items():
        values = values.reshape(len(points), -1)
        if name == "normals":
            attributes.update(zip(NORMAL_ATTRIBUTES, values.astype(np.float64).T, strict=True))
        elif values.shape[1] == 1:
            attributes[name] = values[:, 0]
        else:
            attributes.update({f"{name}_{i}": v for i, v in enumerate(values.T)})
    return Cloud(points, attributes, frame=UNKNOWN)


def _read_e57(path: Path) -> Cloud:
    import pye57

    try:
        e57 = pye57.E57(str(path))
        scans = [e57.read_scan(i, ignore_missing_fields=True, intensity=True, transform=True)
                 for i in range(e57.scan_count)]
    except Exception as exc:  # libE57Format raises its own exception types on bad files
        raise InputError(f"{path}: not a readable E57 file ({exc})") from None
    if not scans:
        raise InputError(f"{path}: E57 file holds no scans")
    xyz = ("cartesianX", "cartesianY", "cartesianZ")
    if any(k not in scan for scan in scans for k in xyz):
        raise InputError(f"{path}: E57 scans without cartesian coordinates are not "
                              "supported")
    points = np.concatenate([np.stack([s[k] for k in xyz], axis=1) for s in scans])
    attributes = {}
    if all("intensity" in s for s in scans):
        attributes["intensity"] = np.concatenate([s["intensity"] for s in scans])
    return Cloud(points.astype(np.float64), attributes, frame=UNKNOWN)


Blocks = Callable[[], Iterator[tuple[np.ndarray, np.ndarray | None]]]


def stream_cloud(path, rows: int) -> tuple[str, Blocks] | None:
    """A cloud file read from disk ``rows`` points at a time, for work whose memory must not
    grow with the file (``recon score``).

    Binary PLY files whose only element is the vertices, recon's HDF5 clouds and LAS/LAZ files
    stream; other files (ASCII PLY, text, PCD, E57, PLY meshes, other suffixes) return None and
    are read whole with :func:`read_cloud` or as meshes.

    Parameters
    ----------
    path : str or Path
    rows : int
        Points per block.

    Returns
    -------
    (frame, blocks) or None
        ``blocks()`` opens the file and yields ``(points, normals)`` pairs: points (b, 3)
        float64 metres in ``frame``, normals (b, 3) float64 or None. It may be called again
        for another pass. A file shorter than its header says raises ``InputError``.
    """
    path = Path(path)
    kind = path.suffix.lower()
    if kind not in (".ply", ".h5", ".las", ".laz"):
        return None
    check_source(path, InputError)
    if kind == ".ply":
        return _stream_ply(path, rows)
    if kind == ".h5":
        return _stream_h5(path, rows)
    if kind in (".las", ".laz"):
        return _stream_las(path, rows)
    return None


def _block(columns, names) -> tuple[np.ndarray, np.ndarray | None]:
    """``(points, normals)`` of one block of named columns (``names``: x, y, z and normals)."""
    points = np.stack([np.asarray(columns[k], dtype=np.float64) for k in names[:3]], axis=1)
    normals = (np.stack([np.asarray(columns[k], dtype=np.float64) for k in names[3:]], axis=1)
               if len(names) == 6 else None)
    return points, normals


def _stream_ply(path: Path, rows: int) -> tuple[str, Blocks] | None:
    layout = binary_vertex_layout(path)
    if layout is None:
        return None
    dtype, offset, count, metadata = layout
    fields = dtype.names or ()
    missing = [k for k in "xyz" if k not in fields]
    if missing:
        raise InputError(f"{path}: PLY vertices lack {', '.join(missing)}")
    names = ("x", "y", "z") + (NORMAL_ATTRIBUTES if all(k in fields for k in NORMAL_ATTRIBUTES)
                               else ())

    def blocks():
        with open(path, "rb") as fh:
            fh.seek(offset)
            for start in range(0, count, rows):
                records = np.fromfile(fh, dtype=dtype, count=min(rows, count - start))
                if len(records) == 0:
                    raise InputError(f"{path}: ends after {start} of {count} vertices")
                yield _block(records, names)
    return frame_of(metadata, path), blocks


def _stream_h5(path: Path, rows: int) -> tuple[str, Blocks]:
    import h5py

    with _open_h5(path) as (f, metadata):
        n = len(f["points"])
        names = [k for k in NORMAL_ATTRIBUTES if k in f["attributes"]]
        normals = len(names) == 3 and all(len(f["attributes"][k]) == n for k in names)

    def blocks():
        with h5py.File(path, "r") as f:
            for start in range(0, n, rows):
                points = np.asarray(f["points"][start:start + rows], dtype=np.float64)
                yield points, (np.stack([f["attributes"][k][start:start + rows] for k in
                                         NORMAL_ATTRIBUTES], axis=1).astype(np.float64)
                               if normals else None)
    return frame_of(metadata, path), blocks


def _stream_las(path: Path, rows: int) -> tuple[str, Blocks]:
    import laspy

    header = _las_header(path)
    metadata = _las_metadata(path, header)
    extra = set(header.point_format.extra_dimension_names)
    names = ("x", "y", "z") + (NORMAL_ATTRIBUTES if extra >= set(NORMAL_ATTRIBUTES) else ())

    def blocks():
        try:
            with laspy.open(path) as reader:
                for chunk in reader.chunk_iterator(rows):
                    yield _block({k: getattr(chunk, k) for k in names}, names)
        except Exception as exc:
            raise InputError(f"{path}: not a readable LAS/LAZ file ({exc})") from None
    return frame_of(metadata, path), blocks
