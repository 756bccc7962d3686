"""Scores of reconstructed point clouds and meshes against a truth mesh.

``score(test, truth)`` is the entry point: exact distances to the truth surface, accuracy,
completeness, Chamfer and Hausdorff distances, precision / recall / F-score at a threshold,
coverage (total and per truth face), normal consistency and the paper's edge metric. ``Truth``
prepares a truth once for many scores. The pieces are public too: ``point_mesh_distance`` /
``MeshDistance`` (exact float64 point-to-mesh distance), ``sample_surface``, and ``edge_score``
(the paper's weighted edge metric) / ``feature_edge_score`` / ``detect_edges`` /
``dihedral_edges`` / ``feature_edges``.

Imports only ``formats`` and third-party libraries; Open3D is imported on the first distance
query.
"""

from formats.errors import InputError
from metrics.distance import MeshDistance, point_mesh_distance
from metrics.edges import (
    EdgeReport,
    SurfaceVariation,
    detect_edges,
    dihedral_edges,
    edge_score,
    feature_edge_score,
    feature_edges,
    surface_variation,
)
from metrics.errors import FrameAssumedWarning, ScaleMismatchWarning
from metrics.inputs import Cloud, Mesh
from metrics.sampling import sample_surface
from metrics.score import ScoreReport, Truth, score

__all__ = [
    "Cloud",
    "EdgeReport",
    "FrameAssumedWarning",
    "InputError",
    "Mesh",
    "MeshDistance",
    "ScaleMismatchWarning",
    "ScoreReport",
    "SurfaceVariation",
    "Truth",
    "detect_edges",
    "dihedral_edges",
    "edge_score",
    "feature_edge_score",
    "feature_edges",
    "point_mesh_distance",
    "sample_surface",
    "score",
    "surface_variation",
]
