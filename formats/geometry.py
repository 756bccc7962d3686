"""The two kinds of geometry every recon package takes and returns: ``Cloud`` and ``Mesh``.

Both carry their frame and units, so a cloud registered in the inertial frame is never scored
silently against a body-frame truth. Coordinates are float64 metres; the frame is ``"body"`` (the
target body frame B of formats/SPEC.md, the default), ``"inertial"`` (I) or ``"unknown"``: read
from a file that records no frame (a text cloud, an OBJ, a PDS table), which recon says when it
uses such geometry with a known frame rather than assuming one silently.

Functions across recon accept these types and the plain data they wrap: an ``(n, 3)`` array for
a cloud, a ``(vertices, faces)`` tuple or any object with ``vertices`` and ``faces`` attributes
(``trimesh.Trimesh``) for a mesh. ``Cloud.of`` and ``Mesh.of`` do that conversion and name the
argument when given something else. A ``Mesh`` unpacks and indexes like the pair:
``vertices, faces = mesh``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Literal

import numpy as np

from formats.errors import InputError

Frame = Literal["body", "inertial", "unknown"]
# The frames recon registers strikes into; geometry read from files may also be UNKNOWN.
FRAMES: tuple[str, ...] = ("body", "inertial")
UNKNOWN = "unknown"
GEOMETRY_FRAMES: tuple[str, ...] = (*FRAMES, UNKNOWN)
# Every length in recon is in metres (formats/SPEC.md); a mesh file in km is scaled on reading.
UNITS = "m"

# Attribute names of per-point normals and view points (sensor positions), as in formats/cloud_io.
NORMAL_ATTRIBUTES = ("nx", "ny", "nz")
VIEW_ATTRIBUTES = ("view_x", "view_y", "view_z")


# Farthest coordinate recon reads or computes with [m]: 1e15 m (6,700 au) is beyond every scene
# recon simulates (sim/defaults.py, MAX_MAGNITUDE), and squared distances of such points stay far
# inside float64 (beyond about 1e154 m they overflow, and KD-tree queries return no neighbours).
MAX_COORDINATE_M = 1e15


def check_extent(points: np.ndarray, where, *, error: type[Exception] = InputError) -> None:
    """Refuse ``points`` (n, 3) [m] with a coordinate that is NaN, Inf or beyond
    ``MAX_COORDINATE_M``, naming ``where`` (the file)."""
    if not np.isfinite(points).all():
        raise error(f"{where}: coordinates contain NaN or Inf")
    reach = float(np.abs(points).max()) if len(points) else 0.0
    if not reach <= MAX_COORDINATE_M:
        raise error(f"{where}: coordinates reach {reach:.3g} m, beyond {MAX_COORDINATE_M:g} m "
                    "(not metres?)")


def xyz_array(values, what: str, *, error: type[Exception] = InputError) -> np.ndarray:
    """``values`` as an (n, 3) float64 array, or ``error`` with a message naming ``what``."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise error(f"{what} must be an (n, 3) array of numbers ({exc})") from None
    if array.ndim != 2 or array.shape[1] != 3:
        raise error(f"{what} must be (n, 3), got shape {array.shape}")
    return array


def _frame(frame: str, what: str) -> str:
    if frame not in GEOMETRY_FRAMES:
        raise InputError(f"{what} frame must be one of {GEOMETRY_FRAMES}, got {frame!r}")
    return frame


def file_metadata(frame: str, *, source=None) -> dict[str, str]:
    """What every cloud or mesh file recon writes says about its content.

    Written as PLY ``comment`` lines, a LAS VLR and HDF5 root attributes (formats/cloud_io.py).

    Parameters
    ----------
    frame : {"body", "inertial", "unknown"}
    source : str or Path, optional
        The strike log (or other file) the geometry was made from.

    Returns
    -------
    dict of str to str
        ``frame``, ``units`` (always ``"m"``), ``source`` (when given) and ``recon_version``.
    """
    from formats.version import __version__

    metadata = {"frame": _frame(frame, "file"), "units": UNITS}
    if source is not None:
        metadata["source"] = str(source)
    return metadata | {"recon_version": __version__}


