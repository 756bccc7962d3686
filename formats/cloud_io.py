"""Point clouds with per-point attributes: binary PLY, LAS/LAZ and HDF5, streamed and read back.

Attribute names recon uses (any others are kept as they are):

=====================  =========  ==============================================================
name                   dtype      meaning
=====================  =========  ==============================================================
``time``               float64    shot time [s] (LAS: stored as ``gps_time``)
``shot``, ``beam``     uint32     shot and beam index in the source strike log
``range``              float64    measured range [m]
``view_x/y/z``         float64    sensor position in the cloud's frame [m] (orients normals)
``nx``, ``ny``, ``nz`` float64    unit normal
=====================  =========  ==============================================================

Formats
-------
``.ply``  binary little-endian, every attribute a vertex property (int64 as double).
``.las``/``.laz``  LAS 1.4 point format 6, coordinates quantised to ``LAS_SCALE_M`` with zero
    offset; ``time`` as ``gps_time``, every other attribute as an extra-bytes dimension.
``.h5``   HDF5 with root attributes ``format = "recon-point-cloud"``, ``format_version = 1``,
    dataset ``points`` (n, 3) float64 and one (n,) dataset per attribute under ``attributes/``,
    chunked and resizable.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from formats.atomic import AtomicWriter
from formats.errors import MeshFormatError
from formats.geometry import Cloud
from formats.hdf5_check import check_hdf5, trust
from formats.paths import check_source
from formats.ply import PlyWriter, read_ply_columns

CLOUD_SUFFIXES = (".ply", ".las", ".laz", ".h5")
CLOUD_FORMAT_NAME = "recon-point-cloud"
CLOUD_FORMAT_VERSION = 1
# LAS stores int32 coordinates: 0.1 mm steps reach +-214 km, beyond any target we image.
LAS_SCALE_M = 1e-4
_CHUNK_ROWS = 65_536


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise MeshFormatError(f"{path}: unknown point-cloud suffix {path.suffix!r} (expected one "
                              f"of {', '.join(CLOUD_SUFFIXES)})")
    return suffix


# --------------------------------------------------------------------------- writers


class _PlyCloud(PlyWriter):
    """Binary PLY: x, y, z then every attribute as a vertex property."""

    def __init__(self, path, n_points: int, dtypes: dict[str, np.dtype]):
        xyz = {"x": np.float64, "y": np.float64, "z": np.float64}
        super().__init__(path, n_points, xyz | dtypes)

    def write(self, points: np.ndarray, attributes: dict[str, np.ndarray]) -> None:
        points = np.asarray(points, dtype=np.float64)
        super().write({"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]} | attributes)


class _H5Cloud(AtomicWriter):
    """recon's HDF5 cloud: ``points`` and one dataset per attribute, chunked and resizable."""

    missing_dir_error = MeshFormatError

    def __init__(self, path, n_points: int, dtypes: dict[str, np.dtype]):
        import h5py

        super().__init__(path, suffix=".h5")
        self.n_points, self.dtypes, self._written = int(n_points), dtypes, 0
        self._h5 = h5py.File(self.temporary, "w")
        self._h5.attrs.update({"format": CLOUD_FORMAT_NAME,
                               "format_version": np.int64(CLOUD_FORMAT_VERSION)})
        rows = max(1, min(_CHUNK_ROWS, self.n_points))
        self._h5.create_dataset("points", shape=(0, 3), maxshape=(None, 3), dtype=np.float64,
                                chunks=(rows, 3))
        g = self._h5.create_group("attributes")
        for name, dtype in dtypes.items():
            g.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dtype, chunks=(rows,))

    def write(self, points: np.ndarray, attributes: dict[str, np.ndarray]) -> None:
        self._check()
        n = len(points)
        for ds, values in [(self._h5["points"], points)] + [
                (self._h5["attributes"][k], attributes[k]) for k in self.dtypes]:
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
            raise MeshFormatError(f"{self.path}: wrote {self._written} points, expected "
                                  f"{self.n_points}")

    def _release(self) -> None:
        self._h5.close()


