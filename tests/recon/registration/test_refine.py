"""Self-calibration of pose knowledge: recovers known errors, leaves good poses alone, never
reads the truth."""

from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest

import sim
from cli.main import main
from formats import StrikeLog
from formats.errors import InputError, ParameterError
from recon.registration.ingest import ingest
from recon.registration.refine import PoseCorrection, refine
from tests.conftest import write_sphere_log

# The paper's asteroid and single-beam LRF (0.3 m 3-sigma range noise), its 50 rotations (fewer
# leave too few crossings of ascending and descending passes to separate the errors).
BASE = ("target.subdivisions=4", "errors.range_sigma3=0.3")
MISALIGNMENT_DEG = np.array([0.03, 0.04, 0.0])    # 0.05 deg
BIAS_M = np.array([1.0, 0.0, 0.0])                # inertial, in the orbit plane


def _simulate(path, *overrides):
    sim.simulate(sim.load_scene("asteroid-lrf", [*BASE, *overrides]), path, seed=0,
                 progress=False)
    return path


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("refine")
    clean = _simulate(tmp / "clean.h5")
    posed = _simulate(tmp / "posed.h5",
                      "errors.boresight_misalignment_deg=[{}, {}, {}]".format(*MISALIGNMENT_DEG),
                      "errors.position_bias_inertial=[{}, {}, {}]".format(*BIAS_M))
    return clean, posed


@pytest.fixture(scope="module")
def refined(logs):
    """``refine`` of the posed log at its defaults (the most expensive call here), once."""
    return refine(logs[1])


def _accuracy(path, correction=None) -> float:
    """Mean distance of the registered points from their true hit points [m]."""
    with StrikeLog(path) as log:
        truth = log.truth_strikes().point
    return float(np.linalg.norm(ingest(path, correction=correction).points - truth, axis=1)
                 .mean())


def test_true_parameters_undo_the_simulated_errors_exactly(tmp_path):
    """The correction model is the simulator's error model inverted (no noise, no estimate)."""
    path = tmp_path / "exact.h5"
    overrides = ["time.duration=3000", "errors.boresight_misalignment_deg=[0.1, 0.2, 0.3]",
                 "errors.position_bias_inertial=[1, -2, 3]", "errors.spin_period_error=30"]
    sim.simulate(sim.load_scene("asteroid-lrf", overrides), path, seed=0, progress=False)
    rate = 2 * math.pi / 15480.0 - 2 * math.pi / 15510.0
    correction = PoseCorrection(np.zeros(1), np.radians([[0.1, 0.2, 0.3]]),
                                np.array([[1.0, -2.0, 3.0]]), rate, np.array([0.0, 0.0, 1.0]))
    assert _accuracy(path) > 1.0
    assert _accuracy(path, correction) < 1e-6


def test_refine_recovers_a_misalignment_and_a_position_bias(logs, refined):
    _, posed = logs
    result = refined
    c, s = result.correction, result.sigma
    estimate = np.degrees(c.misalignment[0])
    # The well-observed axis (along-track) to 10 %, the misalignment's size to 15 %.
    assert estimate[1] == pytest.approx(MISALIGNMENT_DEG[1], rel=0.1)
    assert np.linalg.norm(estimate) == pytest.approx(0.05, rel=0.15)
    assert c.position[0, 0] == pytest.approx(BIAS_M[0], abs=0.15)
    # Not observable for a single beam: the roll about the beam and a shift along the spin axis.
    assert not result.observable["misalignment"][0, 2]
    assert not result.observable["position"][0, 2]
    assert s.misalignment[0, 1] > 0 and s.position[0, 0] > 0
    assert result.residual_after_m < result.residual_before_m
    assert _accuracy(posed, c) < 0.4 * _accuracy(posed)


def test_refine_moves_no_point_of_an_error_free_log_beyond_the_range_noise(logs):
    clean, _ = logs
    result = refine(clean)
    before = ingest(clean).points
    after = ingest(clean, correction=result.correction).points
    range_sigma3 = 0.3
    assert np.linalg.norm(after - before, axis=1).max() < range_sigma3


def test_slowly_varying_errors_are_estimated_per_knot(logs):
    _, posed = logs
    result = refine(posed, interval=25 * 15480.0, max_points=5000)
    assert len(result.correction.knots) == 3   # 50 rotations: knots at 0, 25, 50
    assert result.correction.misalignment.shape == (3, 3)
    along = np.degrees(result.correction.misalignment[:, 1])
    assert np.all(along > 0.02)   # every knot sees the constant 0.04 deg ...
    assert along.mean() == pytest.approx(MISALIGNMENT_DEG[1], rel=0.2)  # ... and together agree


def test_bad_refine_options_are_refused(logs, tmp_path):
    _, posed = logs
    with pytest.raises(ParameterError, match=r"^interval must be a positive number") as error:
        refine(posed, interval=0.0)
    assert error.value.argument == "interval"
    tiny = _simulate(tmp_path / "tiny.h5", "time.duration=300")
    with pytest.raises(InputError, match="too few to refine the poses"):
        refine(tiny)


