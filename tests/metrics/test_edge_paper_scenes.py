"""The weighted edge metric on simulated paper scenes: the orderings the paper reports on its
tri-axial ellipsoid (Figs. 7, 12 and Table 1), with short runs of the built-in presets.

Each scene is simulated, registered (``recon.api.ingest``: recorded poses only) and scored
against the log's truth mesh, the 20,480-face ellipsoid. Numbers measured with these exact runs
are quoted beside each bound.
"""

from __future__ import annotations

import numpy as np
import pytest

from formats import StrikeLog
from metrics import edge_score, feature_edge_score
from recon import api


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    """``scored(name, preset, *overrides, seed=0)`` -> (EdgeReport, points), cached per module."""
    folder = tmp_path_factory.mktemp("edge-scenes")
    cache = {}

    def run(name, preset, *overrides, seed=0):
        if name not in cache:
            log = api.simulate(preset, folder / f"{name}.h5", seed=seed, overrides=overrides,
                               progress=False)
            points = np.asarray(api.ingest(log).points)
            with StrikeLog(log.path) as reader:
                truth = reader.truth_mesh()
            cache[name] = (edge_score(points, truth), points, truth)
        return cache[name]
    return run


def test_single_beam_asteroid_score_is_informative_and_falls_with_imaging_time(scored):
    """Paper Fig. 7: the nadir single-beam LRF at 85 deg, 10 to 100 rotations; the score falls
    as imaging time grows (measured: 0.402, 0.290, 0.124 at 10, 25 and 50 rotations)."""
    reports = [scored(f"lrf-{n}", "asteroid-lrf", f"time.rotations={n}")[0] for n in (10, 25, 50)]
    values = [r.score for r in reports]
    assert all(0.0 < v < 1.0 for v in values)
    assert values[0] > values[1] > values[2]
    assert values[0] - values[2] > 0.2
    # Noise-free: no false edges; the score is the share of the triangulation left unsampled.
    assert all(r.false_edge_rate < 1e-3 for r in reports)
    # The feature-edge variant cannot see any of it: the ellipsoid has no feature edge.
    _, points, truth = scored("lrf-10", "asteroid-lrf", "time.rotations=10")
    assert feature_edge_score(points, truth).score < 1e-3


def test_lidar_after_15_rotations_scores_below_the_cross_lrf_after_2(scored):
    """Paper: LIDAR (15 rotations) 0.02, cross LRF 0.0789 (measured: 0.008 and 0.409)."""
    lidar = scored("lidar", "asteroid-lidar", "sensor.resolution=[5, 5]")[0]
    cross = scored("cross", "asteroid-cross")[0]
    assert lidar.score < 0.05
    assert lidar.score < cross.score - 0.2


@pytest.mark.parametrize(("clean", "noisy"), [
    # Table 1, stochastic: measured 0.008 -> 0.342 (LIDAR), 0.409 -> 0.733 (cross),
    # 0.393 -> 0.710 (zigzag).
    (("lidar", "asteroid-lidar", "sensor.resolution=[5, 5]"),
     ("lidar-stochastic", "asteroid-lidar-noise", "sensor.resolution=[5, 5]")),
    (("cross", "asteroid-cross"), ("cross-stochastic", "asteroid-cross-noise")),
    (("zigzag", "asteroid-zigzag"),
     ("zigzag-stochastic", "asteroid-zigzag", "errors.range_sigma3=0.3",
      "errors.position_sigma3=2.0")),
    # Table 1, pulse dilation with alpha = 0.001 (3-sigma 0.75 m x tan(theta) at 750 m, within
    # the paper's "less than 1 m"): measured 0.409 -> 0.428 (cross), 0.393 -> 0.407 (zigzag).
    (("cross", "asteroid-cross"), ("cross-dilation", "asteroid-cross-dilation",
                                   "errors.dilation_alpha=0.001")),
    (("zigzag", "asteroid-zigzag"), ("zigzag-dilation", "asteroid-zigzag",
                                     "errors.dilation_alpha=0.001")),
], ids=["lidar-stochastic", "cross-stochastic", "zigzag-stochastic", "cross-dilation",
        "zigzag-dilation"])
def test_table1_error_scenarios_raise_the_score(scored, clean, noisy):
    before, after = scored(*clean)[0], scored(*noisy)[0]
    assert after.score > before.score + 0.01
    assert after.false_edge_rate > before.false_edge_rate + 0.02  # noise makes false edges


def test_pulse_dilation_at_the_presets_alpha_only_adds_a_few_grazing_false_edges(scored):
    """With alpha = 0.0002 the error is 0.15 m x tan(theta) (3 sigma) at 750 m, about 1 % of a
    neighbourhood's radius: only strikes at grazing incidence become edge points (measured: 11
    of 15,480), and the score moves by 2e-4 (see docs/paper-reproduction.md, claim 17)."""
    before = scored("cross", "asteroid-cross")[0]
    after = scored("cross-dilation-preset", "asteroid-cross-dilation")[0]
    assert 0 < after.n_edge_points < 0.005 * after.n_points
    assert after.false_edge_rate > before.false_edge_rate
    assert abs(after.score - before.score) < 0.002