def frame_of(metadata: Mapping[str, str], where) -> Frame:
    """The frame a file's metadata (``file_metadata``) names; ``"unknown"`` when it names none,
    as in files of other tools.

    Raises
    ------
    InputError
        The metadata names units other than metres or an unknown frame; the message names
        ``where`` (the file).
    """
    units = metadata.get("units", UNITS)
    if units != UNITS:
        raise InputError(f"{where}: file says units {units!r}; recon reads metres ({UNITS!r})")
    frame = metadata.get("frame", UNKNOWN)
    if frame not in GEOMETRY_FRAMES:
        raise InputError(f"{where}: file says frame {frame!r}, expected one of "
                              f"{', '.join(GEOMETRY_FRAMES)}")
    return frame


class Cloud:
    """Points with named per-point attributes, in one frame.

    Parameters
    ----------
    points : (n, 3) array_like, metres
    attributes : mapping of str to (n,) arrays, optional
        Per-point values (``time``, ``shot``, ``beam``, ``range``, ``view_x/y/z``, ``nx/ny/nz``;
        see formats/cloud_io.py); any others are kept as they are.
    normals : (n, 3) array_like, optional
        Per-point normals, stored as the ``nx``, ``ny``, ``nz`` attributes.
    frame : {"body", "inertial", "unknown"}
        Frame of ``points`` (and of the view points); ``"unknown"`` for points read from a
        file that records none.
    units : str
        Always ``"m"``; recorded so that files and reports can say it.

    Attributes
    ----------
    points : (n, 3) float64, metres, in ``frame``
    attributes : dict of str to (n,) arrays
    """

    __slots__ = ("attributes", "frame", "points", "units")

    def __init__(self, points, attributes: Mapping[str, np.ndarray] | None = None, *,
                 normals=None, frame: Frame = "body", units: str = UNITS):
        self.points = xyz_array(points, "cloud points")
        self.attributes = dict(attributes or {})
        if normals is not None:
            normals = xyz_array(normals, "cloud normals")
            if normals.shape != self.points.shape:
                raise InputError(f"cloud normals must match its points, got "
                                      f"{normals.shape} for {self.points.shape}")
            self.attributes.update(zip(NORMAL_ATTRIBUTES, normals.T, strict=True))
        for name, values in self.attributes.items():
            if len(values) != len(self.points):
                raise InputError(f"attribute {name!r} has {len(values)} values for "
                                      f"{len(self.points)} points")
        self.frame = _frame(frame, "cloud")
        if units != UNITS:
            raise InputError(f"cloud units must be {UNITS!r}, got {units!r}")
        self.units = units

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        return (f"Cloud({len(self)} points, frame={self.frame!r}, "
                f"attributes={sorted(self.attributes)})")

    def _triple(self, names: tuple[str, str, str]) -> np.ndarray | None:
        if not all(n in self.attributes for n in names):
            return None
        return np.stack([np.asarray(self.attributes[n], dtype=np.float64) for n in names], axis=1)

    @property
    def normals(self) -> np.ndarray | None:
        """(n, 3) float64 normals, or None."""
        return self._triple(NORMAL_ATTRIBUTES)

    @property
    def view_points(self) -> np.ndarray | None:
        """(n, 3) float64 sensor positions [m] each point was seen from, in ``frame``, or None."""
        return self._triple(VIEW_ATTRIBUTES)

    def subset(self, index) -> Cloud:
        """The points selected by ``index`` (a boolean mask or integer indices), attributes kept."""
        return Cloud(self.points[index], {k: np.asarray(v)[index]
                                          for k, v in self.attributes.items()},
                     frame=self.frame)

    @classmethod
    def of(cls, value, name: str = "cloud") -> Cloud:
        """``value`` as a ``Cloud``: a ``Cloud`` as it is, an (n, 3) array as body-frame points.

        Raises
        ------
        InputError
            ``value`` is a mesh or not an (n, 3) array; the message names ``name``.
        """
        if isinstance(value, Cloud):
            return value
        if isinstance(value, Mesh) or (hasattr(value, "vertices") and hasattr(value, "faces")):
            raise InputError(f"{name} must be a point cloud, got a mesh")
        try:
            return cls(value)
        except InputError as exc:
            raise InputError(f"{name} must be a Cloud or an (n, 3) array of points, got "
                                  f"{type(value).__name__} ({exc})") from None


