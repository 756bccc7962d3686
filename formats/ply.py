"""Binary little-endian PLY: streaming writer of named per-vertex columns, and a reader.

Written files hold one ``vertex`` element with any number of scalar properties (float64 for
coordinates and floats, uint32 for indices) and, for meshes, a ``face`` element of uint8-counted
int32 index lists. Reading accepts ASCII and binary PLY from any tool (Open3D, MeshLab,
CloudCompare) through trimesh's parser and keeps every vertex property.
"""

from __future__ import annotations

import numpy as np

from formats.atomic import AtomicWriter
from formats.errors import MeshFormatError
from formats.paths import check_source

_PLY_TYPES = {"f8": "double", "f4": "float", "u4": "uint", "i4": "int", "u2": "ushort",
              "i2": "short", "u1": "uchar", "i1": "char", "i8": "double", "u8": "double"}


def _ply_dtype(arr: np.ndarray) -> np.dtype:
    """The on-disk dtype for a column (64-bit integers are stored as double, PLY has no int64)."""
    code = arr.dtype.str[1:]
    if code in ("i8", "u8") or arr.dtype.kind == "b":
        return np.dtype("<f8") if code in ("i8", "u8") else np.dtype("u1")
    if arr.dtype.kind == "f" and arr.dtype.itemsize not in (4, 8):
        return np.dtype("<f8")
    return arr.dtype.newbyteorder("<")


class PlyWriter(AtomicWriter):
    """Stream rows of named columns into a binary PLY file, atomically.

    The vertex count goes in the header, so it is given up front; the file is renamed into place
    on a clean close once exactly ``n_rows`` rows (and ``n_faces`` faces) were written.

    Parameters
    ----------
    path : str or Path
    n_rows : int
    dtypes : dict of str to numpy dtype
        Column names in file order and their in-memory dtypes.
    n_faces : int, optional
        Number of triangles ``write_faces`` will write after the vertices (meshes).
    """

    missing_dir_error = MeshFormatError

    def __init__(self, path, n_rows: int, dtypes: dict[str, np.dtype], *, n_faces: int = 0):
        super().__init__(path)
        self.n_rows = int(n_rows)
        self.n_faces = int(n_faces)
        self._disk = np.dtype([(k, _ply_dtype(np.zeros(0, dtype=v))) for k, v in dtypes.items()])
        header = ["ply", "format binary_little_endian 1.0", "comment written by recon",
                  f"element vertex {self.n_rows}"]
        header += [f"property {_PLY_TYPES[self._disk[k].str[1:]]} {k}" for k in dtypes]
        if self.n_faces:
            header += [f"element face {self.n_faces}", "property list uchar int vertex_indices"]
        header += ["end_header", ""]
        self._fh = open(self.temporary, "wb")  # closed by _finish or _release
        self._fh.write("\n".join(header).encode("ascii"))
        self._written = 0
        self._faces_written = 0

    def write(self, columns: dict[str, np.ndarray]) -> None:
        """Append rows; ``columns`` maps every column name to an (n,) array."""
        self._check()
        n = len(next(iter(columns.values())))
        rows = np.empty(n, dtype=self._disk)
        for name in self._disk.names:
            rows[name] = columns[name]
        self._fh.write(rows.tobytes())
        self._written += n

    def write_faces(self, faces: np.ndarray) -> None:
        """Append the face element (for meshes; call once, after all vertices)."""
        self._check()
        faces = np.asarray(faces)
        rows = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
        rows["n"] = 3
        rows["v"] = faces
        self._fh.write(rows.tobytes())
        self._faces_written = len(faces)

    def _finish(self) -> None:
        self._fh.close()
        if (self._written, self._faces_written) != (self.n_rows, self.n_faces):
            raise MeshFormatError(f"{self.path}: wrote {self._written} rows and "
                                  f"{self._faces_written} faces, header says {self.n_rows} and "
                                  f"{self.n_faces}")

    def _release(self) -> None:
        self._fh.close()


def write_ply(path, columns: dict[str, np.ndarray], *, faces: np.ndarray | None = None) -> None:
    """Write named per-vertex columns (and optional triangles) as one binary PLY."""
    n_faces = 0 if faces is None else len(faces)
    dtypes = {k: np.asarray(v).dtype for k, v in columns.items()}
    with PlyWriter(path, len(columns["x"]), dtypes, n_faces=n_faces) as writer:
        writer.write(columns)
        if n_faces:
            writer.write_faces(faces)


def read_ply_columns(path) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
    """Read every vertex property of a PLY file and its triangles, if any.

    Returns
    -------
    columns : dict of str to (n,) arrays
    faces : (m, 3) int64 or None
    """
    from trimesh.exchange.ply import load_ply

    path = check_source(path, MeshFormatError)
    try:
        with open(path, "rb") as fh:
            loaded = load_ply(fh, prefer_color="vertex")
    except FileNotFoundError:
        raise MeshFormatError(f"{path}: no such file") from None
    except Exception as exc:  # trimesh's parser raises many types on malformed input
        raise MeshFormatError(f"{path}: not a readable PLY file ({type(exc).__name__})") from None
    raw = loaded.get("metadata", {}).get("_ply_raw", {})
    vertex = raw.get("vertex", {}).get("data")
    if vertex is None:
        raise MeshFormatError(f"{path}: PLY file has no vertex element")
    columns = {name: np.asarray(vertex[name]).reshape(-1) for name in vertex.dtype.names}
    faces = loaded.get("faces")
    faces = None if faces is None or len(faces) == 0 else np.asarray(faces, dtype=np.int64)
    return columns, faces
