"""Conversions between ``MethodInput``/mesh arrays and Open3D or pymeshlab objects, the check
that a method's mesh has triangles, and the seeded perturbation qhull's Delaunay needs."""

from __future__ import annotations

import numpy as np

from formats.errors import MethodFailed
from recon.surfaces.methods import MethodInput

# Largest perturbation of a coordinate before a Delaunay tetrahedralisation, in spacings
# (``general_position``). Noise-free samples of planar facets (coplanar) or of a sphere
# (cospherical) make qhull merge facets for minutes: on the 77,400-point noise-free RSO-A LRF
# cloud alpha-shape and delaunay-balls hit recon compare's 600 s limit, and scipy's Delaunay of
# half its points took 74 s CPU (1.3 s perturbed); on 10,000 noise-free samples of a sphere it
# took 18 s CPU (0.2 s perturbed by 1e-6 or 1e-3 spacings). On the whole cloud a perturbation
# of 1e-4, 1e-6 and 1e-8 spacings took 2.5, 3.3 and 3.5 s CPU (scipy's and Open3D's qhull
# alike; docs/decisions.md). 1e-4 spacings is far below any precision a score states (0.5 %
# of the smallest Chamfer distance measured, delaunay-balls on 6000 noise-free samples of a box).
JITTER_SPACINGS = 1e-4


def general_position(points: np.ndarray, spacing: float, seed: int) -> np.ndarray:
    """``points`` moved by a seeded, uniform offset of at most ``JITTER_SPACINGS x spacing`` per
    coordinate, so that no four are coplanar and no five cospherical to qhull's precision.

    Every cloud gets it, noisy or not: telling a degenerate cloud from a general one within
    qhull's roundoff costs as much as the tetrahedralisation itself, and on a noisy cloud the
    offset is far below the noise.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
    spacing : float, metres
        ``MethodInput.spacing``.
    seed : int
        Same seed, same offsets.

    Returns
    -------
    (n, 3) float64, metres, body frame
    """
    amplitude = JITTER_SPACINGS * float(spacing)
    offset = np.random.default_rng(seed).uniform(-amplitude, amplitude, size=points.shape)
    return points + offset


# Vertices of facet j of a Delaunay cell: the facet opposite vertex j, across which
# ``scipy.spatial.Delaunay.neighbors[:, j]`` lies.
CELL_FACETS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


def boundary_faces(points: np.ndarray, simplices: np.ndarray, neighbors: np.ndarray,
                   inside: np.ndarray) -> np.ndarray:
    """The facets between inside cells and the rest (cells not inside, or beyond the convex
    hull), wound counter-clockwise seen from outside.

    Parameters
    ----------
    points : (n, 3) float64, metres
        The points the cells were built on.
    simplices, neighbors : (m, 4) int
        ``scipy.spatial.Delaunay`` cells and their neighbours (-1 beyond the hull).
    inside : (m,) bool

    Returns
    -------
    (k, 3) int, indices into ``points``
    """
    across = np.where(neighbors >= 0, ~inside[np.maximum(neighbors, 0)], True)
    keep_cell, keep_face = np.nonzero(inside[:, None] & across)
    faces = simplices[keep_cell[:, None], CELL_FACETS[keep_face]]
    apex = points[simplices[keep_cell, keep_face]]                 # inside, opposite the face
    p, q, r = (points[faces[:, i]] for i in range(3))
    inward = np.einsum("ij,ij->i", np.cross(q - p, r - p), apex - p) > 0
    faces[inward] = faces[inward][:, ::-1]
    return faces


def source_side(n_nodes: int, rows: np.ndarray, cols: np.ndarray, capacity: np.ndarray,
                source: int, sink: int) -> np.ndarray:
    """The nodes on the source side of a minimum ``source``-``sink`` cut of a directed graph:
    the nodes the source reaches in the residual graph of a maximum flow (the smallest such
    side), by Boykov-Kolmogorov (``_min_cut``).

    Parameters
    ----------
    n_nodes : int
    rows, cols : (e,) int
        Edges ``rows[i] -> cols[i]`` (repeats add up).
    capacity : (e,) int
        Their capacities (integers; a pair's summed capacity is capped at the int32 maximum).
    source, sink : int

    Returns
    -------
    (n_nodes,) bool
    """
    from scipy.sparse import coo_matrix

    from recon.surfaces.methods import _min_cut

    graph = coo_matrix((np.asarray(capacity, dtype=np.int64), (rows, cols)),
                       shape=(n_nodes, n_nodes)).tocsr()
    graph.sum_duplicates()
    np.minimum(graph.data, np.iinfo(np.int32).max, out=graph.data)
    return _min_cut.source_side(n_nodes, graph.indptr, graph.indices, graph.data, source, sink)


def open3d_cloud(cloud: MethodInput):
    """An ``open3d.geometry.PointCloud`` with the cloud's points and oriented normals."""
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points))
    pcd.normals = o3d.utility.Vector3dVector(cloud.normals)
    return pcd