def test_cli_refine_never_reads_the_truth_and_matches_the_api(logs, refined, tmp_path, capsys):
    """``recon ingest --refine`` of the posed log with its truth group zeroed prints and writes
    exactly what ``refine`` found on the intact log."""
    _, posed = logs
    corrupt = tmp_path / "corrupt.h5"
    corrupt.write_bytes(posed.read_bytes())
    with h5py.File(corrupt, "r+") as f:
        for name in ("truth/point", "truth/sensor_position", "truth/sensor_attitude",
                     "truth/target_attitude"):
            f[name][...] = 0.0
    out, estimates = tmp_path / "cloud.ply", tmp_path / "refine.json"
    assert main(["ingest", str(corrupt), "-o", str(out), "--refine",
                 "--refine-json", str(estimates)]) == 0
    printed = capsys.readouterr().out
    assert "misalignment about S y" in printed and "[not observable]" in printed
    assert "refined poses" in printed and out.exists()
    data = json.loads(estimates.read_text())
    assert data == json.loads(json.dumps(refined.to_dict()))
    assert data["misalignment_deg"][0][1] == pytest.approx(0.04, rel=0.1)


def test_cli_refine_options_need_refine(logs, tmp_path, capsys):
    _, posed = logs
    assert main(["ingest", str(posed), "-o", str(tmp_path / "c.ply"),
                 "--refine-interval", "100"]) == 1
    assert "--refine-interval needs --refine" in capsys.readouterr().err
    assert not (tmp_path / "c.ply").exists()


def test_knots_too_many_for_the_strikes_are_refused_up_front(tmp_path, monkeypatch, capsys):
    """The knots follow from the log's duration and the interval: more than the sampled strikes
    can estimate is refused before any shot is read (a 1e-6 s interval asked for 231 GiB, 0.5 s
    for a dense 1 TiB normal matrix)."""
    log = tmp_path / "sphere.h5"
    write_sphere_log(log, n_shots=200)   # 400 strikes over 1990 s: 200 fitted, 4 knots at most
    monkeypatch.setattr(StrikeLog, "shots", _never_read(StrikeLog.shots))
    for interval in (1e-6, 0.5, 600.0, 1e-320):
        with pytest.raises(ParameterError, match=r"^interval .* knots over the log's 1990 s, "
                                                 r"more than its 200 sampled strikes can "
                                                 r"estimate \(4 knots") as error:
            refine(log, interval=interval)
        assert error.value.argument == "interval"
    out = tmp_path / "c.ply"
    assert main(["ingest", str(log), "-o", str(out), "--refine", "--refine-interval",
                 "1e-6"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("recon ingest: error: --refine-interval 1e-06 s makes "
                          "1,990,000,001 knots") and err.endswith("give at least 663.4 s")
    assert "\n" not in err and not out.exists()


def _never_read(read):
    """``StrikeLog.shots`` that fails a test when asked for more than one row."""
    def shots(log, start=0, stop=None):
        assert (stop is not None and stop - start <= 1) or start == log.n_shots - 1, "read"
        return read(log, start, stop)
    return shots


def test_refinement_that_does_not_fit_in_memory_is_refused_up_front(tmp_path, monkeypatch):
    from formats import memory

    log = tmp_path / "sphere.h5"
    write_sphere_log(log, n_shots=200)
    monkeypatch.setattr(memory, "available_bytes", lambda: 10**6)
    monkeypatch.setattr(StrikeLog, "shots", _never_read(StrikeLog.shots))
    with pytest.raises(InputError, match=rf"^{log}: refining the poses of its 200 shots with 3 "
                                         r"knots needs about .* MB of memory but only 1\.0 MB "
                                         r"is available; give a longer interval$"):
        refine(log, interval=1000.0)


def test_refine_json_is_checked_before_the_refinement(sphere_log, tmp_path, capsys):
    """Two outputs on one path, or a directory as --refine-json, are refused before anything
    runs (this 80-strike log is too small to refine: reaching the refinement would say so)."""
    out = tmp_path / "c.ply"
    (tmp_path / "jdir").mkdir()
    cases = {str(out): f"{out}: named by both -o and --refine-json; give each output its own "
                       "file",
             str(tmp_path / "." / "c.ply"): "named by both -o and --refine-json",
             str(tmp_path / "jdir"): f"--refine-json {tmp_path / 'jdir'}: is a directory",
             str(tmp_path / "no" / "r.json"): f"--refine-json {tmp_path / 'no' / 'r.json'}: "
                                              f"directory {tmp_path / 'no'} does not exist"}
    for json_path, expected in cases.items():
        assert main(["ingest", str(sphere_log), "-o", str(out), "--refine", "--refine-json",
                     json_path]) == 1
        err = capsys.readouterr().err.strip()
        assert expected in err and len(err.splitlines()) == 1, err
        assert not out.exists()
