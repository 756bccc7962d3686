"""Binary little-endian PLY: streaming writer of named per-vertex columns, and a reader.

Written files hold one ``vertex`` element with any number of scalar properties and, for meshes, a
``face`` element of uint8-counted int32 index lists. Property types are the ones every common
reader takes (Open3D's tensor reader refuses ``uint`` and ``ushort``): ``double`` for float64
and for 64-bit integers (exact to 2**53), ``float`` for float32, ``uchar`` for bytes and booleans,
and ``int`` (int32) for every other integer (a value beyond int32 is refused on writing).

The header's ``comment`` lines carry the file's metadata as ``comment KEY VALUE`` (e.g.
``comment frame body``, ``comment units m``); ``read_ply`` returns them as a dict.

Reading accepts ASCII and binary PLY from any tool (Open3D, MeshLab, CloudCompare, trimesh)
through trimesh's parser and keeps every vertex property.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from formats.atomic import AtomicWriter
from formats.errors import MeshFormatError
from formats.paths import check_source

_PLY_TYPES = {"f8": "double", "f4": "float", "i4": "int", "u1": "uchar"}
_INT32 = np.iinfo(np.int32)
# A PLY header is a few hundred bytes; a longer one is not a PLY file worth parsing.
_MAX_HEADER_LINES = 10_000


def _ply_dtype(dtype: np.dtype) -> np.dtype:
    """The on-disk dtype of a column (one of ``_PLY_TYPES``)."""
    if dtype.kind == "b" or dtype.str[1:] == "u1":
        return np.dtype("u1")
    if dtype.kind in "iu":
        return np.dtype("<f8") if dtype.itemsize == 8 else np.dtype("<i4")
    if dtype.kind == "f" and dtype.itemsize == 4:
        return np.dtype("<f4")
    if dtype.kind == "f":
        return np.dtype("<f8")
    raise MeshFormatError(f"PLY columns must be numbers, got dtype {dtype}")


def _comment_lines(metadata: dict[str, str]) -> list[str]:
    lines = []
    for key, value in metadata.items():
        text = f"{key} {value}"
        if " " in key or "\n" in text or "\r" in text:
            raise MeshFormatError(f"PLY comment {key!r} must be one line with a one-word key")
        lines.append(f"comment {text}")
    return lines


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
    metadata : dict of str to str, optional
        Written as ``comment KEY VALUE`` header lines.
    """

    missing_dir_error = MeshFormatError

    def __init__(self, path, n_rows: int, dtypes: dict[str, np.dtype], *, n_faces: int = 0,
                 metadata: dict[str, str] | None = None):
        comments = _comment_lines(metadata or {})
        self._disk = np.dtype([(k, _ply_dtype(np.dtype(v))) for k, v in dtypes.items()])
        super().__init__(path)
        self.n_rows = int(n_rows)
        self.n_faces = int(n_faces)
        header = ["ply", "format binary_little_endian 1.0", *comments,
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
            values = np.asarray(columns[name])
            if (self._disk[name] == np.int32 and len(values)
                    and (values.min() < _INT32.min or values.max() > _INT32.max)):
                raise MeshFormatError(f"{self.path}: column {name!r} has values beyond the "
                                      "int32 range of a PLY 'int' property")
            rows[name] = values
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


def write_ply(path, columns: dict[str, np.ndarray], *, faces: np.ndarray | None = None,
              metadata: dict[str, str] | None = None) -> None:
    """Write named per-vertex columns (and optional triangles) as one binary PLY, with
    ``metadata`` as ``comment KEY VALUE`` header lines."""
    n_faces = 0 if faces is None else len(faces)
    dtypes = {k: np.asarray(v).dtype for k, v in columns.items()}
    with PlyWriter(path, len(columns["x"]), dtypes, n_faces=n_faces,
                   metadata=metadata) as writer:
        writer.write(columns)
        if n_faces:
            writer.write_faces(faces)


def _header_metadata(fh) -> dict[str, str]:
    """``comment KEY VALUE`` lines of a PLY header as ``{KEY: VALUE}`` (other comments, e.g.
    ``comment Created by CloudCompare``, too: the first word is the key)."""
    metadata = {}
    for _ in range(_MAX_HEADER_LINES):
        line = fh.readline(4096)
        if not line or line.strip() == b"end_header":
            break
        words = line.decode("ascii", errors="replace").split(None, 2)
        if len(words) == 3 and words[0] == "comment":
            metadata.setdefault(words[1], words[2].strip())
    fh.seek(0)
    return metadata


def read_ply_metadata(path) -> dict[str, str]:
    """The ``comment KEY VALUE`` lines of a PLY file's header, without reading its data."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            return _header_metadata(fh)
    except FileNotFoundError:
        raise MeshFormatError(f"{path}: no such file") from None


def read_ply(path) -> tuple[dict[str, np.ndarray], np.ndarray | None, dict[str, str]]:
    """Read every vertex property of an ASCII or binary PLY file, its triangles and metadata.

    Returns
    -------
    columns : dict of str to (n,) arrays
    faces : (m, 3) int64 or None
    metadata : dict of str to str
        The header's ``comment KEY VALUE`` lines.
    """
    from trimesh.exchange.ply import load_ply

    path = check_source(path, MeshFormatError)
    try:
        with open(path, "rb") as fh:
            if fh.readline(16).strip() != b"ply":
                raise MeshFormatError(f"{path}: not a PLY file (no 'ply' magic line)")
            fh.seek(0)
            metadata = _header_metadata(fh)
            loaded = load_ply(fh, prefer_color="vertex")
    except FileNotFoundError:
        raise MeshFormatError(f"{path}: no such file") from None
    except MeshFormatError:
        raise
    except Exception as exc:  # trimesh's parser raises many types on malformed input
        raise MeshFormatError(f"{path}: not a readable PLY file ({type(exc).__name__})") from None
    raw = loaded.get("metadata", {}).get("_ply_raw", {})
    vertex = raw.get("vertex", {}).get("data")
    if vertex is None:
        raise MeshFormatError(f"{path}: PLY file has no vertex element")
    # binary files give a structured array, ASCII files a dict of arrays
    names = vertex.dtype.names if isinstance(vertex, np.ndarray) else list(vertex)
    columns = {name: np.asarray(vertex[name]).reshape(-1) for name in names}
    faces = loaded.get("faces")
    faces = None if faces is None or len(faces) == 0 else np.asarray(faces, dtype=np.int64)
    return columns, faces, metadata


# PLY scalar types (both spellings) as numpy type codes, for reading any binary PLY.
_NUMPY_OF_PLY = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
                 "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
                 "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
                 "float64": "f8"}


def binary_vertex_layout(path) -> tuple[np.dtype, int, int, dict[str, str]] | None:
    """Where a binary PLY file keeps its vertices, for reading them block by block.

    Returns
    -------
    (dtype, offset, count, metadata) or None
        The vertex record's structured dtype, the byte offset of the first vertex, the number
        of vertices and the header's comments; None when the file cannot be read that way (an
        ASCII file, vertices that are not the first element or hold lists, any faces).
    """
    path = check_source(path, MeshFormatError)
    with open(path, "rb") as fh:
        if fh.readline(16).strip() != b"ply":
            return None
        byte_order, elements = None, []
        for _ in range(_MAX_HEADER_LINES):
            words = fh.readline(4096).decode("ascii", errors="replace").split()
            if not words:
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format" and len(words) >= 2:
                byte_order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(words[1])
            elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
                elements.append((words[1], int(words[2]), []))
            elif words[0] == "property" and elements:
                kind = _NUMPY_OF_PLY.get(words[1]) if len(words) == 3 else None
                elements[-1][2].append((words[-1], kind))
        else:
            return None
        offset = fh.tell()
        fh.seek(0)
        metadata = _header_metadata(fh)
    if byte_order is None or not elements or elements[0][0] != "vertex":
        return None
    if any(n > 0 for name, n, _ in elements[1:]) or any(k is None for _, k in elements[0][2]):
        return None
    names = [name for name, _ in elements[0][2]]
    if len(set(names)) != len(names):
        return None
    dtype = np.dtype([(name, byte_order + kind) for name, kind in elements[0][2]])
    return dtype, offset, elements[0][1], metadata
