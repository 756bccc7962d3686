"""Binary little-endian PLY: streaming writer of named per-vertex columns, and a reader.

Written files hold one ``vertex`` element with any number of scalar properties and, for meshes, a
``face`` element of uint8-counted int32 index lists. Property types are the ones every common
reader takes (Open3D's tensor reader refuses ``uint`` and ``ushort``): ``double`` for float64
and for 64-bit integers (exact to 2**53), ``float`` for float32, ``uchar`` for bytes and booleans,
and ``int`` (int32) for every other integer (a value beyond int32 is refused on writing).

The header's ``comment`` lines carry the file's metadata as ``comment KEY VALUE`` (e.g.
``comment frame body``, ``comment units m``); ``read_ply`` returns them as a dict.

Reading accepts ASCII and binary PLY from any tool (Open3D, MeshLab, CloudCompare, trimesh) and
keeps every vertex property: binary files of triangles (what these tools write) straight into
numpy, any other file through trimesh's parser.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from formats.atomic import AtomicWriter
from formats.errors import InputError
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
    raise InputError(f"PLY columns must be numbers, got dtype {dtype}")


def _comment_lines(metadata: dict[str, str]) -> list[str]:
    lines = []
    for key, value in metadata.items():
        text = f"{key} {value}"
        if " " in key or "\n" in text or "\r" in text:
            raise InputError(f"PLY comment {key!r} must be one line with a one-word key")
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

    missing_dir_error = InputError

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
                raise InputError(f"{self.path}: column {name!r} has values beyond the "
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
            raise InputError(f"{self.path}: wrote {self._written} rows and "
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


# The encodings of PLY 1.0 (Turk 1994; the only version there is).
_ENCODINGS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_VERSION = "1.0"
# Fewest indices of a polygon in a face element.
_MIN_FACE_INDICES = 3
_FACE_LISTS = ("vertex_indices", "vertex_index")


@dataclass(frozen=True)
class PlyHeader:
    """A PLY header, checked against the format (``read_header``).

    Attributes
    ----------
    encoding : {"ascii", "binary_little_endian", "binary_big_endian"}
    elements : tuple of (name, count, properties)
        In file order; each property is ``(name, kind)`` with ``kind`` a numpy type code
        (``"f4"``) or, for a list, ``(count code, item code)``.
    offset : int
        Byte offset of the body.
    metadata : dict of str to str
        The ``comment KEY VALUE`` lines (``comment Created by X`` too: the first word is the key).
    """

    encoding: str
    elements: tuple
    offset: int
    metadata: dict

    def count(self, name: str) -> int:
        """Declared number of ``name`` elements (0 when there is no such element)."""
        return sum(n for element, n, _ in self.elements if element == name)

    def describe(self) -> str:
        """The declared counts in words: ``400 vertex and 2 face``."""
        words = [f"{n:,} {name}" for name, n, _ in self.elements]
        return " and ".join([", ".join(words[:-1]), words[-1]] if len(words) > 1 else words)


def _ply_kind(word: str, path, line: int) -> str:
    kind = _NUMPY_OF_PLY.get(word)
    if kind is None:
        raise InputError(f"{path}: PLY header line {line}: unknown property type {word!r}")
    return kind


def _ply_format(path: Path, words: list[str]) -> str:
    """The encoding of a ``format <encoding> 1.0`` line."""
    if len(words) != 3 or words[1] not in _ENCODINGS:
        raise InputError(f"{path}: PLY format {' '.join(words[1:])!r} is not one of "
                              f"{', '.join(_ENCODINGS)}")
    if words[2] != _VERSION:
        raise InputError(f"{path}: PLY version {words[2]!r} is not supported (the format "
                              f"has version {_VERSION})")
    return words[1]


def _ply_element(path: Path, words: list[str], number: int) -> tuple[str, int, list]:
    """A new ``element <name> <count>`` with no properties yet."""
    if len(words) != 3 or not words[2].isdigit():
        raise InputError(f"{path}: PLY header line {number}: element "
                              f"{' '.join(words[1:])!r} needs a name and a count")
    return words[1], int(words[2]), []


def _ply_property(path: Path, text: str, number: int, elements: list) -> tuple:
    """A ``property <type> <name>`` or ``property list <count type> <item type> <name>`` line
    as ``(name, kind)``; ``kind`` is a tuple for a list."""
    if not elements:
        raise InputError(f"{path}: PLY header line {number}: a property before any "
                              "element")
    words = text.split()
    if len(words) == 5 and words[1] == "list":
        return words[-1], (_ply_kind(words[2], path, number), _ply_kind(words[3], path, number))
    if len(words) == 3:
        return words[-1], _ply_kind(words[1], path, number)
    raise InputError(f"{path}: PLY header line {number}: malformed property "
                          f"{text.strip()!r}")


def _header_line(path: Path, text: str, number: int, state: dict) -> None:
    """Apply one header line (not ``end_header``) to ``state``: ``encoding``, ``elements``
    (name, count, properties) and ``metadata`` (the first comment of each key)."""
    words = text.split()
    key = words[0]
    if key in ("comment", "obj_info"):
        parts = text.split(None, 2)
        if key == "comment" and len(parts) == 3:
            state["metadata"].setdefault(parts[1], parts[2].strip())
    elif key == "format":
        state["encoding"] = _ply_format(path, words)
    elif key == "element":
        state["elements"].append(_ply_element(path, words, number))
    elif key == "property":
        prop = _ply_property(path, text, number, state["elements"])
        state["elements"][-1][2].append(prop)
    else:
        raise InputError(f"{path}: PLY header line {number}: unknown keyword "
                              f"{key[:40]!r}")


def read_header(path) -> PlyHeader:
    """Read and check the header of the PLY file ``path``.

    Refused, each with one line naming the file: no ``ply`` magic, a format other than
    ``ascii``, ``binary_little_endian`` or ``binary_big_endian``, a version other than 1.0,
    an element count that is not a non-negative integer, an unknown property type, a property
    before any element, an unknown header line, and a header without ``end_header``.

    Raises
    ------
    InputError
    """
    path = check_source(path, InputError)
    state = {"encoding": None, "elements": [], "metadata": {}}
    with open(path, "rb") as fh:
        if fh.readline(16).rstrip(b"\r\n") != b"ply":
            raise InputError(f"{path}: not a PLY file (no 'ply' magic line)")
        for number in range(2, _MAX_HEADER_LINES):
            raw = fh.readline(4096)
            if not raw:
                break
            text = raw.decode("ascii", errors="replace")
            if not text.split():
                continue
            if text.split()[0] != "end_header":
                _header_line(path, text, number, state)
                continue
            if state["encoding"] is None:
                raise InputError(f"{path}: PLY header has no format line")
            return PlyHeader(state["encoding"], tuple(state["elements"]), fh.tell(),
                             state["metadata"])
    raise InputError(f"{path}: PLY header has no end_header line")


def _min_record_bytes(name: str, properties) -> tuple[int, bool]:
    """Fewest bytes of one binary record of element ``name``, and whether its size is fixed.

    A face's index list holds at least ``_MIN_FACE_INDICES`` items; other lists may be empty.
    """
    size, fixed = 0, True
    for prop, kind in properties:
        if isinstance(kind, tuple):
            least = _MIN_FACE_INDICES if name == "face" and prop in _FACE_LISTS else 0
            size += np.dtype(kind[0]).itemsize + least * np.dtype(kind[1]).itemsize
            fixed = False
        else:
            size += np.dtype(kind).itemsize
    return size, fixed


def check_body(path, header: PlyHeader) -> None:
    """Refuse a PLY body that does not hold what the header declares, before reading it.

    Binary: the body's size must be the declared records' (at least, with lists: a face has at
    least 3 indices); ASCII: one non-empty line per declared element (trailing blank lines
    aside). Checked from the file's size and lines, so a header declaring 10**12 faces costs
    nothing.

    Raises
    ------
    InputError
        Naming the file, the declared counts and what the body holds.
    """
    path = Path(path)
    body = path.stat().st_size - header.offset
    if header.encoding != "ascii":
        least, exact = 0, True
        for name, count, properties in header.elements:
            size, fixed = _min_record_bytes(name, properties)
            least += count * size
            exact = exact and fixed
        if body < least or (exact and body != least):
            need = f"{least:,}" if exact else f"at least {least:,}"
            raise InputError(f"{path}: the PLY header declares {header.describe()} "
                                  f"elements ({need} bytes) but the body holds {body:,} bytes")
        return
    with open(path, "rb") as fh:
        fh.seek(header.offset)
        text = fh.read().rstrip()
    empty = re.search(rb"(?:^|\n)[ \t\r]*\n", text)
    if empty is not None:
        line = text[:empty.end()].count(b"\n")
        raise InputError(f"{path}: line {line} of the ASCII PLY body is empty (the format "
                              "has one element per line)")
    lines = text.count(b"\n") + 1 if text else 0
    declared = sum(n for _, n, _ in header.elements)
    if lines != declared:
        raise InputError(f"{path}: the PLY header declares {header.describe()} elements "
                              f"({declared:,} lines) but the body has {lines:,} lines")
    _check_ascii_values(path, header, _values_per_line(text, lines))


def _values_per_line(text: bytes, lines: int) -> np.ndarray:
    """Whitespace-separated values on each line of ``text`` (lines, int64), counted with
    array operations over its bytes."""
    data = np.frombuffer(text, dtype=np.uint8)
    space = np.isin(data, np.frombuffer(b" \t\r\n\v\f", dtype=np.uint8))
    starts = ~space & np.concatenate([[True], space[:-1]])
    line = np.cumsum(data == ord("\n")) - (data == ord("\n"))
    return np.bincount(line[starts], minlength=lines)


def _check_ascii_values(path, header: PlyHeader, values: np.ndarray) -> None:
    """Each ASCII line holds its element's values: exactly one per property, or, with lists,
    at least one per scalar property and list count."""
    first = 0
    for name, count, properties in header.elements:
        block = values[first:first + count]
        lists = any(isinstance(kind, tuple) for _, kind in properties)
        bad = np.flatnonzero(block < len(properties) if lists else block != len(properties))
        if len(bad):
            line = first + int(bad[0]) + 1
            want = f"at least {len(properties)}" if lists else str(len(properties))
            raise InputError(f"{path}: line {line:,} of the ASCII PLY body holds "
                                  f"{int(block[bad[0]])} values where a {name} element has "
                                  f"{want}")
        first += count


def read_ply_metadata(path) -> dict[str, str]:
    """The ``comment KEY VALUE`` lines of a PLY file's header, without reading its data."""
    return read_header(path).metadata


