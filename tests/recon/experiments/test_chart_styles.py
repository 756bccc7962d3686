"""Every method keeps its marker and colour from chart to chart whatever its rank, and every
label of the speed-accuracy chart is anchored on its own run's marker."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import to_rgba

from recon.experiments import charts
from recon.experiments.cases import CHAMFER, FSCORE


def _records(order, seed):
    rng = np.random.default_rng(seed)
    out = []
    for rank, method in enumerate(order):
        for depth in (6, 8):
            out.append({"method": method, "label": f"{method} depth={depth}", "status": "ok",
                        "wall_time_s": float(rng.uniform(0.05, 20.0)),
                        CHAMFER: float(0.01 * (rank + 1) * rng.uniform(0.5, 1.5)),
                        FSCORE: float(rng.uniform(0.2, 0.99))})
    return out


def _styles(fig):
    """{method: (face colour, marker path vertices)} of the scatters of every panel."""
    out = {}
    for ax in fig.axes:
        for collection in ax.collections:
            name = collection.get_label()
            if name.startswith("_"):
                continue
            colour = tuple(np.round(collection.get_facecolor()[0], 6))
            shape = collection.get_paths()[0].vertices.round(6).tobytes()
            assert out.setdefault(name, (colour, shape)) == (colour, shape), name
    return out


def test_a_method_keeps_its_style_across_charts_and_methods_differ():
    methods = ["plane", "planes", "delaunay-balls", "screened-poisson", "poisson",
               "ball-pivoting"]
    first = charts.speed_accuracy_figure(_records(methods, 0))
    second = charts.speed_accuracy_figure(_records(methods[::-1], 1))
    a, b = _styles(first), _styles(second)
    assert set(a) == set(b) == set(methods)
    assert a == b
    assert len({colour for colour, _ in a.values()}) == len(methods)
    assert len({(colour, shape) for colour, shape in a.values()}) == len(methods)
    for name, (colour, _) in a.items():
        assert colour == tuple(np.round(to_rgba(charts.method_style(name)["color"]), 6))
    charts._pyplot().close("all")


def test_every_registered_method_has_its_own_style():
    from recon.surfaces.methods import available

    styles = [tuple(charts.method_style(name).values()) for name in available()]
    assert len(set(styles)) == len(styles)
    assert len({colour for _, colour in styles}) == len(styles)
    assert charts.method_style("some-test-method") == charts.method_style("some-test-method")


def test_every_marker_is_filled_since_it_is_drawn_with_an_edge():
    from matplotlib.markers import MarkerStyle

    from recon.surfaces.methods import available

    for name in [*available(), "some-test-method", "another-test-method"]:
        assert MarkerStyle(charts.method_style(name)["marker"]).is_filled(), name


def test_labels_are_anchored_on_their_own_markers():
    records = _records(["plane", "delaunay-balls", "screened-poisson", "planes"], 3)
    fig = charts.speed_accuracy_figure(records)
    by_label = {r["label"]: r for r in records}
    labelled = 0
    for ax, metric in zip(fig.axes[:2], (CHAMFER, FSCORE), strict=True):
        points = {c.get_label(): {tuple(p) for p in np.asarray(c.get_offsets()).round(9)}
                  for c in ax.collections}
        for text in ax.texts:
            run = by_label[text.get_text()]
            anchor = tuple(np.round(text.xy, 9))
            assert anchor == (round(run["wall_time_s"], 9), round(run[metric], 9))
            assert anchor in points[run["method"]]   # the marker of the run's own method
            labelled += 1
    assert labelled >= 2
    charts._pyplot().close(fig)


def _texts_outside(fig) -> list[str]:
    """The visible texts of ``fig`` (titles, labels, colour-bar labels) not wholly inside it."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    from matplotlib.text import Text

    texts = [t for t in fig.findobj(Text) if t.get_visible() and t.get_text()]
    out = []
    for t in texts:
        e = t.get_window_extent(renderer)
        if e.x0 < box.x0 - 1 or e.x1 > box.x1 + 1 or e.y0 < box.y0 - 1 or e.y1 > box.y1 + 1:
            out.append(t.get_text())
    return out


