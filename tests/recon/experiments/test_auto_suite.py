"""The auto suite's quick form on one tiny cloud: it runs, scores auto against the truth and
writes its table and chart (the full suite is ``python benchmarks/suite.py``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import suite


def _overrides(cloud) -> dict:
    return dict(o.split("=", 1) for o in cloud.overrides)


def test_suite_defines_the_clouds_the_issue_asks_for():
    clouds = suite.CLOUDS.values()
    assert len(suite.CLOUDS) >= 24
    assert {"asteroid", "RSO-A", "RSO-B"} <= {c.target for c in clouds}
    # Noisy single-beam, cross and LIDAR all appear, among the tuning clouds and held out.
    kinds = {"LRF + 2 deg slew", "cross", "LIDAR"}
    for names in (suite.TUNING, suite.HELD_OUT):
        assert kinds <= {suite.CLOUDS[n].sensor for n in names
                         if suite.CLOUDS[n].errors == "paper"}
    assert len({c.mesh for c in clouds if c.mesh}) >= 8
    assert {c.errors for c in clouds} == {"none", "paper"}
    assert {c.density for c in clouds} == {"dense", "sparse"}
    generated = {name: _overrides(c) for name, c in suite.CLOUDS.items()
                 if "target.seed" in _overrides(c)}
    kinds = [o["target.kind"] for o in generated.values()]
    satellites = {o["target.seed"] for o in generated.values() if o["target.kind"] == "satellite"}
    assert len(satellites) >= 3 and kinds.count("cratered-asteroid") >= 1
    # One polyhedron at two scales: the same seed, sizes 3.5 times apart.
    polyhedra = [o for o in generated.values() if o["target.kind"] == "polyhedron"
                 and o["target.seed"] == str(suite.POLYHEDRON_SEED)]
    sizes = sorted(float(o["target.size"]) for o in polyhedra)
    assert len(sizes) == 2 and sizes[1] == pytest.approx(3.5 * sizes[0])
    # At least six held-out clouds, listed, apart from the tuning clouds; the earlier round's
    # held-out clouds have been looked at and are tuning clouds now.
    assert len(suite.HELD_OUT) >= 6 and all(suite.CLOUDS[n].held_out for n in suite.HELD_OUT)
    assert not set(suite.HELD_OUT) & set(suite.TUNING)
    assert set(suite.HELD_OUT) | set(suite.TUNING) == set(suite.CLOUDS)
    assert set(suite.EARLIER_HELD_OUT) <= set(suite.TUNING)
    # Held out: new generated bodies (no seed a tuning cloud uses) and real models in a
    # configuration (preset, sensor, errors) no tuning cloud of the same model uses.
    tuned_seeds = {(o["target.kind"], o["target.seed"]) for n, o in generated.items()
                   if n in suite.TUNING}
    assert not any((o["target.kind"], o["target.seed"]) in tuned_seeds
                   for n, o in generated.items() if n in suite.HELD_OUT)

    def configuration(name):
        c = suite.CLOUDS[name]
        return (c.mesh, c.preset, c.sensor, c.errors)

    real_held = {configuration(n) for n in suite.HELD_OUT if suite.CLOUDS[n].mesh}
    assert real_held and not real_held & {configuration(n) for n in suite.TUNING}
    assert {suite.CLOUDS[n].mesh is None for n in suite.HELD_OUT} == {True, False}


def test_every_generated_scene_loads():
    import sim

    for name, cloud in suite.CLOUDS.items():
        if cloud.mesh is None and "target.seed" in _overrides(cloud):
            scene = sim.load_scene(cloud.preset, list(cloud.overrides))
            assert scene.target.split(":")[0] in ("satellite", "polyhedron",
                                                  "cratered-asteroid"), name


# The held-out set, fixed before any of its results existed: changing it means changing this
# list in the same commit, where the history shows it.
FIXED_HELD_OUT = ("satellite-am-cross-noisy", "satellite-an-lidar-noisy",
                  "polyhedron-38m-slew-noisy", "cratered-asteroid-17-lidar-noisy",
                  "comet-cross-noisy", "eros-lidar-noisy", "spot-cross-noisy")


def test_held_out_set_is_the_fixed_one_and_apart_from_every_tuning_cloud():
    assert suite.HELD_OUT == FIXED_HELD_OUT
    assert not set(suite.HELD_OUT) & (set(suite.TUNING) | set(suite.EARLIER_HELD_OUT))
    # No held-out shape is a tuning cloud's: not its body (kind, seed, size) nor its real model.
    def body(name):
        o = _overrides(suite.CLOUDS[name])
        return (o.get("target.kind"), o.get("target.seed"), o.get("target.size"),
                suite.CLOUDS[name].mesh)

    generated_held = {body(n) for n in suite.HELD_OUT if suite.CLOUDS[n].mesh is None}
    assert generated_held and not generated_held & {body(n) for n in suite.TUNING}
    tuned_sizes = {float(o["target.size"]) for o in map(_overrides, map(suite.CLOUDS.get,
                                                                          suite.TUNING))
                   if o.get("target.kind") == "polyhedron"}
    held_sizes = {float(o["target.size"]) for o in map(_overrides, map(suite.CLOUDS.get,
                                                                         suite.HELD_OUT))
                  if o.get("target.kind") == "polyhedron"}
    assert held_sizes and not held_sizes & tuned_sizes


@pytest.mark.parametrize("name", [n for n in FIXED_HELD_OUT
                                  if "target.seed" in _overrides(suite.CLOUDS[n])])
def test_held_out_generated_body_is_built_from_its_seed_alone(name):
    import sim

    cloud = suite.CLOUDS[name]
    first, again = (sim.load_scene(cloud.preset, list(cloud.overrides)) for _ in range(2))
    assert first.vertices.tobytes() == again.vertices.tobytes()
    assert first.faces.tobytes() == again.faces.tobytes()
    # The seed is what makes the body: the next seed is another one.
    seed = int(_overrides(cloud)["target.seed"])
    other = sim.load_scene(cloud.preset, [*cloud.overrides, f"target.seed={seed + 1}"])
    assert other.vertices.shape != first.vertices.shape or \
        not np.allclose(other.vertices, first.vertices)


def test_prediction_reads_a_records_columns():
    assert suite.prediction({"predicted_chamfer_m": 0.1, "predicted_chamfer_low_m": 0.05,
                             "predicted_chamfer_high_m": 0.15}) == \
        {"chamfer_m": 0.1, "lo_m": 0.05, "hi_m": 0.15}
    assert suite.prediction({"chamfer_m": 0.1}) is None


def _summary(name, pairs, choice, *, held_out=False):
    """A cloud's summary as far as prediction_totals reads it: (true, predicted) per run and
    auto's choice (true, predicted, lo, hi)."""
    truth, predicted, lo, hi = choice
    return {"cloud": name, "held_out": held_out,
            "predicted": {"runs": [{"truth_m": t, "predicted_m": p, "lo_m": p, "hi_m": p}
                                   for t, p in pairs]},
            "auto": {"chamfer_m": truth,
                     "predicted": {"chamfer_m": predicted, "lo_m": lo, "hi_m": hi}}}