def _face_lists(path, raw: dict, n_vertices: int) -> None:
    """Refuse face elements whose index lists have fewer than 3 items or index missing
    vertices (``raw``: trimesh's ``_ply_raw``); a reader that dropped them would give a mesh
    with holes that looks complete."""
    face = raw.get("face", {}).get("data")
    if face is None:
        return
    names = face.dtype.names if isinstance(face, np.ndarray) else list(face)
    name = next((k for k in _FACE_LISTS if k in (names or ())), None)
    if name is None:
        return
    lists = face[name]
    if isinstance(lists, np.ndarray) and lists.dtype.names:   # binary: (count, items) records
        counts, items = lists[lists.dtype.names[0]], lists[lists.dtype.names[1]]
        width = items.shape[1] if items.ndim == 2 else 1
        bad = np.flatnonzero(counts != width)
        sizes = np.where(counts == width, width, counts)
    elif isinstance(lists, np.ndarray) and lists.dtype != object:   # ASCII, equal lengths
        items = lists.reshape(len(lists), -1)
        sizes = np.full(len(items), items.shape[1])
        bad = np.zeros(0, dtype=np.intp)
    else:   # ASCII, lists of different lengths
        sizes = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
        items = np.concatenate([np.asarray(x).ravel() for x in lists]) if len(lists) else None
        bad = np.zeros(0, dtype=np.intp)
    if len(bad):
        raise InputError(f"{path}: face {int(bad[0])} declares {int(counts[bad[0]])} "
                              f"indices where the binary PLY holds {width}")
    small = np.flatnonzero(sizes < _MIN_FACE_INDICES)
    if len(small):
        raise InputError(f"{path}: face {int(small[0])} has {int(sizes[small[0]])} "
                              f"vertex indices; a face needs at least {_MIN_FACE_INDICES}")
    if items is not None and np.size(items):
        items = np.asarray(items)
        if items.min() < 0 or items.max() >= n_vertices:
            raise InputError(f"{path}: faces index vertices that do not exist (the file "
                                  f"has {n_vertices:,} vertices, indices run "
                                  f"{int(items.min())}..{int(items.max())})")


