"""Open what a user hands a command: a point cloud, a mesh, or a strike log.

``.h5`` files are told apart by their root ``format`` attribute (a strike log or a recon point
cloud); a ``.ply`` with faces is a mesh, without faces a cloud; ``.obj``, ``.stl``, ``.off``,
glTF and the planetary shape models (``.tab``, ``.icq``, ``.bds``, ``.dsk``) are meshes;
``.las``/``.laz`` are clouds. A strike log given as a cloud is registered into
the body frame on the fly (``recon.registration.ingest``); given as a truth, its embedded truth
mesh is used.
"""

from __future__ import annotations

import os
from pathlib import Path

from formats.cloud_io import CLOUD_SUFFIXES, cloud_from_ply_columns, read_cloud
from formats.errors import InputError
from formats.geometry import Cloud, Mesh
from formats.hdf5_check import check_hdf5, is_hdf5
from formats.mesh_io import MESH_SUFFIXES, read_mesh
from formats.paths import check_source
from formats.ply import read_ply
from metrics.inputs import as_mesh


def is_strike_log(path) -> bool:
    """True when ``path`` is an HDF5 file whose root ``format`` names a strike log.

    Raises
    ------
    InputError
        An HDF5 file that is damaged or reads other files (``formats.hdf5_check``).
    """
    path = Path(path)
    if (path.suffix.lower() != ".h5" or not path.is_file()
            or not is_hdf5(path, InputError)):
        return False
    import h5py  # HDF5 only for .h5 files: reading a PLY or a mesh does not pay for it

    from formats.strike_log import FORMAT_NAME

    check_hdf5(path, InputError)
    try:
        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format")
    except OSError:
        return False
    return (fmt.decode() if isinstance(fmt, bytes) else fmt) == FORMAT_NAME


def walk_early(*sources) -> None:
    """Walk the HDF5 structure of each source that is a strike log now (``is_strike_log``).

    The walk runs in a forked child while recon has one thread, but in a fresh interpreter
    (0.6 s of CPU) once it has more (``formats.hdf5_check``): a command that starts worker
    threads walks its files first. The verdict is kept, so reading them later walks nothing.

    Parameters
    ----------
    *sources : str, PathLike or anything else (ignored)
    """
    for source in sources:
        if isinstance(source, str | os.PathLike):
            is_strike_log(source)


def load_geometry(path, *, points_only: bool = False) -> Cloud | Mesh:
    """A ``Cloud`` or a ``Mesh`` from any supported file, each file read once.

    Strike logs are ingested into a body-frame cloud; with ``points_only`` (scoring) without
    the per-point attributes, in a third of the memory.
    """
    path = check_source(path, InputError)
    suffix = path.suffix.lower()
    if is_strike_log(path):
        # scipy's Rotation, which ingest needs, is imported only when a log is read.
        from recon.registration.ingest import ingest, ingest_points

        return Cloud(ingest_points(path)) if points_only else ingest(path)
    if suffix == ".ply":
        columns, faces, metadata = read_ply(path)
        cloud = cloud_from_ply_columns(path, columns, metadata)
        return cloud if faces is None else Mesh(cloud.points, faces, frame=cloud.frame)
    if suffix in MESH_SUFFIXES:
        return read_mesh(path)
    if suffix in CLOUD_SUFFIXES:
        return read_cloud(path)
    raise InputError(f"{path}: unknown suffix {path.suffix!r}: expected a point cloud "
                          f"({', '.join(CLOUD_SUFFIXES)}), a mesh ({', '.join(MESH_SUFFIXES)}) "
                          "or a strike log (.h5)")


def load_cloud(path) -> Cloud:
    """A point cloud from a cloud file or a strike log (ingested); a mesh is refused."""
    geometry = load_geometry(path)
    if not isinstance(geometry, Cloud):
        raise InputError(f"{path}: is a mesh, expected a point cloud or a strike log")
    return geometry


def load_truth(path, *, scale: float = 1.0, units: str | None = None) -> Mesh:
    """The truth mesh from a mesh file or from a strike log's ``/truth/mesh``.

    Parameters
    ----------
    path : str or Path
    scale : float
        Factor applied to a mesh file's coordinates (e.g. 1000 for km); logs are in metres.
    units : {"km", "m"}, optional
        Units of a mesh file's coordinates (default: the format's, ``formats.mesh_io``).
    """
    path = check_source(path, InputError)
    if is_strike_log(path):
        from formats import StrikeLog

        with StrikeLog(path) as log:
            if not log.has_truth:
                raise InputError(f"truth: {path} is a strike log without a truth mesh; "
                                 "give a mesh file as the truth", argument="truth")
            mesh = log.truth_mesh()
    elif path.suffix.lower() in CLOUD_SUFFIXES and path.suffix.lower() != ".ply":
        raise InputError(f"{path}: is not a mesh (truth must be a mesh file or a strike "
                              "log with truth)")
    else:
        mesh = read_mesh(path, scale=scale, units=units)
    return as_mesh(mesh, f"truth {path}")   # degenerate or far-off truths, named by file