def test_prediction_totals_rank_correlation_and_band():
    rising = [(0.1, 1.0), (0.2, 2.0), (0.4, 3.0), (0.8, 4.0)]
    summaries = [_summary("a", rising, (0.1, 0.12, 0.08, 0.15)),
                 _summary("b", [(t * 3, p * 3) for t, p in rising], (0.3, 0.5, 0.4, 0.6))]
    out = suite.prediction_totals(summaries)
    assert out["n_runs"] == 8 and out["spearman_within_cloud_median"] == pytest.approx(1.0)
    # Over all runs the ranks still agree but for b's first runs ranked under a's last.
    assert 0.8 < out["spearman"] < 1.0
    assert out["n_choices"] == 2 and out["band_holds_truth"] == pytest.approx(0.5)
    reversed_ = suite.prediction_totals([_summary("c", [(t, -p) for t, p in rising],
                                                  (0.1, 0.1, 0.1, 0.1))])
    assert reversed_["spearman"] == pytest.approx(-1.0) and reversed_["band_holds_truth"] == 1
    # Constant predictions say nothing: NaN, not a warning or a number.
    flat = suite.prediction_totals([_summary("d", [(t, 1.0) for t, _ in rising],
                                             (0.1, 0.1, 0.1, 0.1))])
    assert np.isnan(flat["spearman"])