def read_ply(path) -> tuple[dict[str, np.ndarray], np.ndarray | None, dict[str, str]]:
    """Read every vertex property of an ASCII or binary PLY file, its triangles and metadata.

    The header and the body's size are checked first (``read_header``, ``check_body``), the
    faces after parsing: each needs 3 or more indices of existing vertices (polygons are
    triangulated).

    Returns
    -------
    columns : dict of str to (n,) arrays
    faces : (m, 3) int64 or None
    metadata : dict of str to str
        The header's ``comment KEY VALUE`` lines.

    Raises
    ------
    InputError
        A header, body or face that breaks the format, naming the file.
    """
    header = read_header(path)
    path = Path(path)
    check_body(path, header)
    fixed = _read_fixed_binary(path, header)
    if fixed is not None:
        return (*fixed, header.metadata)
    from trimesh.exchange.ply import load_ply

    try:
        with open(path, "rb") as fh:
            loaded = load_ply(fh, prefer_color="vertex")
    except Exception as exc:  # trimesh's parser raises many types on malformed input
        raise InputError(f"{path}: not a readable PLY file ({type(exc).__name__})") from None
    raw = loaded.get("metadata", {}).get("_ply_raw", {})
    vertex = raw.get("vertex", {}).get("data")
    if vertex is None:
        raise InputError(f"{path}: PLY file has no vertex element")
    # binary files give a structured array, ASCII files a dict of arrays
    names = vertex.dtype.names if isinstance(vertex, np.ndarray) else list(vertex)
    columns = {name: np.asarray(vertex[name]).reshape(-1) for name in names}
    n_vertices = header.count("vertex")
    if any(len(c) != n_vertices for c in columns.values()):
        raise InputError(f"{path}: the PLY header declares {n_vertices:,} vertices but "
                              f"{min(len(c) for c in columns.values()):,} were read")
    _face_lists(path, raw, n_vertices)
    faces = loaded.get("faces")
    faces = None if faces is None or len(faces) == 0 else np.asarray(faces, dtype=np.int64)
    return columns, faces, header.metadata