def test_a_narrow_heatmap_shows_its_titles_and_colour_bars_whole(tmp_path, monkeypatch):
    drawn = []
    monkeypatch.setattr(charts, "_save", lambda fig, path: drawn.append(fig))
    values = np.array([[0.02, 1.5], [0.3, np.nan], [0.9, 0.05]])
    charts.heatmaps(["plane", "planes", "poisson"], ["rso-a-stochastic", "asteroid-none"], [
        {"title": "Chamfer distance [m]; colour: ratio to the condition's best",
         "values": values, "colour": values / np.nanmin(values, axis=0),
         "label": "Chamfer / best Chamfer of the condition", "lower_better": True, "log": True},
        {"title": "F-score at τ", "values": 1 - values, "label": "F-score"}],
        tmp_path / "h.png", title="Best run of each method per condition (x: failed)",
        note="rso-a: 1.2x1.2 deg cross LRF; asteroid: 10x10 deg cross LRF; τ = 1 % of the "
             "truth's bounding-box diagonal")
    assert _texts_outside(drawn[0]) == []
    charts._pyplot().close(drawn[0])


def test_choice_vs_ranking_labels_each_mark_once(tmp_path, monkeypatch):
    drawn = []
    monkeypatch.setattr(charts, "_save", lambda fig, path: drawn.append(fig))
    runs = [{CHAMFER: c, FSCORE: f} for c, f in ((0.1, 0.9), (0.2, 0.8), (0.4, 0.6))]
    summaries = [
        {"cloud": "first (auto failed)", "ranking": runs, "verdict": {"failed": True}},
        {"cloud": "second", "ranking": runs, "verdict": {"f_ratio": 0.97, "chamfer_ratio": 1.2},
         "visibility": {"present": True, "f_ratio": 0.9, "chamfer_ratio": 1.5}}]
    charts.choice_vs_ranking(summaries, tmp_path / "c.png", title="auto against the ranking")
    for ax in drawn[0].axes:
        labels = ax.get_legend_handles_labels()[1]
        assert len(labels) == len(set(labels)) == 5, labels
        assert "auto's choice" in labels    # labelled though the first cloud has none
    charts._pyplot().close(drawn[0])


def test_predicted_vs_true_names_each_group_once(tmp_path, monkeypatch):
    drawn = []
    monkeypatch.setattr(charts, "_save", lambda fig, path: drawn.append(fig))
    runs = [{"truth_m": t, "predicted_m": 1.2 * t} for t in (0.1, 0.2, 0.4)]
    auto = {"chamfer_m": 0.1, "predicted": {"chamfer_m": 0.12, "lo_m": 0.05, "hi_m": 0.3}}
    summaries = [{"cloud": f"{kind}-{i}", "held_out": i == 2, "predicted": {"runs": runs},
                  "auto": auto} for kind in ("sat", "poly") for i in range(3)]
    charts.predicted_vs_true(summaries, tmp_path / "p.png", title="estimate",
                             group=lambda s: s["cloud"].split("-")[0])
    (ax,) = drawn[0].axes
    handles, labels = ax.get_legend_handles_labels()
    assert labels == ["sat", "sat (held out)", "poly", "poly (held out)", "predicted = true"]
    colour = [to_rgba(h.get_facecolor()[0]) for h in handles[:4]]
    assert colour[0] == colour[1] != colour[2] == colour[3]   # a hue a group
    charts._pyplot().close(drawn[0])
    charts.predicted_vs_true(summaries, tmp_path / "p.png", title="estimate")
    assert len(drawn[1].axes[0].get_legend_handles_labels()[1]) == 7   # a cloud each
    charts._pyplot().close(drawn[1])