def _record(label, method, chamfer, fscore, wall):
    return {"key": label, "label": label, "method": method, "status": "ok",
            "chamfer_m": chamfer, "fscore": fscore, "wall_time_s": wall}


def test_visibility_on_the_front_or_not_and_against_the_best():
    records = [_record("plane", "plane", 0.10, 0.90, 1.0),
               _record("poisson", "poisson", 0.05, 0.95, 10.0),
               _record("visibility", "visibility", 0.08, 0.97, 5.0)]
    report = {"records": records,
              "pareto_chamfer": [{"label": "plane"}, {"label": "visibility"},
                                 {"label": "poisson"}],
              "pareto_fscore": [{"label": "plane"}, {"label": "visibility"}]}
    v = suite.visibility(report)
    assert v["present"] and v["on_front_chamfer"] and v["on_front_f"]
    assert v["chamfer_ratio"] == pytest.approx(1.6) and v["f_ratio"] == pytest.approx(1.0)
    assert v["rank_chamfer"] == 2 and v["best_chamfer_label"] == "poisson"
    report["pareto_chamfer"] = [{"label": "plane"}, {"label": "poisson"}]
    report["pareto_fscore"] = [{"label": "plane"}]
    v = suite.visibility(report)
    assert not v["on_front_chamfer"] and not v["on_front_f"]
    absent = suite.visibility({"records": records[:2], "pareto_chamfer": [],
                               "pareto_fscore": []})
    assert not absent["present"] and "no run of it here" in absent["note"]


def _fake_columns(vertices, faces, strikes, misses=None):
    """A stand-in prediction: the mesh's largest extent over 100, and a band of +-10 %."""
    from recon.experiments.compare import n_misses

    size = float(np.ptp(vertices, axis=0).max()) / 100.0
    return {"predicted_chamfer_m": size, "predicted_chamfer_low_m": 0.9 * size,
            "predicted_chamfer_high_m": 1.1 * size, "predicted_by": "v2",
            "predicted_misses": n_misses(misses)}


def test_predict_runs_reads_current_records_and_falls_back_on_kept_meshes(tmp_path,
                                                                          monkeypatch):
    from formats.mesh_io import write_mesh
    from recon.experiments import compare
    from sim import targets

    (tmp_path / "meshes").mkdir()
    records = []
    for i, edge in enumerate((1.0, 2.0, 4.0)):
        path = tmp_path / "meshes" / f"run{i}.ply"
        write_mesh(path, *targets.box([0, 0, 0], [edge, edge, edge]))
        records.append({"key": f"k{i}", "status": "ok", "chamfer_m": edge / 10,
                        "mesh": f"meshes/run{i}.ply"})
    records[0] |= {"predicted_chamfer_m": 9.0, "predicted_chamfer_low_m": 8.0,
                   "predicted_chamfer_high_m": 10.0, "predicted_by": "v1"}   # stale
    records.append({"key": "failed", "status": "failed"})
    records.append({"key": "given", "status": "ok", "chamfer_m": 1.0,
                    "predicted_chamfer_m": 0.5, "predicted_chamfer_low_m": 0.4,
                    "predicted_chamfer_high_m": 0.6, "predicted_by": "v2",
                    "predicted_misses": 0})
    monkeypatch.setattr(compare, "estimate_version", lambda: "v2")
    monkeypatch.setattr(compare, "predicted_columns", _fake_columns)
    out = suite.predict_runs(records, None, tmp_path)
    assert out["note"] == "" and out["from_records"] == 1 and out["from_meshes"] == 3
    assert out["runs"]["k0"] == pytest.approx({"chamfer_m": 0.01, "lo_m": 0.009,
                                               "hi_m": 0.011})
    assert out["runs"]["given"] == {"chamfer_m": 0.5, "lo_m": 0.4, "hi_m": 0.6}
    assert "failed" not in out["runs"]
    # Cached beside the compare under the estimate's version: not computed again ...
    for r in records[:3]:
        (tmp_path / r["mesh"]).unlink()
    assert suite.predict_runs(records, None, tmp_path)["runs"] == out["runs"]
    # ... until the estimate changes: then runs with neither record nor mesh are said missing.
    monkeypatch.setattr(compare, "estimate_version", lambda: "v3")
    missing = suite.predict_runs(records, None, tmp_path)
    assert missing["runs"]["k0"] is None and missing["runs"]["given"] is None
    assert "no predicted Chamfer for 4 of 4 runs" in missing["note"]


