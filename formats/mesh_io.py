"""Read triangle meshes (OBJ, PLY, STL, OFF, glTF, and the planetary shape-model formats: PDS
vertex/plate tables, ICQ grids, SPICE DSK) and write them as binary PLY, PDS tables or DSK.

A mesh is a pair ``(vertices, faces)``: ``(n, 3) float64`` coordinates and ``(m, 3) int64``
vertex indices, counter-clockwise seen from outside. Written PLY meshes carry vertex normals and
say their frame, units, source and the recon version in ``comment`` lines (formats/ply.py), which
reading gives back as the mesh's frame. Files that record no frame (OBJ, STL, PDS tables, ICQ)
are read in the frame ``"unknown"``; a DSK segment names its frame (formats/shape_models.py).

Units: recon works in metres and converts on reading. Each format has a stated default
(``default_units``): metres for the 3D formats (OBJ, PLY, STL, OFF, glTF; a PLY written by recon
says ``comment units m``), km for the planetary ones (PDS tables and ICQ as published; DSK by
definition, which no other unit can override).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from formats.errors import InputError
from formats.geometry import UNKNOWN, Mesh, check_extent, file_metadata, frame_of
from formats.paths import check_source
from formats.ply import read_ply, read_ply_metadata, write_ply
from formats.shape_models import (
    DEFAULT_UNITS,
    DSK_SUFFIXES,
    METRES_PER,
    SHAPE_SUFFIXES,
    read_dsk,
    read_pds_table,
    units_factor,
    write_dsk,
    write_pds_table,
)

TRIMESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
MESH_SUFFIXES = (*TRIMESH_SUFFIXES, *SHAPE_SUFFIXES)
WRITE_SUFFIXES = (".ply", ".tab", *DSK_SUFFIXES)
UNITS = tuple(METRES_PER)


def default_units(path) -> str:
    """The units a mesh file is read in when none are given: ``"km"`` for PDS tables, ICQ and
    DSK, ``"m"`` for the 3D formats (a recon PLY's ``comment units`` overrides)."""
    return DEFAULT_UNITS.get(Path(path).suffix.lower(), "m")


def read_mesh(path, *, scale: float = 1.0, units: str | None = None) -> Mesh:
    """Read a triangle mesh in metres, multiplying its coordinates by ``scale`` too.

    Parameters
    ----------
    path : str or Path
        OBJ, PLY, STL, OFF or glTF file (polygons are triangulated; several bodies are merged);
        a PDS vertex/plate table or ICQ grid (``.tab``, ``.icq``); a SPICE DSK (``.bds``,
        ``.dsk``; every type 2 segment).
    scale : float
        Factor applied after the unit conversion (e.g. to resize a model).
    units : {"km", "m"}, optional
        Units of the file's coordinates; default ``default_units(path)`` (km for the planetary
        formats, metres otherwise). A DSK is in km and a recon PLY says its units: another
        value for those is refused.

    Returns
    -------
    Mesh
        vertices (n, 3) float64, metres (times ``scale``); faces (m, 3) int64; in the frame the
        file records (a recon PLY's ``comment frame``, a DSK segment's frame), else
        ``"unknown"``.

    Raises
    ------
    InputError
        Missing file, unknown suffix or units, unreadable content, no triangles, indices that
        name no vertex, or non-finite vertices; the message names the file (and the units it
        was read in where they matter).
    """
    path = check_source(path, InputError)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise InputError(f"{path}: unknown mesh suffix {path.suffix!r} (expected one of "
                              f"{', '.join(MESH_SUFFIXES)})")
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(f"{path}: scale must be a positive number, got {scale}")
    if units is not None:
        units_factor(units, path)   # a bad name first
    stated = _stated_units(path, suffix)
    if units is not None and stated is not None and units != stated:
        raise InputError(f"{path}: the file is in {stated}, not {units} (omit the units)")
    units = units or stated or default_units(path)
    factor = units_factor(units, path) * scale
    if suffix in DSK_SUFFIXES:
        vertices, faces, frame = read_dsk(path)
    elif suffix in SHAPE_SUFFIXES:
        vertices, faces, _ = read_pds_table(path)
        frame = UNKNOWN
    elif suffix == ".ply":
        vertices, faces, frame = _read_ply_mesh(path)
    else:
        vertices, faces, frame = _read_trimesh(path)
    if not np.all(np.isfinite(vertices)):
        raise InputError(f"{path}: vertices contain NaN or Inf (read as {units})")
    if len(faces) == 0:
        raise InputError(f"{path}: has no triangles (a point cloud, not a mesh?)")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(f"{path}: faces index vertices that do not exist")
    vertices = vertices * factor
    check_extent(vertices, path)
    return Mesh(vertices, faces, frame=frame)


def _stated_units(path: Path, suffix: str) -> str | None:
    """Units the file itself states: km for a DSK, a recon PLY's ``comment units``."""
    if suffix in DSK_SUFFIXES:
        return "km"
    if suffix == ".ply":
        stated = read_ply_metadata(path).get("units")
        if stated is not None and stated not in METRES_PER:
            raise InputError(f"{path}: file says units {stated!r}; recon reads "
                                  f"{' or '.join(UNITS)}")
        return stated
    return None


def _read_ply_mesh(path: Path) -> tuple[np.ndarray, np.ndarray, str]:
    """A PLY mesh through the strict reader (formats/ply.py: header, counts and faces checked);
    its frame from its ``comment`` lines (units are read by ``_stated_units``)."""
    columns, faces, metadata = read_ply(path)
    missing = [k for k in "xyz" if k not in columns]
    if missing:
        raise InputError(f"{path}: PLY vertices lack {', '.join(missing)}")
    vertices = np.stack([np.asarray(columns[k], dtype=np.float64) for k in "xyz"], axis=1)
    faces = np.zeros((0, 3), dtype=np.int64) if faces is None else faces
    return vertices, faces, frame_of({k: v for k, v in metadata.items() if k != "units"}, path)


def _read_trimesh(path: Path) -> tuple[np.ndarray, np.ndarray, str]:
    """OBJ, STL, OFF or glTF through trimesh; these record no frame."""
    import trimesh

    frame = UNKNOWN
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types on bad files; all mean "unreadable"
        raise InputError(f"{path}: not a readable mesh ({type(exc).__name__}: "
                              f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    if faces.ndim != 2 or faces.shape[1] != 3:
        faces = np.zeros((0, 3), dtype=np.int64)
    return vertices, faces, frame


def write_mesh(path, vertices, faces: np.ndarray | None = None, *,
               vertex_normals: np.ndarray | None = None, source=None,
               units: str | None = None) -> Path:
    """Write a triangle mesh (atomically); the suffix of ``path`` picks the format.

    ``.ply``: binary little-endian PLY with vertex normals, in metres, with ``comment`` lines
    for the frame, units, ``source`` and recon version. ``.tab``: PDS vertex/plate table
    (two-table form, 1-based; formats/shape_models.py), in km unless ``units="m"``.
    ``.bds``/``.dsk``: SPICE DSK type 2, in km, body ``RECON_TARGET`` in frame
    ``RECON_TARGET_FIXED``.

    Parameters
    ----------
    path : str or Path
    vertices : (n, 3) float64, metres, or a ``Mesh`` (then ``faces`` is not given)
    faces : (m, 3) int
    vertex_normals : (n, 3) float64, optional
        PLY only. Default: ``Mesh.vertex_normals``, computed from the faces.
    source : str or Path, optional
        The file the mesh was made from, recorded in the PLY header (``comment source``) or the
        DSK's internal file name.
    units : {"km", "m"}, optional
        Units of a ``.tab``'s coordinates (default km). PLY is always metres and DSK km.
    """
    path = Path(path)
    frame = getattr(vertices, "frame", "body")
    if faces is None:
        vertices, faces = Mesh.of(vertices, "mesh")
    suffix = path.suffix.lower()
    if suffix not in WRITE_SUFFIXES:
        raise InputError(f"{path}: meshes are written as {', '.join(WRITE_SUFFIXES)}")
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise InputError(f"{path}: vertices must be (n, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise InputError(f"{path}: faces must be (m, 3), got {faces.shape}")
    fixed = {".ply": "m", ".bds": "km", ".dsk": "km"}.get(suffix)
    if units is not None and fixed is not None and units != fixed:
        raise InputError(f"{path}: {suffix} files are written in {fixed}, not {units}")
    if suffix == ".tab":
        return write_pds_table(path, vertices, faces, units=units or "km")
    if suffix in DSK_SUFFIXES:
        return write_dsk(path, vertices, faces,
                         comment=f"recon shape model from {Path(source).name}" if source
                         else "recon shape model")
    if vertex_normals is None:
        vertex_normals = Mesh(vertices, faces).vertex_normals
    n = np.asarray(vertex_normals, dtype=np.float64)
    if n.shape != vertices.shape:
        raise InputError(f"{path}: vertex_normals must be {vertices.shape}, got {n.shape}")
    columns = {"x": vertices[:, 0], "y": vertices[:, 1], "z": vertices[:, 2],
               "nx": n[:, 0], "ny": n[:, 1], "nz": n[:, 2]}
    write_ply(path, columns, faces=faces, metadata=file_metadata(frame, source=source))
    return path