def _fixed_record(properties, byte_order: str) -> np.dtype | None:
    """The record dtype of an element whose lists all hold three items (a triangle's index
    list) and whose other properties are scalars; None when another list makes records vary."""
    fields = []
    for name, kind in properties:
        if not isinstance(kind, tuple):
            fields.append((name, byte_order + kind))
        elif name in _FACE_LISTS:
            fields.append((name, [("count", byte_order + kind[0]),
                                  ("items", byte_order + kind[1], (3,))]))
        else:
            return None
    names = [name for name, _ in fields]
    return np.dtype(fields) if len(set(names)) == len(names) else None


def _fixed_layout(path: Path, header: PlyHeader) -> list[tuple[str, int, np.dtype]] | None:
    """``(name, count, record dtype)`` of each element of a binary PLY with a vertex element
    whose records all have one size (``_fixed_record``) filling the body exactly; else None."""
    byte_order = _ENCODINGS[header.encoding]
    names = [name for name, _, _ in header.elements]
    if byte_order is None or "vertex" not in names or len(set(names)) != len(names):
        return None
    layout = [(name, count, _fixed_record(properties, byte_order))
              for name, count, properties in header.elements]
    if any(dtype is None for _, _, dtype in layout):
        return None
    size = sum(count * dtype.itemsize for _, count, dtype in layout)
    return layout if path.stat().st_size - header.offset == size else None