def test_a_prediction_made_with_other_missed_beams_is_made_again(tmp_path, monkeypatch):
    from formats.mesh_io import write_mesh
    from recon.experiments import compare
    from sim import targets

    (tmp_path / "meshes").mkdir()
    write_mesh(tmp_path / "meshes" / "run.ply", *targets.box([0, 0, 0], [2.0, 2.0, 2.0]))
    made = {"key": "k", "status": "ok", "chamfer_m": 0.2, "mesh": "meshes/run.ply",
            "predicted_chamfer_m": 9.0, "predicted_chamfer_low_m": 8.0,
            "predicted_chamfer_high_m": 10.0, "predicted_by": "v2"}
    monkeypatch.setattr(compare, "estimate_version", lambda: "v2")
    monkeypatch.setattr(compare, "predicted_columns", _fake_columns)
    # Made without the log's missed beams (none given, or a record older than the count) ...
    for record in ({**made, "predicted_misses": 0}, made):
        out = suite.predict_runs([record], None, tmp_path,
                                 misses=[None] * 5)
        assert out["from_records"] == 0 and out["from_meshes"] == 1
        assert out["runs"]["k"] == pytest.approx({"chamfer_m": 0.02, "lo_m": 0.018,
                                                  "hi_m": 0.022})
        (tmp_path / "predicted.json").unlink()
    # ... against made with them: read from the record.
    given = suite.predict_runs([{**made, "predicted_misses": 5}], None, tmp_path,
                               misses=[None] * 5)
    assert given["from_records"] == 1 and given["runs"]["k"]["chamfer_m"] == 9.0


def test_the_compares_predictions_are_given_the_logs_missed_beams(tmp_path, monkeypatch):
    """As ``recon compare`` and auto give them: the estimate's proxy is carved by them."""
    from types import SimpleNamespace

    from recon.experiments import compare

    prepared = SimpleNamespace(misses=object())
    monkeypatch.setattr(suite, "load_cloud", lambda cloud, args: ("points", "truth", prepared))
    given = {}
    monkeypatch.setattr(compare, "compare", lambda *a, **kw: given.update(kw) or
                        {"records": []})
    args = suite.parse_args(["--out", str(tmp_path), "--clouds", "asteroid-cross-noisy"])
    (tmp_path / "asteroid-cross-noisy").mkdir()
    suite.compare_cloud(suite.CLOUDS["asteroid-cross-noisy"], args)
    assert given["strikes"] == "points" and given["misses"] is prepared.misses


def test_band_width_is_the_median_high_over_low():
    rising = [(0.1, 1.0), (0.2, 2.0)]
    summaries = [_summary("a", rising, (0.1, 0.1, 0.05, 0.2)),
                 _summary("b", rising, (0.1, 0.1, 0.1, 1.0)),
                 _summary("c", rising, (0.1, 0.1, 0.0, 1.0))]
    out = suite.prediction_totals(summaries)
    assert out["band_width_choices"] == pytest.approx(10.0)   # 4, 10 and inf
    assert out["band_width_runs"] == pytest.approx(1.0)       # the runs' bands are points


