"""The end-to-end demo: the whole pipeline on a built-in scene, the first thing a new user runs.

simulate (a preset) -> validate -> ingest (body-frame cloud, written and kept from one pass) ->
reconstruct -> score the cloud and the surface against the log's truth mesh. Every file lands in
one directory. ``recon demo`` calls :func:`run_demo` and prints its table.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

from formats.atomic import write_text_atomically
from recon import api

DEMO_SCENE = "asteroid-lrf-slew"   # the paper's slewing single-beam LRF at 85 deg, 50 rotations
DEMO_METHOD = "screened-poisson"   # the most accurate method on the noisy ellipsoid (compare)
DEMO_SEED = 0
# Rows of the demo's table: label and ScoreReport attribute.
SCORE_ROWS = (("Chamfer [m]", "chamfer_m"), ("Hausdorff [m]", "hausdorff_m"),
              ("F-score at tau", "fscore"), ("coverage", "coverage"),
              ("edge score", "edge_score"))


def run_demo(output, *, scene: str = DEMO_SCENE, method: str = DEMO_METHOD,
             overrides: tuple[str, ...] | list[str] = (), seed: int = DEMO_SEED,
             say: Callable[[str], None] = lambda text: None) -> dict:
    """Run the demo and write its files to ``output``.

    Parameters
    ----------
    output : str or Path
        Directory (created) for ``strikes.h5``, ``cloud.ply``, ``truth.ply``, ``surface.ply``
        and ``scores.json``.
    scene : str
        Preset name or scene file.
    method : str
        Reconstruction method, run isolated.
    overrides : sequence of str
        ``section.key=value`` scene overrides.
    seed : int
        Seed of the simulation, the normals and the scoring samples.
    say : callable
        Called with one line per step as the demo goes (the CLI passes ``print``).

    Returns
    -------
    dict
        ``files`` (name -> Path), ``simulation`` (summary), ``scores`` (``cloud`` and
        ``surface`` -> ``metrics.ScoreReport``), ``n_faces``.
    """
    from formats import StrikeLog
    from formats.mesh_io import write_mesh

    out = Path(output)
    out.mkdir(parents=True, exist_ok=True)
    files = {"log": out / "strikes.h5", "cloud": out / "cloud.ply", "truth": out / "truth.ply",
             "surface": out / "surface.ply", "scores": out / "scores.json"}

    start = _step(say, f"simulate {scene} (seed {seed})")
    log = api.simulate(scene, files["log"], seed=seed, overrides=overrides)
    summary = log.summary
    say(f"  {summary['shots']:,} shots, {summary['strikes']:,} strikes, "
        f"{summary['duration_s'] / 3600:.1f} h of flight, in {time.perf_counter() - start:.1f} s")

    _step(say, "validate the strike log")
    with StrikeLog(log) as reader:
        reader.validate()
        truth = reader.truth_mesh()
    write_mesh(files["truth"], truth, source=files["log"].name)

    start = _step(say, "ingest: register strikes into the target body frame")
    cloud = api.ingest(log, output=files["cloud"])
    say(f"  {len(cloud):,} points in {time.perf_counter() - start:.1f} s")

    start = _step(say, f"reconstruct with {method}")
    surface = api.reconstruct(cloud, method=method, seed=seed, isolate=True)
    write_mesh(files["surface"], surface, source=files["cloud"].name)
    say(f"  {surface.n_faces:,} faces in {time.perf_counter() - start:.1f} s")

    start = _step(say, "score cloud and surface against the truth mesh")
    scores = {"cloud": api.score(cloud, truth=truth, seed=seed),
              "surface": api.score(surface, truth=truth, seed=seed)}
    say(f"  in {time.perf_counter() - start:.1f} s")
    write_text_atomically(files["scores"], json.dumps(
        {"scene": scene, "simulation": summary,
         "scores": {k: s.to_dict() for k, s in scores.items()}}, indent=2, default=str))
    return {"files": files, "simulation": summary, "scores": scores, "n_faces": surface.n_faces}


def format_scores(scores: dict) -> str:
    """The demo's table: one row per score, one column per scored geometry."""
    tau = next(iter(scores.values())).tau_m
    lines = [f"{'score (tau = ' + format(tau, '.3g') + ' m)':<24}"
             + "".join(f"{name:>10}" for name in scores)]
    for label, key in SCORE_ROWS:
        lines.append(f"{label:<24}" + "".join(f"{getattr(s, key):>10.4g}"
                                              for s in scores.values()))
    return "\n".join(lines)


def _step(say: Callable[[str], None], text: str) -> float:
    say(f"- {text}")
    return time.perf_counter()