class _LasCloud(AtomicWriter):
    """LAS 1.4 point format 6 (LAZ when the suffix says so); attributes as extra bytes."""

    missing_dir_error = MeshFormatError

    def __init__(self, path, n_points: int, dtypes: dict[str, np.dtype]):
        import laspy

        suffix = Path(path).suffix.lower()
        super().__init__(path, suffix=suffix)
        self.n_points, self._written = int(n_points), 0
        header = laspy.LasHeader(point_format=6, version="1.4")
        header.scales = np.full(3, LAS_SCALE_M)
        header.offsets = np.zeros(3)
        extra = [laspy.ExtraBytesParams(name=k, type=v) for k, v in dtypes.items()
                 if k != "time"]
        if extra:
            header.add_extra_dims(extra)
        self._las = laspy.open(self.temporary, mode="w", header=header,
                               do_compress=suffix == ".laz")

    def write(self, points: np.ndarray, attributes: dict[str, np.ndarray]) -> None:
        import laspy

        self._check()
        points = np.asarray(points, dtype=np.float64)
        if len(points) and np.abs(points).max() > np.iinfo(np.int32).max * LAS_SCALE_M:
            raise MeshFormatError(f"{self.path}: coordinates beyond +-214 km do not fit LAS at "
                                  f"{LAS_SCALE_M} m resolution")
        record = laspy.ScaleAwarePointRecord.zeros(len(points), header=self._las.header)
        record.x, record.y, record.z = points[:, 0], points[:, 1], points[:, 2]
        for name, values in attributes.items():
            record["gps_time" if name == "time" else name] = values
        self._las.write_points(record)
        self._written += len(points)

    def _finish(self) -> None:
        self._las.close()
        if self._written != self.n_points:
            raise MeshFormatError(f"{self.path}: wrote {self._written} points, expected "
                                  f"{self.n_points}")

    def _release(self) -> None:
        self._las.close()


_WRITERS = {".ply": _PlyCloud, ".h5": _H5Cloud, ".las": _LasCloud, ".laz": _LasCloud}


def open_cloud_writer(path, n_points: int, dtypes: dict[str, np.dtype]) -> AtomicWriter:
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
    """
    path = Path(path)
    return _WRITERS[_suffix(path)](path, n_points, {k: np.dtype(v) for k, v in dtypes.items()})


def write_cloud(path, cloud: Cloud) -> Path:
    """Write a whole point cloud; the suffix of ``path`` picks PLY, LAS, LAZ or HDF5."""
    dtypes = {k: np.asarray(v).dtype for k, v in cloud.attributes.items()}
    with open_cloud_writer(path, len(cloud), dtypes) as writer:
        writer.write(cloud.points, cloud.attributes)
    return Path(path)


# --------------------------------------------------------------------------- readers


def read_cloud(path) -> Cloud:
    """Read a point cloud with its attributes (PLY, LAS/LAZ, or recon's HDF5 cloud).

    A PLY mesh is read as the cloud of its vertices.
    """
    path = Path(path)
    kind = _suffix(path)
    check_source(path, MeshFormatError)
    if kind == ".ply":
        return cloud_from_ply_columns(path, read_ply_columns(path)[0])
    if kind == ".h5":
        return _read_h5(path)
    return _read_las(path)


def cloud_from_ply_columns(path, columns: dict[str, np.ndarray]) -> Cloud:
    """The cloud of a PLY file's vertex columns (``formats.ply.read_ply_columns``): x, y, z as
    points, every other column an attribute. ``path`` only names the file in errors."""
    missing = [k for k in "xyz" if k not in columns]
    if missing:
        raise MeshFormatError(f"{path}: PLY vertices lack {', '.join(missing)}")
    columns = dict(columns)
    points = np.stack([columns.pop(k).astype(np.float64) for k in "xyz"], axis=1)
    return Cloud(points, columns)


def _read_h5(path: Path) -> Cloud:
    import h5py

    check_hdf5(path, MeshFormatError)   # no other files, no loops: formats/hdf5_check.py
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != CLOUD_FORMAT_NAME:
                raise MeshFormatError(f"{path}: not a recon point cloud (root attribute "
                                      f"'format' is {f.attrs.get('format')!r})")
            if int(f.attrs.get("format_version", -1)) != CLOUD_FORMAT_VERSION:
                raise MeshFormatError(f"{path}: point-cloud format version "
                                      f"{f.attrs.get('format_version')} is not supported")
            points = np.asarray(f["points"][()], dtype=np.float64)
            attributes = {k: np.asarray(v[()]) for k, v in f["attributes"].items()}
    except MeshFormatError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise MeshFormatError(f"{path}: unreadable HDF5 point cloud ({exc})") from None
    return Cloud(points, attributes)


def _read_las(path: Path) -> Cloud:
    import laspy

    try:
        las = laspy.read(path)
    except Exception as exc:  # laspy raises its own and OS errors on bad files
        raise MeshFormatError(f"{path}: not a readable LAS/LAZ file ({exc})") from None
    points = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    attributes = {}
    gps_time = np.asarray(las.gps_time, dtype=np.float64)
    if np.any(gps_time != 0):  # format 6 always has gps_time; all zeros means none was written
        attributes["time"] = gps_time
    for name in las.point_format.extra_dimension_names:
        attributes[name] = np.asarray(las[name])
    return Cloud(points, attributes)