def test_records_carry_the_estimate_of_their_mesh():
    from formats.geometry import Cloud
    from recon.experiments.compare import estimate_version, predicted_columns
    from sim import targets

    vertices, faces = targets.box([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0])
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (400, 3))
    points[np.arange(400), rng.integers(0, 3, 400)] = rng.choice([-1.0, 1.0], 400)
    columns = predicted_columns(vertices, faces, Cloud(points))
    assert columns["predicted_by"] == estimate_version() and len(estimate_version()) == 12
    assert columns["predicted_misses"] == 0
    assert columns["predicted_chamfer_low_m"] <= columns["predicted_chamfer_m"] \
        <= columns["predicted_chamfer_high_m"]
    far = predicted_columns(vertices * 3.0, faces, Cloud(points))
    assert far["predicted_chamfer_m"] > columns["predicted_chamfer_m"] + 0.5


def test_quick_suite_on_one_cloud(tmp_path, capsys):
    doc = tmp_path / "docs" / "auto-suite.md"
    doc.parent.mkdir()
    common = ["--quick", "--clouds", "asteroid-cross-noisy", "--methods", "ellipsoid", "planes",
              "poisson", "--out", str(tmp_path / "out"), "--workers", "2"]
    # The compares alone first (as for held-out clouds), then auto, the estimate and the
    # report on them, resumed.
    assert suite.main([*common, "--compare-only"]) == 0
    assert (tmp_path / "out" / "asteroid-cross-noisy" / "results.json").is_file()
    assert not (tmp_path / "out" / "summary.json").exists()
    status = suite.main([*common, "--resume", "--doc", str(doc)])
    assert status == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    (cloud,) = summary["clouds"]
    labels = {r["label"] for r in cloud["ranking"]}
    # Every method at its defaults plus the ellipsoid's unweighted twin, all scored.
    assert labels == {"ellipsoid", "ellipsoid weighted=False", "planes", "poisson"}
    verdict = cloud["verdict"]
    # The paper's asteroid is an ellipsoid: 9 numbers are the truth's best model, and auto
    # must find them from ~800 noisy strikes.
    assert verdict["best_chamfer_label"].startswith("ellipsoid")
    assert verdict["within_f"] and verdict["within_chamfer"], cloud["auto"]["reason"]
    assert cloud["weighting"]["ellipsoid"]["chamfer_weighted"] > 0
    assert summary["totals"]["within_both"] == pytest.approx(1.0)
    assert summary["totals_tuning"]["n_clouds"] == 1 and summary["totals_held_out"]["n_clouds"] == 0
    text = doc.read_text()
    assert "asteroid-cross-noisy" in text and "| cloud | points | auto's choice" in text
    assert (doc.parent / "figures" / "auto-suite.png").stat().st_size > 10_000
    # Every run's prediction comes from the compare's records; auto's choice has its band.
    assert cloud["predicted"]["note"] == ""
    assert cloud["predicted"]["from_records"] == len(cloud["ranking"]) == 4

    band = cloud["auto"]["predicted"]
    assert band["lo_m"] <= band["chamfer_m"] <= band["hi_m"] and band["source"] == "held-out"
    assert cloud["visibility"]["present"] is False    # not among the methods asked for
    assert "## The `visibility` method" in text and "Held out" in text
    # The cloud's summary is kept: the report is rebuilt from it alone, the same but for the
    # command it names, its groups the present held-out set's (not the flag it was made
    # with); a cloud without one is named, and nothing is written.
    doc.unlink()
    (tmp_path / "out" / "summary.json").unlink()
    kept = tmp_path / "out" / "asteroid-cross-noisy" / "summary.json"
    kept.write_text(json.dumps(json.loads(kept.read_text()) | {"held_out": True}))
    assert suite.main([*common, "--report", "--doc", str(doc)]) == 0
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["clouds"] == [
        json.loads(json.dumps(cloud))]
    assert doc.read_text().replace(" --report", "") == text.replace(" --resume", "")
    doc.unlink()
    status = suite.main(["--clouds", "asteroid-cross-noisy", "rso-a-cross-noisy",
                         "--out", str(tmp_path / "out"), "--report", "--doc", str(doc)])
    assert status == 1 and not doc.exists()
    # A damaged kept summary, or another cloud's, is named in one line; nothing is written.
    for damaged in ("{\"cloud\": ", json.dumps({"cloud": "rso-a-cross-noisy"})):
        kept.write_text(damaged)
        capsys.readouterr()
        assert suite.main([*common, "--report", "--doc", str(doc)]) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(kept) in err and not doc.exists()