def _triangles(path: Path, face: np.ndarray | None, n_vertices: int):
    """The (m, 3) int64 triangles of a face element read by ``_fixed_layout``'s dtype (None
    without faces), or False when its lists are not all triangles (trimesh reads those)."""
    if face is None or len(face) == 0:
        return None
    lists = [k for k in _FACE_LISTS if k in (face.dtype.names or ())]
    if not lists or np.any(face[lists[0]]["count"] != 3):
        return False   # no index list, or polygons of other sizes filling the same bytes
    faces = face[lists[0]]["items"].astype(np.int64)
    if faces.min() < 0 or faces.max() >= n_vertices:
        raise InputError(f"{path}: faces index vertices that do not exist (the file "
                              f"has {n_vertices:,} vertices, indices run "
                              f"{int(faces.min())}..{int(faces.max())})")
    return faces


def _read_fixed_binary(path: Path, header: PlyHeader):
    """Vertex columns and triangles of a binary PLY whose every face is a triangle, read
    straight into numpy (the files recon, Open3D, MeshLab and trimesh write); None for any
    other file (ASCII, polygons, extra lists), which trimesh's parser reads.

    Returns
    -------
    (columns, faces) or None
        As ``read_ply``: columns dict of str to (n,) native-order arrays; faces (m, 3) int64
        or None.
    """
    layout = _fixed_layout(path, header)
    if layout is None:
        return None
    data = {}
    with open(path, "rb") as fh:
        fh.seek(header.offset)
        for name, count, dtype in layout:
            data[name] = np.fromfile(fh, dtype=dtype, count=count)
    vertex = data["vertex"]
    faces = _triangles(path, data.get("face"), len(vertex))
    if faces is False:
        return None
    columns = {name: vertex[name].astype(vertex.dtype[name].newbyteorder("="))
               for name in vertex.dtype.names}
    return columns, faces


# PLY scalar types (both spellings) as numpy type codes, for reading any binary PLY.
_NUMPY_OF_PLY = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
                 "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
                 "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
                 "float64": "f8"}


def binary_vertex_layout(path) -> tuple[np.dtype, int, int, dict[str, str]] | None:
    """Where a binary PLY file keeps its vertices, for reading them block by block.

    The header is checked (``read_header``) and the body's size against it (``check_body``).

    Returns
    -------
    (dtype, offset, count, metadata) or None
        The vertex record's structured dtype, the byte offset of the first vertex, the number
        of vertices and the header's comments; None when the file cannot be read that way (an
        ASCII file, vertices that are not the first element or hold lists, any faces).
    """
    header = read_header(path)
    check_body(path, header)
    elements = header.elements
    byte_order = _ENCODINGS[header.encoding]
    if byte_order is None or not elements or elements[0][0] != "vertex":
        return None
    if any(n > 0 for _, n, _ in elements[1:]) or any(isinstance(k, tuple)
                                                     for _, k in elements[0][2]):
        return None
    names = [name for name, _ in elements[0][2]]
    if len(set(names)) != len(names):
        return None
    dtype = np.dtype([(name, byte_order + kind) for name, kind in elements[0][2]])
    return dtype, header.offset, elements[0][1], header.metadata