class Mesh:
    """A triangle mesh in one frame.

    Parameters
    ----------
    vertices : (n_vertices, 3) array_like, metres
    faces : (n_faces, 3) array_like of int, rows of ``vertices``, counter-clockwise seen from
        outside (outward normals)
    frame : {"body", "inertial", "unknown"}
    units : str
        Always ``"m"``.

    Attributes
    ----------
    vertices : (n_vertices, 3) float64, metres, in ``frame``
    faces : (n_faces, 3) int64
    """

    __slots__ = ("faces", "frame", "units", "vertices")

    def __init__(self, vertices, faces, *, frame: Frame = "body", units: str = UNITS):
        self.vertices = xyz_array(vertices, "mesh vertices")
        faces = np.asarray(faces)
        if faces.size == 0:
            faces = faces.reshape(0, 3)
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise InputError(f"mesh faces must be (m, 3), got {faces.shape}")
        if not np.issubdtype(faces.dtype, np.integer):
            raise InputError(f"mesh faces must be integers, got dtype {faces.dtype}")
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.frame = _frame(frame, "mesh")
        if units != UNITS:
            raise InputError(f"mesh units must be {UNITS!r}, got {units!r}")
        self.units = units

    def __iter__(self) -> Iterator[np.ndarray]:
        """``vertices, faces = mesh``, as with the plain pair."""
        return iter((self.vertices, self.faces))

    def __getitem__(self, index: int) -> np.ndarray:
        """``mesh[0]`` is the vertices and ``mesh[1]`` the faces, as in the plain pair."""
        return (self.vertices, self.faces)[index]

    def __repr__(self) -> str:
        return f"Mesh({len(self.vertices)} vertices, {len(self.faces)} faces, frame={self.frame!r})"

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def vertex_normals(self) -> np.ndarray:
        """(n_vertices, 3) float64 unit normals: the area-weighted mean of the adjacent faces'
        normals (outward for counter-clockwise faces); zero at vertices of no face."""
        v = self.vertices
        f = self.faces
        cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # 2 x area x normal
        summed = np.stack([np.bincount(f.ravel(), weights=np.repeat(cross[:, i], 3),
                                       minlength=len(v)) for i in range(3)], axis=1)
        length = np.linalg.norm(summed, axis=1, keepdims=True)
        return np.divide(summed, length, out=np.zeros_like(summed), where=length > 0)

    @classmethod
    def of(cls, value, name: str = "mesh") -> Mesh:
        """``value`` as a ``Mesh``: a ``Mesh`` as it is, a ``(vertices, faces)`` pair, or any
        object with ``vertices`` and ``faces`` attributes (e.g. ``trimesh.Trimesh``).

        Raises
        ------
        InputError
            Anything else; the message names ``name``.
        """
        if isinstance(value, Mesh):
            return value
        if isinstance(value, tuple | list) and len(value) == 2:
            vertices, faces = value
        elif hasattr(value, "vertices") and hasattr(value, "faces"):
            vertices, faces = value.vertices, value.faces
        else:
            raise InputError(f"{name} must be a Mesh, a (vertices, faces) pair or an object "
                                  f"with vertices and faces, got {type(value).__name__}")
        try:
            return cls(vertices, faces, frame=getattr(value, "frame", "body"))
        except InputError as exc:
            raise InputError(f"{name}: {exc}") from None
