"""Read triangle meshes (OBJ, PLY, STL, OFF, GLB) and write them as binary PLY.

A mesh is a pair ``(vertices, faces)``: ``(n, 3) float64`` coordinates and ``(m, 3) int64``
vertex indices, counter-clockwise seen from outside. Written meshes carry vertex normals and say
their frame, units, source and the recon version in ``comment`` lines (formats/ply.py), which
reading gives back as the mesh's frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from formats.errors import MeshFormatError
from formats.geometry import Mesh, file_metadata, frame_of
from formats.paths import check_source
from formats.ply import read_ply, write_ply

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


def read_mesh(path, *, scale: float = 1.0) -> Mesh:
    """Read a triangle mesh, multiplying its coordinates by ``scale``.

    Parameters
    ----------
    path : str or Path
        OBJ, PLY, STL, OFF or glTF file. Polygons are triangulated; several bodies are merged.
    scale : float
        Factor applied to the coordinates, e.g. 1000 for a shape model in km.

    Returns
    -------
    Mesh
        vertices (n, 3) float64, file units times ``scale``; faces (m, 3) int64; in the frame a
        PLY written by recon records, else the body frame.

    Raises
    ------
    MeshFormatError
        Missing file, unknown suffix, unreadable content, no triangles, or non-finite vertices.
    """
    import trimesh

    path = check_source(path, MeshFormatError)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshFormatError(f"{path}: unknown mesh suffix {path.suffix!r} (expected one of "
                              f"{', '.join(MESH_SUFFIXES)})")
    if not (np.isfinite(scale) and scale > 0):
        raise MeshFormatError(f"{path}: scale must be a positive number, got {scale}")
    if path.suffix.lower() == ".ply":   # the strict reader: header, counts and faces checked
        columns, faces, metadata = read_ply(path)
        missing = [k for k in "xyz" if k not in columns]
        if missing:
            raise MeshFormatError(f"{path}: PLY vertices lack {', '.join(missing)}")
        vertices = np.stack([np.asarray(columns[k], dtype=np.float64) for k in "xyz"], axis=1)
        faces = np.zeros((0, 3), dtype=np.int64) if faces is None else faces
        frame = frame_of(metadata, path)
    else:
        try:
            mesh = trimesh.load(path, force="mesh", process=False)
        except Exception as exc:  # trimesh raises many types on bad files: "unreadable"
            raise MeshFormatError(f"{path}: not a readable mesh ({type(exc).__name__}: "
                                  f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
        faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
        vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
        frame = "body"
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshFormatError(f"{path}: has no triangles (a point cloud, not a mesh?)")
    if not np.all(np.isfinite(vertices)):
        raise MeshFormatError(f"{path}: vertices contain NaN or Inf")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshFormatError(f"{path}: faces index vertices that do not exist")
    return Mesh(vertices * scale, faces, frame=frame)


def write_mesh(path, vertices, faces: np.ndarray | None = None, *,
               vertex_normals: np.ndarray | None = None, source=None) -> Path:
    """Write a triangle mesh as binary little-endian PLY (atomically), with vertex normals.

    Parameters
    ----------
    path : str or Path
        Destination; must end in ``.ply``.
    vertices : (n, 3) float64, or a ``Mesh`` (then ``faces`` is not given)
    faces : (m, 3) int
    vertex_normals : (n, 3) float64, optional
        Default: ``Mesh.vertex_normals``, computed from the faces.
    source : str or Path, optional
        The file the mesh was made from, recorded in the header with the mesh's frame.
    """
    path = Path(path)
    frame = getattr(vertices, "frame", "body")
    if faces is None:
        vertices, faces = Mesh.of(vertices, "mesh")
    if path.suffix.lower() != ".ply":
        raise MeshFormatError(f"{path}: meshes are written as .ply")
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise MeshFormatError(f"{path}: vertices must be (n, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshFormatError(f"{path}: faces must be (m, 3), got {faces.shape}")
    if vertex_normals is None:
        vertex_normals = Mesh(vertices, faces).vertex_normals
    n = np.asarray(vertex_normals, dtype=np.float64)
    if n.shape != vertices.shape:
        raise MeshFormatError(f"{path}: vertex_normals must be {vertices.shape}, got {n.shape}")
    columns = {"x": vertices[:, 0], "y": vertices[:, 1], "z": vertices[:, 2],
               "nx": n[:, 0], "ny": n[:, 1], "nz": n[:, 2]}
    write_ply(path, columns, faces=faces, metadata=file_metadata(frame, source=source))
    return path