def _scored(name, *, held_out, within, cost, vis_ratio, best="plane"):
    """A cloud's summary as far as the targets table reads it: auto within both tolerances or
    not (and below the median when not), its cost ratio, the visibility method's Chamfer
    ratio, runs predicted in the truth's order with auto's band holding its Chamfer, and the
    compare's ranking: ``best`` at the best scores, the ellipsoid far behind."""
    base = _summary(name, [(0.1, 1.0), (0.2, 2.0), (0.4, 3.0)], (0.1, 0.1, 0.05, 0.2),
                    held_out=held_out)
    return base | {
        "verdict": {"within_f": within, "within_chamfer": within, "not_below_median": within,
                    "best_f": 0.9, "best_chamfer_m": 0.1},
        "ranking": [{"label": best, "chamfer_m": 0.1, "fscore": 0.9},
                    {"label": "ellipsoid", "chamfer_m": 0.5, "fscore": 0.3}],
        "cost_ratio": cost, "fit_ratio": cost,
        "visibility": {"present": True, "on_chart": True, "chamfer_ratio": vis_ratio}}


# Tuning clouds of each kind for the targets table's summaries (their names give the target's
# kind, hence auto's candidates).
SPACECRAFT = [name for name, c in suite.CLOUDS.items()
              if not c.held_out and c.target_kind == "unknown"]
NATURAL = [name for name, c in suite.CLOUDS.items()
           if not c.held_out and c.target_kind == "natural"]


def test_targets_table_marks_each_group_against_the_issue_targets():
    summaries = [*(_scored(name, held_out=False, within=True, cost=0.1, vis_ratio=1.05)
                   for name in SPACECRAFT[:8]),
                 _scored(NATURAL[0], held_out=False, within=True, cost=0.1, vis_ratio=1.05,
                         best="completed-poisson"),
                 _scored(SPACECRAFT[8], held_out=False, within=False, cost=0.3, vis_ratio=2.0,
                         best="rimls"),
                 _scored(SPACECRAFT[9], held_out=True, within=True, cost=0.2, vis_ratio=3.0,
                         best="completed-poisson")]
    groups = {key: [s for s in summaries if keep(s)] for key, _, keep in suite.GROUPS}
    lines = suite._targets_lines(summaries, {k: suite.totals(g) for k, g in groups.items()},
                                 {k: suite.prediction_totals(g) for k, g in groups.items()})
    assert lines[0] == "| target | All clouds | Tuning clouds | Held out |"
    both, median, cost, spearman, band, drawn, wins, candidates, any_run = (
        line.strip("| ").split(" | ")[1:] for line in lines[2:-1])
    assert both == ["91% (10 of 11) yes", "90% (9 of 10) yes", "100% (1 of 1) yes"]
    assert median[0].endswith("**no**") and median[2].startswith("100% (1 of 1) yes")
    assert cost[0] == "worst 0.30, median 0.10 **no**" and cost[2].startswith("worst 0.20")
    assert spearman[0].startswith("1.00 (33 runs) yes") and band[0] == "100% (11 of 11) yes"
    assert drawn[1] == "10 of 10 yes" and wins == ["9 of 11", "9 of 10", "0 of 1"]
    # the completion is a candidate on a natural body only; rimls is none of auto's
    assert candidates == ["82% (9 of 11)", "90% (9 of 10)", "0% (0 of 1)"]
    assert any_run == ["100% (11 of 11)", "100% (10 of 10)", "100% (1 of 1)"]


