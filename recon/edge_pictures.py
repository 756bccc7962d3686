"""Edge pictures: the edge points a cloud shows against its truth, as in the paper's Figs. 15, 17
and 19 ("Blue points are detected edges").

``edge_pictures(test, truth, output)`` runs the weighted edge metric (``metrics.edge_score``) and
writes into the directory ``output``:

- ``edges.ply``: the test points (a mesh: its seeded surface samples) with per-point ``label``
  (0 surface point, 1 detected edge point within the tolerance of a truth feature edge, 2 false
  edge point), ``near_edge`` (1 within the tolerance of a feature edge), ``sigma`` (surface
  variation) and ``drop`` (its fall when the point leaves its neighbourhood);
- ``edges.png``: two opposite views of the cloud, detected edge points in blue, false ones in
  red, the truth's missed feature edges in black and its missed gentler edges (the unsampled
  triangulation: blind spots) as a faint orange shade behind the points;
- ``edges.json``: the edge report's scalars and what was written.

The three are written under temporary names and renamed into place together once all are
complete, every destination checked before the work starts: a refused, failed or interrupted run
leaves the previous set as it was (and no new, empty output directory).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from formats.atomic import written_together
from formats.errors import ParameterError
from formats.geometry import Mesh
from formats.paths import writing_into

# File names in the output directory.
PLY_NAME, PNG_NAME, JSON_NAME = "edges.ply", "edges.png", "edges.json"
# Point labels of edges.ply.
SURFACE, TRUE_EDGE, FALSE_EDGE = 0, 1, 2
# A truth edge is drawn as missed when less than this fraction of its length is reconstructed.
MISSED_BELOW = 0.5


def edge_pictures(test, truth, output, *, seed: int = 0, n_test_samples: int | None = None,
                  title: str | None = None, edge_options: dict | None = None,
                  progress=None) -> dict:
    """Detect the edge points of a cloud, score them against the truth, draw and write them.

    Parameters
    ----------
    test : Cloud, (n, 3) array or Mesh
        Metres, in the truth's frame. A mesh is sampled uniformly by area first.
    truth : Mesh
    output : str or Path
        Directory (created) for ``edges.ply``, ``edges.png`` and ``edges.json``.
    seed : int
        Seed of the surface samples of a test mesh and of the points drawn.
    n_test_samples : int, optional
        Samples of a test mesh (default ``metrics.defaults.TEST_MESH_SAMPLES``).
    title : str, optional
        Title of the picture.
    edge_options : dict, optional
        Keyword arguments of ``metrics.edge_score`` (``k``, ``rule``, ``threshold``,
        ``feature_angle_deg``, ``tolerance``, ``tolerance_fraction``, ``variant``).
    progress : callable, optional
        Called with the name of each stage as it finishes (``edges``, ``ply``, ``png``).

    Returns
    -------
    dict
        ``report`` (``metrics.EdgeReport``), ``files`` (name -> Path), ``counts`` (surface, true
        and false edge points, missed feature and gentle edges).
    """
    from metrics import defaults, edge_score, sample_surface
    from metrics.inputs import as_mesh, as_test
    from recon.experiments import charts

    stage = progress or (lambda name: None)
    truth = as_mesh(truth, "truth")
    test = as_test(test, "test")
    out = Path(output)
    files = {"ply": out / PLY_NAME, "png": out / PNG_NAME, "json": out / JSON_NAME}
    # Every destination checked before the work, the three published together after it.
    with writing_into(out, ParameterError), \
            written_together(files.values(), error=ParameterError) as (ply, png, summary):
        if isinstance(test, Mesh):
            points = sample_surface(test, n_test_samples or defaults.TEST_MESH_SAMPLES,
                                    seed=seed)[0]
        else:
            points = test.points
        report = edge_score(points, truth, **dict(edge_options or {}))
        stage("edges")

        label = np.full(len(points), SURFACE, dtype=np.uint8)
        label[report.is_edge & report.near_edge] = TRUE_EDGE
        label[report.is_edge & ~report.near_edge] = FALSE_EDGE
        _write_ply(ply, points, label, report)
        stage("ply")

        sharp = report.edge_angle_deg > report.feature_angle_deg
        missed = report.edge_found < MISSED_BELOW
        segments = truth.vertices[report.truth_edges]
        counts = {"surface_points": int((label == SURFACE).sum()),
                  "true_edge_points": int((label == TRUE_EDGE).sum()),
                  "false_edge_points": int((label == FALSE_EDGE).sum()),
                  "missed_feature_edges": int((missed & sharp).sum()),
                  "missed_gentle_edges": int((missed & ~sharp).sum())}
        note = (f"edge score {report.score:.3f} ({report.variant}): false-edge rate "
                f"{_number(report.false_edge_rate)}, missed (weighted) "
                f"{_number(report.missed_edge_rate)}, feature edges missed "
                f"{_number(report.feature_missed_rate)}\nk = {report.k}, tolerance "
                f"{report.tolerance_m:.3g} m, feature angle {report.feature_angle_deg:g} deg")
        charts.edge_points(points, label, png, bounds=(truth.vertices.min(axis=0),
                                                       truth.vertices.max(axis=0)),
                           missed_feature=segments[missed & sharp],
                           missed_gentle=segments[missed & ~sharp],
                           title=title or "Edge points against the truth", note=note, seed=seed)
        stage("png")
        record = {"edge": report.to_dict(), "counts": counts,
                  "files": {k: str(v) for k, v in files.items()}}
        summary.write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    return {"report": report, "files": files, "counts": counts}


def _number(value) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def _write_ply(path: Path, points: np.ndarray, label: np.ndarray, report) -> None:
    from formats.ply import write_ply

    write_ply(path, {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2], "label": label,
                     "near_edge": report.near_edge.astype(np.uint8),
                     "sigma": report.variation.sigma, "drop": report.variation.drop})