def with_triangles(vertices: np.ndarray, faces: np.ndarray, failure: str
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` unchanged, unless there are no faces.

    Parameters
    ----------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    failure : str
        Message of the ``MethodFailed`` raised when ``faces`` is empty, naming the method and
        the setting that gave nothing (``"ball-pivoting: no triangles with radii [...] m"``).

    Returns
    -------
    vertices, faces : as given
    """
    if len(faces) == 0:
        raise MethodFailed(failure)
    return vertices, faces


def open3d_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` of an ``open3d.geometry.TriangleMesh``."""
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles, dtype=np.int64)


# Fewest faces that must survive dropping NaN vertices (``meshlab_arrays``): below half, the
# surface is more hole than surface.
MIN_FINITE_FRACTION = 0.5
# Bounds of the automatic marching-cubes resolution (cells along the longest side): below 32 a
# target is a handful of voxels; MeshLab documents values "up to 1000 or even more".
AUTO_RESOLUTION_RANGE = (32, 1000)


def above_noise(cloud: MethodInput, spacings: float, noises: float) -> float:
    """A length no finer than the samples nor the noise: ``max(spacings x spacing, noises x
    noise)``, metres.

    The automatic cells and balls of the grid and pivoting methods. Where the out-of-surface
    scatter is comparable to the spacing (the paper's clouds: RSO-A's LRF tracks, 0.035 m noise
    at 0.048 m spacing; the asteroid LIDAR, 0.73 m at 0.92 m), a cell or ball of one spacing
    resolves the noise itself: spurious sheets and bubbles, several times the faces (and the
    time) for no accuracy (``benchmarks/bench_methods.py``). On clean clouds (noise well below
    the spacing) it is ``spacings x spacing``.

    Parameters
    ----------
    cloud : MethodInput
    spacings, noises : float
        Multiples of ``cloud.spacing`` and of ``cloud.noise``.
    """
    return max(float(spacings) * cloud.spacing, float(noises) * cloud.noise)


def auto_resolution(cloud: MethodInput, resolution: int | None) -> int:
    """``resolution`` or, when None, one grid cell per spacing along the longest side.

    One spacing, noise or not (unlike ``above_noise``): MeshLab's MLS projection from nodes
    farther than its kernel (filter_scale x the local spacing) diverges, so a coarser grid leaves
    holes. On the 336k-point asteroid LIDAR cloud cells of 3 x noise (2.4 spacings) took RIMLS
    from a 0.59 m to a 10.5 m Chamfer distance (``benchmarks/bench_methods.py``); one cell per
    spacing ran in under a minute there (1.2 M faces).
    """
    if resolution is not None:
        return int(resolution)
    extent = float(np.ptp(cloud.points, axis=0).max())
    low, high = AUTO_RESOLUTION_RANGE
    return int(np.clip(np.ceil(extent / cloud.spacing), low, high))


def meshlab_set(cloud: MethodInput, *, quality: np.ndarray | None = None):
    """A ``pymeshlab.MeshSet`` holding the cloud (vertices with normals, no faces) and, when
    given, a per-vertex quality ((n,) float64, e.g. a confidence)."""
    import pymeshlab

    extra = {} if quality is None else {"v_scalar_array": np.ascontiguousarray(quality)}
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.ascontiguousarray(cloud.points),
                               v_normals_matrix=np.ascontiguousarray(cloud.normals), **extra),
                "cloud")
    return ms


def meshlab_arrays(ms, *, method: str, drop_nan: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` of the current mesh of a ``pymeshlab.MeshSet``.

    ``drop_nan`` removes the faces touching non-finite vertices (MeshLab's MLS marching cubes
    writes NaN where its projection diverged, on noisy clouds) instead of failing; a mesh that
    is mostly NaN still fails.
    """
    mesh = ms.current_mesh()
    if mesh.face_number() == 0:
        raise MethodFailed(f"{method}: produced no triangles")
    vertices = np.asarray(mesh.vertex_matrix(), dtype=np.float64)
    faces = np.asarray(mesh.face_matrix(), dtype=np.int64)
    if drop_nan:
        bad = ~np.all(np.isfinite(vertices), axis=1)
        if bad.any():
            keep = ~bad[faces].any(axis=1)
            if keep.mean() < MIN_FINITE_FRACTION:
                raise MethodFailed(f"{method}: {bad.mean():.0%} of the vertices are NaN (the MLS "
                                   "projection diverged)")
            faces = faces[keep]
            vertices = np.where(bad[:, None], 0.0, vertices)  # unreferenced now
    return vertices, faces


def meshlab_call(ms, filter_name: str, *, method: str, **params) -> None:
    """Apply a pymeshlab filter, turning its exceptions into ``MethodFailed``."""
    import pymeshlab

    try:
        getattr(ms, filter_name)(**params)
    except pymeshlab.PyMeshLabException as exc:
        raise MethodFailed(f"{method}: pymeshlab {filter_name} failed: "
                           f"{str(exc).strip().splitlines()[0]}") from None