def test_plan_counts_cached_runs_and_spots_a_compare_on_other_points(tmp_path, monkeypatch,
                                                                      capsys):
    import hashlib
    from types import SimpleNamespace

    points = np.arange(12.0).reshape(4, 3)
    prepared = SimpleNamespace(points=points, spacing=0.1, seed=0)
    monkeypatch.setattr(suite, "load_cloud", lambda cloud, args: (None, (None, [0, 1]),
                                                                  prepared))
    monkeypatch.setattr(suite, "runs_of", lambda names, grid: [SimpleNamespace(key=k)
                                                               for k in ("a", "b")])
    name = "satellite-a-cross-noisy"
    out = tmp_path / name
    out.mkdir()
    fingerprint = {"n_points": 4, "spacing": 0.1, "seed": 0, "truth_faces": 2,
                   "timeout_s": 300.0, "memory_mb": 8192, "score_options": suite.SCORE_OPTIONS,
                   "points_sha1": hashlib.sha1(points).hexdigest()}
    (out / "sweep.json").write_text(json.dumps(fingerprint))
    (out / "results.jsonl").write_text('{"key": "a"}\n{"key": "gone"}\n')
    args = suite.parse_args(["--plan", "--out", str(tmp_path), "--clouds", name])
    assert suite.plan([name], args) == 1
    assert f"{name}: 1 of 2 runs cached, 1 to run\n" in capsys.readouterr().out
    (out / "results.jsonl").write_text('{"key": "a"}\n{"key": "b"}\n')
    assert suite.plan([name], args) == 0
    assert "suite: 0 runs to compute over 1 clouds" in capsys.readouterr().out
    (out / "sweep.json").write_text(json.dumps(fingerprint | {"points_sha1": "other"}))
    assert suite.plan([name], args) == 1
    assert "--resume refuses it" in capsys.readouterr().out


def test_targets_table_of_a_group_without_clouds_is_dashes():
    summaries = [_scored(SPACECRAFT[0], held_out=False, within=True, cost=0.1, vis_ratio=1.0)]
    groups = {key: [s for s in summaries if keep(s)] for key, _, keep in suite.GROUPS}
    lines = suite._targets_lines(summaries, {k: suite.totals(g) for k, g in groups.items()},
                                 {k: suite.prediction_totals(g) for k, g in groups.items()})
    assert all(line.strip("| ").split(" | ")[3] == "-" for line in lines[2:-1])


def test_the_reports_command_names_a_subset_of_clouds_but_not_all_of_them():
    every = suite.parse_args(["--resume", "--doc", "docs/auto-suite.md",
                              "--clouds", *reversed(suite.CLOUDS)])
    assert suite._command(every) == ("python benchmarks/suite.py --resume "
                                     "--doc docs/auto-suite.md")
    some = suite.parse_args(["--clouds", "asteroid-cross-noisy", "rso-a-cross-noisy"])
    assert suite._command(some) == ("python benchmarks/suite.py --clouds asteroid-cross-noisy "
                                    "rso-a-cross-noisy")


def test_each_cloud_has_its_family_for_the_charts():
    family = {name: suite.family(c) for name, c in suite.CLOUDS.items()}
    assert family["satellite-a-cross-noisy"] == "generated satellites"
    assert family["polyhedron-27m-cross-noisy"] == "generated polyhedra"
    assert family["cratered-asteroid-cross-noisy"] == "generated cratered asteroids"
    assert family["itokawa-cross-noisy"] == family["asteroid-slew-clean"]
    assert family["hst-cross-noisy"] == family["rso-a-cross-noisy"] != family["itokawa-cross-noisy"]
    assert len(set(family.values())) == 5
