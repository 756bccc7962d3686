"""Shape models in the forms planetary missions publish them: PDS vertex/plate tables, Gaskell's
ICQ grids and SPICE DSK type 2 kernels.

Each reader returns vertices in the file's units with 0-based ``(m, 3)`` triangles and the
frame the file records; ``formats.mesh_io.read_mesh`` converts to metres and picks the reader
by suffix (and, for ``.tab``, by content). Layouts, as their publishers specify them:

PDS vertex/plate table, ``v``/``f`` form (``.tab``; the PDS Small Bodies Node radar shape models)
    one row per vertex ``v x y z`` then one row per triangle ``f i j k``, indices 1-based into
    the vertex rows.
PDS vertex/plate table, two-table form (``.tab``; PDS SBN plate models such as Gaskell's)
    a line with the vertex count N, N rows ``id x y z``, a line with the plate count M, M rows
    ``id i j k``; plate corners name vertex ids (1-based).
ICQ, implicitly connected quadrilaterals (``.icq``, or ``.tab`` of that layout; Gaskell's SPC
    global topography models)
    a line with Q, then 6 (Q+1)^2 rows ``x y z``: six cube faces F = 1..6, each a grid of
    vertices v(I, J, F) with I = 0..Q varying fastest, then J. Facet f(I, J, F) joins v(I, J),
    v(I, J+1), v(I+1, J+1), v(I+1, J); it is split into two triangles along v(I, J)-v(I+1, J+1).
    The cube's 12 edges and 8 corners repeat vertices of neighbouring faces, welded here: a
    valid grid leaves 6 Q^2 + 2 distinct vertices and a closed surface.
SPICE DSK type 2 (``.bds``, ``.dsk``; NAIF DSK Required Reading)
    triangular plate segments, vertices in km in the segment's body-fixed frame, plates 1-based;
    every type 2 segment of the file is read and merged.

Units: DSK is km by definition. The text forms state none; PDS and SPC publish them in km, the
default (``DEFAULT_UNITS``); a file in metres is read with ``units="m"``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from formats.atomic import write_atomically
from formats.errors import InputError
from formats.paths import check_source
from formats.spice import LOCK, TARGET_FRAME, TARGET_FRAME_ID, TARGET_ID

# Units of the planetary formats when the caller states none: DSK is km by definition (NAIF DSK
# Required Reading); PDS SBN shape-model tables and SPC's ICQ files are published in km.
DEFAULT_UNITS = {".tab": "km", ".icq": "km", ".bds": "km", ".dsk": "km"}
SHAPE_SUFFIXES = tuple(DEFAULT_UNITS)
DSK_SUFFIXES = (".bds", ".dsk")
METRES_PER = {"m": 1.0, "km": 1000.0}

# The target's identities (body RECON_TARGET and its frame RECON_TARGET_FIXED) are those of the
# kernels recon writes (formats/spice.py).
SURFACE_ID = 1
# DSK type 2 spatial index (NAIF dskmi2): fine voxels 5 plates across and coarse voxels of 4^3
# fine ones, the values of NAIF's own dskw02 example. The integer index starts with a fixed part
# of SPICE_DSK02_IXIFIX = SPICE_DSK02_MAXCGR (100,000) + 7 ints. The voxel-plate lists took
# 1.6-1.9 ints a plate on the shared test models (2.3k-63k plates, asteroids and spacecraft);
# 16 a plate leaves room for slivers that cross many voxels.
DSK_FINE_SCALE = 5.0
DSK_COARSE_SCALE = 4
DSK_INDEX_FIXED = 100_007
DSK_LIST_PER_PLATE = 16
# Inertial frames built into SPICE have IDs 1-21 (J2000, ECLIPJ2000, ...; Frames Required
# Reading); a DSK segment in one of them is read as inertial, any other frame as the body frame.
SPICE_INERTIAL_IDS = range(1, 22)


def units_factor(units: str, where) -> float:
    """Metres per file unit of ``units`` (``"km"`` or ``"m"``)."""
    if units not in METRES_PER:
        raise InputError(f"{where}: units must be km or m, got {units!r}")
    return METRES_PER[units]


# --------------------------------------------------------------------------- text tables


def _numbers(path: Path, tokens: list[str], what: str) -> np.ndarray:
    """``tokens`` as float64 (Fortran ``1.0D+03`` exponents accepted), or a one-line error
    naming the first word that is not a number and its line."""
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        pass
    try:
        return np.array([t.replace("D", "E").replace("d", "e") for t in tokens],
                        dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not _is_number(t))
        raise InputError(f"{path}: {what} holds {bad!r}, not a number "
                              f"(line {_line_of(path, bad)})") from None


def _is_number(token: str) -> bool:
    try:
        float(token.replace("D", "E").replace("d", "e"))
    except ValueError:
        return False
    return True


def _line_of(path: Path, token: str) -> int:
    text = path.read_text(encoding="utf-8", errors="replace")
    match = re.search(rf"(?<!\S){re.escape(token)}(?!\S)", text)
    return text.count("\n", 0, match.start()) + 1 if match else 0


def _indices(path: Path, values: np.ndarray, what: str) -> np.ndarray:
    """Whole numbers of ``values`` as int64, or an error naming ``what``."""
    if not np.all(np.isfinite(values)) or np.any(values != np.round(values)):
        bad = values[~np.isfinite(values) | (values != np.round(values))][0]
        raise InputError(f"{path}: {what} must be whole numbers, found {bad:g}")
    return values.astype(np.int64)


def _count(path: Path, token: str, what: str) -> int:
    if not token.isdigit():
        raise InputError(f"{path}: expected the {what} count (a whole number), found "
                              f"{token[:40]!r}")
    return int(token)


def read_pds_table(path) -> tuple[np.ndarray, np.ndarray, str]:
    """Read a PDS vertex/plate table (``v``/``f`` or two-table form) or an ICQ grid, by content.

    Returns
    -------
    vertices : (n, 3) float64, file units
    faces : (m, 3) int64, 0-based
    layout : {"v/f", "plates", "icq"}

    Raises
    ------
    InputError
        Not one of the layouts, counts that disagree with the rows, indices that name no
        vertex, words that are not numbers; one line naming the file.
    """
    path = check_source(path, InputError)
    try:
        tokens = path.read_text(encoding="utf-8", errors="replace").split()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    if not tokens:
        raise InputError(f"{path}: is empty")
    if tokens[0].lower() == "v":
        return (*_read_vf(path, tokens), "v/f")
    n = _count(path, tokens[0], "vertex (or ICQ Q)")
    if len(tokens) == 1 + 18 * (n + 1) ** 2 and not _looks_like_plates(tokens, n):
        return (*_icq_mesh(path, n, _numbers(path, tokens[1:], "the ICQ grid")), "icq")
    return (*_read_plates(path, tokens, n), "plates")


def _looks_like_plates(tokens: list[str], n: int) -> bool:
    """Whether the token after N rows of four is a plate count matching the rest."""
    at = 1 + 4 * n
    return at < len(tokens) and tokens[at].isdigit() and \
        len(tokens) == at + 1 + 4 * int(tokens[at])


def _read_vf(path: Path, tokens: list[str]) -> tuple[np.ndarray, np.ndarray]:
    if len(tokens) % 4:
        raise InputError(f"{path}: every row of a v/f table is 'v x y z' or 'f i j k'; "
                              f"{len(tokens)} words do not make rows of four")
    rows = np.array(tokens, dtype=object).reshape(-1, 4)
    tags = np.char.lower(rows[:, 0].astype(str))
    unknown = sorted(set(tags) - {"v", "f"})
    if unknown:
        raise InputError(f"{path}: rows must start with v or f, found {unknown[0]!r}")
    vertices = _numbers(path, list(rows[tags == "v", 1:].ravel()),
                        "a vertex row").reshape(-1, 3)
    faces = _indices(path, _numbers(path, list(rows[tags == "f", 1:].ravel()), "a facet row"),
                     "facet indices").reshape(-1, 3) - 1
    _check_faces(path, faces, len(vertices), "facet", base=1)
    return vertices, faces


def _read_plates(path: Path, tokens: list[str], n: int) -> tuple[np.ndarray, np.ndarray]:
    at = 1 + 4 * n
    if at >= len(tokens):
        raise InputError(f"{path}: says {n} vertices but holds {(len(tokens) - 1) // 4} "
                              "rows of 'id x y z' and no plate table")
    m = _count(path, tokens[at], "plate")
    if len(tokens) != at + 1 + 4 * m:
        raise InputError(f"{path}: says {n} vertices and {m} plates, which take "
                              f"{at + 1 + 4 * m} words; the file holds {len(tokens)}")
    vertex_rows = _numbers(path, tokens[1:at], "the vertex table").reshape(n, 4)
    plate_rows = _indices(path, _numbers(path, tokens[at + 1:], "the plate table"),
                          "plate rows").reshape(m, 4)
    ids = _indices(path, vertex_rows[:, 0], "vertex ids")
    if len(np.unique(ids)) != n:
        raise InputError(f"{path}: vertex ids repeat")
    order = np.argsort(ids)
    corners = plate_rows[:, 1:]
    where = np.searchsorted(ids[order], corners)
    found = (where < n) & (ids[order][np.minimum(where, n - 1)] == corners)
    if not found.all():
        plate = int(np.argmax(~found.all(axis=1)))
        raise InputError(f"{path}: plate {plate_rows[plate, 0]} names vertex "
                              f"{corners[~found][0]}, which the vertex table does not hold")
    return vertex_rows[:, 1:], order[where]


def _check_faces(path: Path, faces: np.ndarray, n_vertices: int, what: str, *, base: int):
    if len(faces) == 0:
        raise InputError(f"{path}: has no {what}s (a point list, not a shape model?)")
    bad = (faces < 0) | (faces >= n_vertices)
    if bad.any():
        row = int(np.argmax(bad.any(axis=1)))
        raise InputError(f"{path}: {what} {row + base} names vertex "
                              f"{faces[bad][0] + base}; the file has vertices {base}.."
                              f"{n_vertices - 1 + base}")


def _icq_mesh(path: Path, q: int, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of an ICQ grid (see the module docstring), shared edge vertices welded."""
    if q < 1:
        raise InputError(f"{path}: ICQ Q must be at least 1, got {q}")
    grid = values.reshape(6, q + 1, q + 1, 3)               # [F, J, I, xyz]
    index = np.arange(6 * (q + 1) ** 2).reshape(6, q + 1, q + 1)
    a, b = index[:, :-1, :-1], index[:, 1:, :-1]            # v(I, J), v(I, J+1)
    c, d = index[:, 1:, 1:], index[:, :-1, 1:]              # v(I+1, J+1), v(I+1, J)
    quads = np.stack([a, b, c, d], axis=-1).reshape(-1, 4)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    unique, inverse = np.unique(grid.reshape(-1, 3), axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    if len(unique) != 6 * q * q + 2:
        raise InputError(f"{path}: the ICQ faces do not meet at the cube's edges "
                              f"({len(unique)} distinct vertices, a valid Q = {q} grid has "
                              f"{6 * q * q + 2})")
    return unique, _outward(faces, unique)


def _outward(faces: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """``faces`` wound so that the enclosed volume is positive (outward normals)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return faces if np.einsum("ij,ij->", a, np.cross(b, c)) >= 0 else faces[:, ::-1].copy()


def write_pds_table(path, vertices, faces, *, form: str = "plates", units: str = "km") -> Path:
    """Write a triangle mesh as a PDS vertex/plate table (atomically).

    Parameters
    ----------
    path : str or Path
        Destination, usually ``.tab``.
    vertices : (n, 3) float64, metres
    faces : (m, 3) int, 0-based
    form : {"plates", "v/f"}
        Two-table form (counts, then ``id x y z`` and ``id i j k`` rows) or ``v``/``f`` rows.
    units : {"km", "m"}
        Units of the written coordinates (km, as PDS publishes shape models).
    """
    factor = units_factor(units, path)
    vertices = np.asarray(vertices, dtype=np.float64) / factor
    faces = np.asarray(faces, dtype=np.int64) + 1
    n, m = len(vertices), len(faces)
    if form == "plates":
        head_v, head_f = f"{n}\n", f"{m}\n"
        v_rows = np.column_stack([np.arange(1, n + 1), vertices])
        f_rows = np.column_stack([np.arange(1, m + 1), faces])
        v_fmt, f_fmt = "%d %.17g %.17g %.17g", "%d"
    elif form == "v/f":
        head_v = head_f = ""
        v_rows, f_rows = vertices, faces
        v_fmt, f_fmt = "v %.17g %.17g %.17g", "f %d %d %d"
    else:
        raise InputError(f"{path}: PDS table form must be 'plates' or 'v/f', got {form!r}")

    def write(tmp: Path) -> None:
        with open(tmp, "w", encoding="ascii") as fh:
            fh.write(head_v)
            np.savetxt(fh, v_rows, fmt=v_fmt)
            fh.write(head_f)
            np.savetxt(fh, f_rows, fmt=f_fmt)
    return write_atomically(path, write, error=InputError)


# --------------------------------------------------------------------------- SPICE DSK


def _spice_call(path, call, what: str):
    """Run ``call(spiceypy)`` under the toolkit lock; SPICE errors become one line naming
    ``path`` and ``what`` failed."""
    import spiceypy
    from spiceypy.utils.exceptions import SpiceyError

    with LOCK:   # the toolkit's one global state, shared with formats/spice.py
        try:
            return call(spiceypy)
        except SpiceyError as exc:
            short = getattr(exc, "short", "") or type(exc).__name__
            detail = " ".join((getattr(exc, "long", "") or "").split())
            raise InputError(f"{path}: {what} ({short} {detail})") from None


def read_dsk(path) -> tuple[np.ndarray, np.ndarray, str]:
    """Read every type 2 (plate model) segment of a SPICE DSK file.

    Returns
    -------
    vertices : (n, 3) float64, km, in the segments' frame
    faces : (m, 3) int64, 0-based
    frame : {"body", "inertial"}
        ``"inertial"`` when the segments' frame is one of SPICE's built-in inertial frames,
        else ``"body"`` (a shape model's body-fixed frame).

    Raises
    ------
    InputError
        Not a DSK file, no type 2 segment, segments in different frames or of different bodies.
    """
    path = check_source(path, InputError)

    def read(sp):
        handle = sp.dasopr(str(path))
        segments = []
        try:
            with sp.no_found_check():
                dladsc, found = sp.dlabfs(handle)
                while found:
                    descriptor = sp.dskgd(handle, dladsc)
                    if descriptor.dtype == 2:
                        nv, np_ = sp.dskz02(handle, dladsc)
                        segments.append((
                            descriptor.center, descriptor.frmcde,
                            np.asarray(sp.dskv02(handle, dladsc, 1, nv), np.float64),
                            np.asarray(sp.dskp02(handle, dladsc, 1, np_), np.int64)))
                    dladsc, found = sp.dlafns(handle, dladsc)
        finally:
            sp.dascls(handle)
        return segments

    segments = _spice_call(path, read, "not a readable DSK file")
    if not segments:
        raise InputError(f"{path}: holds no DSK type 2 (plate model) segment")
    if len({(center, frame) for center, frame, _, _ in segments}) > 1:
        raise InputError(f"{path}: its segments describe different bodies or frames; "
                              "recon reads one body in one frame")
    offsets = np.cumsum([0] + [len(v) for _, _, v, _ in segments[:-1]])
    vertices = np.concatenate([v for _, _, v, _ in segments])
    faces = np.concatenate([p - 1 + o for (_, _, _, p), o in zip(segments, offsets,
                                                                  strict=True)])
    frame = "inertial" if segments[0][1] in SPICE_INERTIAL_IDS else "body"
    return vertices, faces, frame


def write_dsk(path, vertices, faces, *, center: int = TARGET_ID, frame: str = TARGET_FRAME,
              frame_id: int = TARGET_FRAME_ID, surface_id: int = SURFACE_ID,
              comment: str = "") -> Path:
    """Write a triangle mesh as a SPICE DSK file with one type 2 segment (atomically), in km.

    Parameters
    ----------
    path : str or Path
        Destination, ``.bds`` (NAIF's suffix) or ``.dsk``.
    vertices : (n, 3) float64, metres, body frame
    faces : (m, 3) int, 0-based, counter-clockwise seen from outside
    center : int
        NAIF ID of the body (default ``RECON_TARGET``, -998, as in recon's SPK and FK).
    frame, frame_id : str, int
        The body-fixed frame of the segment and its ID (default ``RECON_TARGET_FIXED``,
        1499902, the frame recon's FK defines). A frame SPICE does not know is made known for
        the write only.
    surface_id : int
    comment : str
        Kept as the file's internal name (first 60 characters).

    Notes
    -----
    The segment covers all longitudes and latitudes (latitudinal coordinates) between the
    model's smallest and largest radius, at all times, as a general surface (data class 2):
    the model may be any closed or open triangle mesh.
    """
    vertices_km = np.asarray(vertices, dtype=np.float64) / METRES_PER["km"]
    plates = np.asarray(faces, dtype=np.int64) + 1
    if len(plates) == 0 or vertices_km.ndim != 2 or vertices_km.shape[1] != 3:
        raise InputError(f"{path}: a DSK needs (n, 3) vertices and at least one plate")
    size = DSK_LIST_PER_PLATE * len(plates) + 10_000
    # the integer index: fixed part, voxel pointers and lists, and the vertex-plate list
    # (a count and the plates of each vertex)
    index_size = DSK_INDEX_FIXED + 2 * size + 2 * len(vertices_km) + 3 * len(plates)

    def write(tmp: Path) -> None:
        tmp.unlink()   # dskopn makes the file itself

        def call(sp):
            added = sp.namfrm(frame) == 0
            if added:   # make the frame's name known for this write only
                sp.pipool(f"FRAME_{frame}", [frame_id])
                sp.pcpool(f"FRAME_{frame_id}_NAME", [frame])
                sp.pipool(f"FRAME_{frame_id}_CLASS", [4])
                sp.pipool(f"FRAME_{frame_id}_CLASS_ID", [frame_id])
                sp.pipool(f"FRAME_{frame_id}_CENTER", [center])
            try:
                spaixd, spaixi = sp.dskmi2(vertices_km, plates, DSK_FINE_SCALE,
                                           DSK_COARSE_SCALE, size, size, size, True,
                                           index_size)
                corpar = np.zeros(10)
                r_min, r_max = sp.dskrb2(vertices_km, plates, 1, corpar)
                handle = sp.dskopn(str(tmp), (comment or "recon shape model")[:60], 0)
                try:
                    sp.dskw02(handle, center, surface_id, 2, frame, 1, corpar, -np.pi, np.pi,
                              -np.pi / 2, np.pi / 2, r_min, r_max, -1e12, 1e12,
                              vertices_km, plates, spaixd, spaixi)
                finally:
                    sp.dskcls(handle, True)
            finally:
                if added:
                    for name in (f"FRAME_{frame}", *(f"FRAME_{frame_id}_{k}" for k in
                                                     ("NAME", "CLASS", "CLASS_ID", "CENTER"))):
                        sp.dvpool(name)
        _spice_call(path, call, "cannot write the DSK file")
    return write_atomically(path, write, error=InputError)
