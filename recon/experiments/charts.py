"""Every chart recon draws (matplotlib, Agg, one resolution): the studies' score panels, grouped
bars, coverage maps and clouds, ``recon edges``' edge pictures, ``recon compare``'s speed against
accuracy, and ``recon stability``'s failure and accuracy maps.

Every chart of a study shows the paper's edge score beside the standard scores (F-score, Chamfer
distance, coverage), each panel saying which way is better, so no conclusion rests on one metric.
Log axes carry plain-number tick labels (20, not 2 x 10^1).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from formats.atomic import write_atomically
from formats.errors import ResourceError
from recon.experiments.cases import CHAMFER, FSCORE, pareto_front
from recon.surfaces.isolation import FAILURE_KINDS

# (key, axis label, lower is better). The edge score is our formalisation of the paper's metric
# (metrics/edges.py); tau is 1 % of the truth's bounding-box diagonal (metrics/defaults.py).
METRICS = (
    ("edge_score", "edge score (paper's metric)", True),
    ("fscore", "F-score at τ", False),
    ("chamfer_m", "Chamfer distance [m]", True),
    ("coverage", "coverage (area within τ)", False),
)
# Chamfer axes are logarithmic when the values span more than this factor (else linear: a log
# axis within one decade has no labelled ticks).
LOG_SPAN = 5.0
# Resolution of every PNG: readable on screen, small enough to embed in reports and docs.
DPI = 100
# Colours of the failure map, per outcome.
OUTCOME_COLOURS = {"ok": "#4daf4a", "timeout": "#984ea3", "crash": "#e41a1c",
                   "memory": "#ff7f00", "error": "#377eb8", "empty": "#a65628",
                   "degenerate": "#f781bf", "score": "#999999", "task": "#333333",
                   "collapse": "#ffd92f"}
# Marker and colour of each surface method, the same in every chart whatever its rank (a reader
# learns them once); plane and planes, poisson and screened-poisson well apart.
METHOD_STYLES = {
    "convex-hull": ("o", "#7f7f7f"), "ellipsoid": ("s", "#bcbd22"),
    "planes": ("D", "#2ca02c"), "plane": ("v", "#d62728"),
    "poisson": ("^", "#1f77b4"), "screened-poisson": ("<", "#17becf"),
    "ball-pivoting": (">", "#ff7f0e"), "ball-pivoting-meshlab": ("P", "#8c564b"),
    "alpha-shape": ("X", "#9467bd"), "rimls": ("*", "#e377c2"), "apss": ("h", "#393b79"),
    "delaunay-balls": ("p", "#111111"), "visibility": ("8", "#e7ba52"),
    "completed-poisson": ("d", "#843c39"),
}
# Styles of methods not listed above (test methods), picked by a checksum of the name; filled
# markers only, since every marker is drawn with a black edge.
EXTRA_MARKERS = ("H",)
EXTRA_COLOURS = ("#843c39", "#637939", "#5254a3", "#ad494a", "#8ca252", "#7b4173")
# The missed gentle edges of an edge picture (often tens of thousands): thin, light, faint.
GENTLE_EDGE_STYLE = {"colors": "#f5a142", "linewidths": 0.25, "alpha": 0.3, "zorder": 1}
# Points drawn per class in an edge picture (a seeded subsample beyond): 3D scatter cost grows
# with the count, and 60,000 grey points already fill a 6-inch panel.
MAX_DRAWN = 60_000
# Equal-area bins of the coverage maps: longitude steps and latitude bands (uniform in sin).
MAP_LON_BINS, MAP_LAT_BINS = 72, 36


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    # Every text is drawn as written: titles, labels and file names are the user's free text,
    # and a '$' in them (`--title '$\frac{a}{$'`, a file named 'a$b.ply') is a dollar sign,
    # not TeX for matplotlib's mathtext parser to fail on.
    matplotlib.rcParams["text.parse_math"] = False
    import matplotlib.pyplot as plt

    return plt


def preload() -> None:
    """Import matplotlib in a background thread now (a sweep calls it before its runs: its
    parent only waits on the workers), so the charts at the end do not wait for the import."""
    import threading

    threading.Thread(target=_pyplot, name="recon-charts-preload", daemon=True).start()


def _save(fig, path) -> Path:
    """Write ``fig`` to ``path`` atomically: an interrupted or failed write (a full disk)
    leaves the previous chart as it was. The PNG carries the chart's title (its ``Title``
    text chunk), which ``recon report`` shows as the picture's alt text."""
    title = fig.get_suptitle() or next((ax.get_title() for ax in fig.axes if ax.get_title()),
                                       "")
    metadata = {"Title": " ".join(title.split())} if title else {}
    try:
        return write_atomically(path, lambda tmp: fig.savefig(tmp, dpi=DPI, metadata=metadata),
                                error=ResourceError)
    finally:
        _pyplot().close(fig)


def _plain_log_ticks(axis) -> None:
    """Readable ticks on a log axis whatever its range: plain numbers (20, not 2 x 10^1) at
    1, 2 and 5 times the decades over a wide range, and at evenly spaced round numbers within a
    narrow one (where a log locator would label at most one tick)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter

    class ReadableLogLocator(LogLocator):
        def tick_values(self, vmin, vmax):
            lo, hi = sorted((vmin, vmax))
            ticks = LogLocator(subs=(1.0, 2.0, 5.0)).tick_values(lo, hi)
            if np.count_nonzero((ticks >= lo) & (ticks <= hi)) >= 3 or lo <= 0:
                return ticks
            linear = MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]).tick_values(lo, hi)
            return linear[linear > 0]

    axis.set_major_locator(ReadableLogLocator())
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.4g}"))
    axis.set_minor_formatter(NullFormatter())


def _spans(lines, factor: float) -> bool:
    """True when the positive y data of ``lines`` span more than ``factor`` (max / min)."""
    y = np.concatenate([np.asarray(line.get_ydata(), dtype=float) for line in lines] or [[]])
    y = y[np.isfinite(y) & (y > 0)]
    return bool(y.size) and y.max() > factor * y.min()


def _wrap(text: str, width_in: float, fontsize: float) -> str:
    """``text`` broken into lines that fit ``width_in`` inches at ``fontsize`` points (an
    average character is about half an em wide)."""
    import textwrap

    columns = max(20, int(width_in * 72 / (0.5 * fontsize)))
    return "\n".join(textwrap.fill(line, columns) for line in text.split("\n"))


def _title(fig, title: str, note: str = "") -> None:
    """The figure's title, with optional small print under it (assumptions), both wrapped to
    the figure's width."""
    size = 11.5 if note else 12
    fig.suptitle(_wrap(title + (f"\n{note}" if note else ""), fig.get_figwidth() * 0.95, size),
                 fontsize=size)


def _better(lower: bool) -> str:
    return "lower is better" if lower else "higher is better"


def metric_panels(curves: Sequence[Mapping], path, *, title: str, x_label: str,
                  logx: bool = False, references: Sequence[Mapping] = (),
                  metrics=METRICS, note: str = "") -> Path:
    """One panel per metric, a line per curve.

    Parameters
    ----------
    curves : sequence of dict
        ``label``, ``x`` (n,), ``y`` (dict of metric key to (n,) values) and optionally
        ``style`` (matplotlib keyword arguments).
    path : str or Path
        PNG to write.
    title, x_label : str
    logx : bool
        Logarithmic x axis.
    references : sequence of dict
        Horizontal reference lines: ``label``, ``y`` (dict of metric key to value), ``style``.
    metrics : sequence of (key, label, lower_is_better)
    note : str
        Small print under the panels (what was assumed, score options).
    """
    plt = _pyplot()
    n = len(metrics)
    cols = 2 if n > 1 else 1
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(11, 3.6 * rows + 0.9), squeeze=False,
                             constrained_layout=True)
    for ax, (key, label, lower) in zip(axes.flat, metrics, strict=False):
        _metric_axis(ax, curves, key, label, lower, x_label=x_label, logx=logx,
                     references=references)
        ax.set_title(f"{label} ({_better(lower)})", fontsize=10)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    _shared_legend(fig, list(axes.flat)[:n])
    _title(fig, title, note)
    return _save(fig, path)


def metric_grid(rows: Sequence[Mapping], path, *, title: str, x_label: str,
                metrics=METRICS, x_ticks: Sequence[float] | None = None, legend_columns: int = 2,
                note: str = "") -> Path:
    """A row of metric panels per group (e.g. per target), a line per curve, one legend.

    Parameters
    ----------
    rows : sequence of dict
        ``title`` (of the row) and ``curves`` (as for ``metric_panels``; the same labels in
        every row share one legend entry).
    path : str or Path
        PNG to write.
    title, x_label : str
    metrics : sequence of (key, label, lower_is_better)
        One column each.
    x_ticks : sequence of float, optional
        Ticks of every x axis, labelled as plain numbers. When they start at 0 and the positive
        ones span more than ``LOG_SPAN``, the axes are symmetric-log (linear up to the smallest
        positive tick), so small values do not bunch up at 0.
    legend_columns : int
        Columns of the legend (it fills column by column).
    note : str
        Small print under the title.
    """
    plt = _pyplot()
    fig = plt.figure(figsize=(4.1 * len(metrics), 3.3 * len(rows) + 1.5), layout="constrained")
    for sub, row in zip(fig.subfigures(len(rows), 1, squeeze=False)[:, 0], rows, strict=True):
        for ax, (key, label, lower) in zip(sub.subplots(1, len(metrics), squeeze=False)[0],
                                           metrics, strict=True):
            _metric_axis(ax, row["curves"], key, label, lower, x_label=x_label)
            ax.set_title(f"{label} ({_better(lower)})", fontsize=10)
            if x_ticks is not None:
                _set_x_ticks(ax, x_ticks)
        sub.suptitle(row["title"], fontsize=11, fontweight="bold")
    _shared_legend(fig, fig.axes, ncol=legend_columns)
    _title(fig, title, note)
    return _save(fig, path)


def _set_x_ticks(ax, ticks: Sequence[float]) -> None:
    """Plain-number ticks at ``ticks``; symmetric-log when they start at 0 and span decades."""
    from matplotlib.ticker import FixedLocator, NullLocator

    ticks = sorted(float(t) for t in ticks)
    positive = [t for t in ticks if t > 0]
    if ticks[0] == 0 and positive and positive[-1] > LOG_SPAN * positive[0]:
        ax.set_xscale("symlog", linthresh=positive[0], linscale=0.6)
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_minor_locator(NullLocator())
    ax.set_xticklabels([f"{t:g}" for t in ticks])


def _metric_axis(ax, curves: Sequence[Mapping], key: str, label: str, lower: bool, *,
                 x_label: str, logx: bool = False, references: Sequence[Mapping] = ()) -> None:
    """Draw the ``key`` values of ``curves`` (and reference lines) on one panel."""
    for curve in curves:
        y = np.asarray(curve["y"].get(key, []), dtype=float)
        if y.size == 0 or np.all(np.isnan(y)):
            continue
        style = {"marker": "o", "ms": 3.5, "lw": 1.6} | dict(curve.get("style", {}))
        ax.plot(curve["x"], y, label=curve["label"], **style)
    for ref in references:
        value = ref["y"].get(key)
        if value is not None and np.isfinite(value):
            style = {"color": "0.35", "ls": ":", "lw": 1.4} | dict(ref.get("style", {}))
            ax.axhline(value, label=ref["label"], **style)
    if logx:
        ax.set_xscale("log")
        _plain_log_ticks(ax.xaxis)
    if key.startswith("chamfer") and _spans(ax.get_lines(), LOG_SPAN):
        ax.set_yscale("log")
        _plain_log_ticks(ax.yaxis)
    ax.set_xlabel(x_label)
    ax.set_ylabel(label)
    ax.grid(True, which="both", alpha=0.3)


def _shared_legend(fig, axes, *, ncol: int = 4, loc: str = "outside lower center") -> None:
    """One legend (below the panels by default) with every label of ``axes`` once."""
    handles, labels = [], []
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc=loc, ncol=min(len(labels), ncol), fontsize=8.5,
               frameon=False)


def grouped_bars(groups: Sequence[str], scenarios: Sequence[str], values: Mapping, path, *,
                 title: str, errors: Mapping | None = None, paper: Mapping | None = None,
                 metrics=METRICS, note: str = "") -> Path:
    """Grouped bars: one group per configuration, one bar per scenario, one panel per metric.

    Parameters
    ----------
    groups : sequence of str
        Configurations (x axis), e.g. LIDAR, cross, zigzag.
    scenarios : sequence of str
        Bars within a group, e.g. no error, stochastic, pulse dilation.
    values : dict of (metric, group, scenario) to float
        Missing keys draw no bar ("n/a").
    errors : dict of (metric, group, scenario) to float, optional
        Error bars (standard deviation over seeds).
    paper : dict of (group, scenario) to float, optional
        The paper's edge scores, drawn as black diamonds on the edge-score panel.
    """
    plt = _pyplot()
    colours = plt.get_cmap("tab10")
    n = len(metrics)
    fig, axes = plt.subplots((n + 1) // 2, 2, figsize=(11, 3.6 * ((n + 1) // 2) + 0.9),
                             squeeze=False, constrained_layout=True)
    width = 0.8 / max(len(scenarios), 1)
    x = np.arange(len(groups))
    for ax, (key, label, lower) in zip(axes.flat, metrics, strict=False):
        for j, scenario in enumerate(scenarios):
            heights = np.array([values.get((key, g, scenario), np.nan) for g in groups], float)
            err = None
            if errors:
                err = np.array([errors.get((key, g, scenario), 0.0) or 0.0 for g in groups])
            offset = (j - (len(scenarios) - 1) / 2) * width
            ax.bar(x + offset, np.nan_to_num(heights), width, yerr=err, capsize=3,
                   color=colours(j), label=scenario, edgecolor="black", linewidth=0.4)
            for xi, h in zip(x + offset, heights, strict=True):
                if np.isnan(h):
                    ax.text(xi, 0, "n/a", ha="center", va="bottom", fontsize=7, rotation=90)
            if paper and key == "edge_score":
                p = np.array([paper.get((g, scenario), np.nan) for g in groups], float)
                ax.scatter(x + offset, p, marker="D", color="black", s=22, zorder=4,
                           label="paper's value" if j == 0 else None)
        ax.set_xticks(x, groups)
        ax.set_title(f"{label} ({_better(lower)})", fontsize=10)
        ax.set_ylabel(label)
        if key.startswith("chamfer"):
            ax.set_yscale("log")
            _plain_log_ticks(ax.yaxis)
        ax.grid(True, axis="y", alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    handles, labels = [], []
    for ax in list(axes.flat)[:n]:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=8.5,
               frameon=False)
    _title(fig, title, note)
    return _save(fig, path)


def face_lonlat(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """Longitude and latitude of each face centroid in the body frame, and face areas.

    The centroids are first scaled by the half-extents of the mesh's bounding box, so an
    ellipsoid maps onto the unit sphere: its faces (an icosphere scaled onto it) then spread
    evenly over equal-area bins, and the latitude is the ellipsoid's parametric latitude.

    Parameters
    ----------
    vertices : (v, 3) float64, metres, body frame (spin axis +z)
    faces : (f, 3) int

    Returns
    -------
    lon, lat : (f,) float64, degrees (latitude from the x-y plane, positive towards +z)
    area : (f,) float64, m^2
    """
    tri = vertices[faces]
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    half = np.where(hi > lo, (hi - lo) / 2, 1.0)
    centre = (tri.mean(axis=1) - (hi + lo) / 2) / half
    lon = np.degrees(np.arctan2(centre[:, 1], centre[:, 0]))
    lat = np.degrees(np.arctan2(centre[:, 2], np.hypot(centre[:, 0], centre[:, 1])))
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return lon, lat, area


def binned_map(lon, lat, area, coverage) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Area-weighted mean coverage on equal-area longitude-latitude bins.

    Returns
    -------
    lon_edges : (MAP_LON_BINS + 1,) degrees
    lat_edges : (MAP_LAT_BINS + 1,) degrees, uniform in sin(latitude)
    grid : (MAP_LAT_BINS, MAP_LON_BINS) float64, NaN where no face centroid falls
    """
    lon_edges = np.linspace(-180.0, 180.0, MAP_LON_BINS + 1)
    lat_edges = np.degrees(np.arcsin(np.linspace(-1.0, 1.0, MAP_LAT_BINS + 1)))
    weight, _, _ = np.histogram2d(lat, lon, bins=[lat_edges, lon_edges], weights=area)
    covered, _, _ = np.histogram2d(lat, lon, bins=[lat_edges, lon_edges],
                                   weights=area * np.asarray(coverage, dtype=float))
    grid = np.divide(covered, weight, out=np.full_like(weight, np.nan), where=weight > 0)
    return lon_edges, lat_edges, grid


def coverage_maps(panels: Sequence[Mapping], path, *, title: str, cols: int = 2,
                  note: str = "") -> Path:
    """Maps of per-face coverage over body-frame longitude and latitude.

    Parameters
    ----------
    panels : sequence of dict
        ``title``, ``lon``, ``lat``, ``area`` (per face, from ``face_lonlat``) and
        ``coverage`` (per face, in [0, 1]).
    """
    plt = _pyplot()
    rows = (len(panels) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(5.6 * cols, 3.3 * rows + 0.8), squeeze=False,
                             constrained_layout=True)
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")
    image = None
    for ax, panel in zip(axes.flat, panels, strict=False):
        lon_edges, lat_edges, grid = binned_map(panel["lon"], panel["lat"], panel["area"],
                                                panel["coverage"])
        image = ax.pcolormesh(lon_edges, lat_edges, np.ma.masked_invalid(grid), cmap=cmap,
                              vmin=0.0, vmax=1.0, shading="flat")
        ax.set_title(panel["title"], fontsize=10)
        ax.set_xlabel("body-frame longitude [deg]")
        ax.set_ylabel("parametric latitude [deg]")
        ax.set_xticks(np.arange(-180, 181, 60))
        ax.set_yticks(np.arange(-90, 91, 30))
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    if image is not None:
        fig.colorbar(image, ax=axes, shrink=0.8,
                     label="fraction of the area within τ of a strike")
    _title(fig, title, note)
    return _save(fig, path)


def clouds(panels: Sequence[Mapping], path, *, title: str) -> Path:
    """3D scatter pictures of point clouds, one panel each (``title``, ``points`` (n, 3) m)."""
    plt = _pyplot()
    fig = plt.figure(figsize=(5.2 * len(panels), 5.4), constrained_layout=True)
    for i, panel in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), i + 1, projection="3d")
        p = np.asarray(panel["points"], dtype=float).reshape(-1, 3)
        if len(p):
            ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=0.6, c=p[:, 2], cmap="viridis",
                       depthshade=False)
            span = (p.max(axis=0) - p.min(axis=0)).max() / 2
            mid = (p.max(axis=0) + p.min(axis=0)) / 2
            for setter, m in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, strict=True):
                setter(m - span, m + span)
        ax.set_box_aspect(None, zoom=0.88)  # room for the z label
        ax.set_title(panel["title"], fontsize=10)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
    fig.suptitle(title, fontsize=12)
    return _save(fig, path)


def edge_points(points: np.ndarray, label: np.ndarray, path, *, bounds, missed_feature,
                missed_gentle, title: str, note: str = "", seed: int = 0,
                views=((22.0, -55.0), (22.0, 125.0))) -> Path:
    """The paper's edge pictures (Figs. 15, 17, 19): a cloud's edge points, two opposite views.

    Parameters
    ----------
    points : (n, 3) float64, metres
    label : (n,) uint8
        0 surface point (light grey), 1 detected edge point near a truth feature edge (blue, as
        the paper's "Blue points are detected edges"), 2 false edge point (red).
    path : str or Path
        PNG to write.
    bounds : ((3,), (3,)) metres
        Lower and upper corner of the truth, so every picture of one body has the same box.
    missed_feature : (a, 2, 3) float64, metres
        Truth feature edges not reconstructed (black).
    missed_gentle : (b, 2, 3) float64, metres
        Gentler truth edges not reconstructed: the unsampled triangulation (faint orange,
        behind the points).
    title, note : str
    seed : int
        Seed of the subsample drawn when a class has more than ``MAX_DRAWN`` points.
    views : sequence of (elevation, azimuth) degrees
    """
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    plt = _pyplot()
    rng = np.random.default_rng(seed)
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    classes = ((0, "surface points", "0.72", 0.4), (2, "false edge points", "#d62728", 2.0),
               (1, "detected edge points", "#1f3fbf", 2.0))
    drawn = {}
    for value, *_ in classes:
        index = np.flatnonzero(label == value)
        if len(index) > MAX_DRAWN:
            index = np.sort(rng.choice(index, MAX_DRAWN, replace=False))
        drawn[value] = (points[index], int((label == value).sum()))
    # Gentle edges are many (every unsampled triangle edge): thin and faint, behind the points,
    # so they read as a shade over the blind spots; missed feature edges stand out in black.
    lines = ((missed_gentle, GENTLE_EDGE_STYLE, "missed gentle truth edges"),
             (missed_feature, {"colors": "black", "linewidths": 1.3, "zorder": 3},
              "missed feature edges"))
    size, zoom = _edge_figure_size(lo, hi, len(views))
    fig = plt.figure(figsize=size, constrained_layout=True)
    for i, (elevation, azimuth) in enumerate(views):
        ax = fig.add_subplot(1, len(views), i + 1, projection="3d")
        ax.computed_zorder = False   # draw in the order given: gentle edges first
        for segments, style, text in lines:
            segments = np.asarray(segments, dtype=float).reshape(-1, 2, 3)
            if len(segments):
                ax.add_collection3d(Line3DCollection(segments, label=f"{text} ({len(segments):,})",
                                                     **style))
        for value, text, colour, size in classes:
            p, total = drawn[value]
            if total:
                ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=size, c=colour, depthshade=False,
                           linewidths=0, label=f"{text} ({total:,})", zorder=2)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(np.maximum(hi - lo, 1e-9 * (hi - lo).max()), zoom=zoom)
        ax.view_init(elev=elevation, azim=azimuth)
        ax.set_title(f"view from elevation {elevation:g} deg, azimuth {azimuth:g} deg",
                     fontsize=9.5)
        for axis, name in ((ax.xaxis, "x"), (ax.yaxis, "y"), (ax.zaxis, "z")):
            axis.set_major_locator(MaxNLocator(4))
            axis.set_label_text(f"{name} [m]")
        if i == 0:
            handles, texts = ax.get_legend_handles_labels()
    legend = fig.legend(handles, texts, loc="outside lower center", ncol=len(texts),
                        fontsize=9, markerscale=5, frameon=False)
    for handle in legend.legend_handles:   # a faint, thin line is hard to see in a key
        if isinstance(handle, Line2D):
            handle.set_color(handle.get_color()[:3] if np.ndim(handle.get_color()) else
                             handle.get_color())
            handle.set_linewidth(max(handle.get_linewidth(), 2.0))
    _title(fig, title, note)
    return _save(fig, path)


def _edge_figure_size(lo: np.ndarray, hi: np.ndarray, n_views: int
                      ) -> tuple[tuple[float, float], float]:
    """Size of an edge picture and the zoom of its 3D panels.

    Each panel is shaped as the body looks from the side (its horizontal diagonal against its
    height), so neither a tall body nor a flat one leaves an empty band, with room above for the
    title and below for the legend. matplotlib fits a 3D box into the panel's shorter side
    whatever its shape; the zoom enlarges a long box into the longer side.

    Returns
    -------
    (width, height) : inches
    zoom : float
        ``Axes3D.set_box_aspect``'s zoom.
    """
    extent = np.maximum(hi - lo, 1e-9 * (hi - lo).max())
    ratio = float(np.hypot(extent[0], extent[1]) / extent[2])
    if ratio >= 1.0:   # wide: full-width panels, as tall as the body needs
        width, height = 6.0, float(np.clip(6.0 / ratio, 3.0, 6.0))
    else:              # tall: full-height panels, as wide as the body needs
        width, height = float(np.clip(5.6 * ratio, 4.2, 5.6)), 5.6
    zoom = 0.9 * float(np.sqrt(max(width, height) / min(width, height)))
    return (n_views * width + 0.6, height + 1.6), zoom


def bars(labels: Sequence[str], values: Mapping[str, Sequence[float]], path, *, title: str,
         ylabel: str, annotate: bool = True) -> Path:
    """Side-by-side bars: one group per label, one bar per series (NaN draws no bar).

    Parameters
    ----------
    labels : sequence of str
        Groups on the x axis.
    values : dict of series name to values (one per label)
    """
    plt = _pyplot()
    colours = plt.get_cmap("tab10")
    fig, ax = plt.subplots(figsize=(9, 4.8), constrained_layout=True)
    x = np.arange(len(labels))
    width = 0.8 / max(len(values), 1)
    for j, (name, ys) in enumerate(values.items()):
        ys = np.asarray(ys, dtype=float)
        offset = (j - (len(values) - 1) / 2) * width
        shown = ~np.isnan(ys)
        rects = ax.bar((x + offset)[shown], ys[shown], width, label=name, color=colours(j),
                       edgecolor="black", linewidth=0.4)
        if annotate:
            ax.bar_label(rects, labels=[f"{v:,.0f}" for v in ys[shown]], fontsize=8, padding=2)
    ax.set_xticks(x, labels)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=11)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=9)
    ax.margins(y=0.12)
    return _save(fig, path)


def heatmaps(rows: Sequence[str], cols: Sequence[str], panels: Sequence[Mapping], path, *,
             title: str, note: str = "") -> Path:
    """Annotated heatmaps one above the other, e.g. methods x conditions.

    Parameters
    ----------
    rows, cols : sequence of str
        Row and column labels.
    panels : sequence of dict
        ``title``, ``values`` ((rows, cols) float, NaN: failed or not run, drawn grey and
        marked "x"), ``label`` (colour-bar label), ``lower_better`` (bool), ``log`` (bool),
        ``fmt`` (format of the annotations, e.g. "{:.3f}"), and optionally ``colour``
        ((rows, cols) float: what the colours show, when not the annotated values).
    """
    from matplotlib.colors import LogNorm, Normalize

    plt = _pyplot()
    # At least 8.5 x 3.4 inches a panel: room for its title and its colour bar's label.
    width = max(8.5, 3.5 + 1.25 * len(cols))
    fig, axes = plt.subplots(len(panels), 1, figsize=(width, max(3.4, 1.6 + 0.4 * len(rows))
                                                      * len(panels)),
                             squeeze=False, constrained_layout=True)
    for ax, panel in zip(axes.flat, panels, strict=True):
        values = np.asarray(panel["values"], dtype=float)
        shown = np.asarray(panel.get("colour", values), dtype=float)
        finite = shown[np.isfinite(shown)]
        cmap = plt.get_cmap("viridis_r" if panel.get("lower_better") else "viridis")
        cmap = cmap.with_extremes(bad="0.8")
        if panel.get("log") and finite.size and finite.min() > 0:
            norm = LogNorm(vmin=finite.min(), vmax=max(finite.max(), finite.min() * 1.01))
        else:
            norm = Normalize(vmin=finite.min() if finite.size else 0,
                             vmax=finite.max() if finite.size else 1)
        image = ax.imshow(np.ma.masked_invalid(shown), cmap=cmap, norm=norm, aspect="auto")
        for (i, j), v in np.ndenumerate(values):
            text = "x" if not np.isfinite(v) else panel.get("fmt", "{:.3g}").format(v)
            shade = 0.0 if not np.isfinite(shown[i, j]) else norm(shown[i, j])
            dark = shade > 0.6 if panel.get("lower_better") else shade < 0.4
            ax.text(j, i, text, ha="center", va="center", fontsize=7.5,
                    color="white" if dark and np.isfinite(v) else "black")
        ax.set_xticks(np.arange(len(cols)), cols, rotation=30, ha="right", fontsize=8)
        ax.set_yticks(np.arange(len(rows)), rows, fontsize=8)
        better = _better(bool(panel.get("lower_better")))
        ax.set_title(_wrap(f"{panel['title']} ({better})", width * 0.7, 10), fontsize=10)
        bar = fig.colorbar(image, ax=ax, shrink=0.85)
        bar.set_label(_wrap(panel.get("label", ""), 0.85 * ax.figure.get_figheight()
                            / len(panels), 10), fontsize=10)
        if isinstance(norm, LogNorm):
            _plain_log_ticks(bar.ax.yaxis)
    _title(fig, title, note)
    return _save(fig, path)


def method_style(name: str) -> dict:
    """The marker and colour of surface method ``name``, the same in every chart.

    Parameters
    ----------
    name : str
        A method name (``recon methods``); one not in ``METHOD_STYLES`` (a test method) gets a
        fixed style from a checksum of its name.

    Returns
    -------
    dict
        ``marker`` and ``color``, matplotlib keyword arguments.
    """
    import zlib

    if name in METHOD_STYLES:
        marker, colour = METHOD_STYLES[name]
    else:
        code = zlib.crc32(name.encode("utf-8"))
        marker = EXTRA_MARKERS[code % len(EXTRA_MARKERS)]
        colour = EXTRA_COLOURS[(code // len(EXTRA_MARKERS)) % len(EXTRA_COLOURS)]
    return {"marker": marker, "color": colour}


# Offsets of the Pareto-front labels from their points, in points, tried in turn until the label
# covers no other label or marker; a thin line joins each label to its marker.
LABEL_OFFSETS = ((14, 14), (14, -18), (-14, 16), (-14, -18), (30, 34), (30, -38), (-30, 36),
                 (-30, -38), (0, 48), (0, -50))


def speed_accuracy(records: list[dict], path, *, title: str = "") -> Path:
    """Write the speed-accuracy chart (``speed_accuracy_figure``) to ``path``."""
    return _save(speed_accuracy_figure(records, title=title), path)


def speed_accuracy_figure(records: list[dict], *, title: str = ""):
    """Wall time against Chamfer distance (left) and F-score (right), one marker per run in
    its method's style (``method_style``), the Pareto fronts dashed and their runs labelled, a
    line joining each label to its own marker.

    Parameters
    ----------
    records : list of dict
        Runs of ``recon compare``: ``method``, ``label``, ``status``, ``wall_time_s`` [s],
        ``chamfer_m`` [m], ``fscore`` and optionally ``failure``.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    ok = [r for r in records if r.get("status") == "ok" and r.get(CHAMFER) is not None
          and r.get("wall_time_s")]
    fig, axes = plt.subplots(1, 2, figsize=(14, 5.6), constrained_layout=True)
    fronts = []
    for ax, metric, minimize, ylabel in (
            (axes[0], CHAMFER, True, "Chamfer distance [m] (lower is better)"),
            (axes[1], FSCORE, False, "F-score (higher is better)")):
        runs = [r for r in ok if r.get(metric) is not None]
        _method_markers(ax, runs, metric)
        fronts.append((ax, runs, _pareto_front(ax, runs, metric, minimize), metric))
        _speed_axes(ax, runs, metric, ylabel)
    if ok:
        _shared_legend(fig, axes, ncol=1, loc="outside right upper")
    fig.suptitle(title or "speed against accuracy", fontsize=11)
    fig.draw_without_rendering()   # the layout, so that labels can be placed apart
    for ax, runs, front, metric in fronts:
        _pareto_labels(ax, runs, front, metric)
    failed = [r for r in records if r.get("status") != "ok"]
    if failed:
        text = "failed: " + "; ".join(f"{r['label']} ({r.get('failure')})" for r in failed)
        fig.text(0.01, 0.005, text[:260], fontsize=7, color="firebrick", va="bottom")
    return fig


def _method_markers(ax, runs: list[dict], metric: str) -> None:
    """One scatter per method, in its fixed style, labelled with the method's name."""
    for name in dict.fromkeys(r["method"] for r in runs):
        mine = [r for r in runs if r["method"] == name]
        ax.scatter([r["wall_time_s"] for r in mine], [r[metric] for r in mine], s=55,
                   label=name, edgecolors="black", linewidths=0.5, zorder=3,
                   **method_style(name))


def _pareto_front(ax, runs: list[dict], metric: str, minimize: bool) -> list[int]:
    """Draw the Pareto front of ``runs`` as a dashed step line; return its runs' indices."""
    if not runs:
        return []
    t = np.array([r["wall_time_s"] for r in runs], dtype=float)
    v = np.array([r[metric] for r in runs], dtype=float)
    front = pareto_front(t, v, minimize=minimize)
    ax.step(t[front], v[front], where="post", color="0.3", lw=1.2, ls="--", zorder=2,
            label="Pareto front")
    return [int(i) for i in front]


def _pareto_labels(ax, runs: list[dict], front: list[int], metric: str) -> None:
    """Label each run of the Pareto front: the label's anchor is the run's own point, joined to
    the text by a thin line; the text goes to the first of ``LABEL_OFFSETS`` where it stays
    inside the panel and covers no label placed before and no marker (the figure's layout must
    be drawn)."""
    from matplotlib.text import Text

    renderer = ax.figure.canvas.get_renderer()
    markers = np.concatenate([c.get_offset_transform().transform(c.get_offsets())
                              for c in ax.collections] or [np.empty((0, 2))])
    taken = []
    for i in front:
        point = (runs[i]["wall_time_s"], runs[i][metric])
        for offset in LABEL_OFFSETS:
            label = ax.annotate(
                runs[i]["label"], point, textcoords="offset points", xytext=offset,
                fontsize=7.5, color="0.15", ha="left" if offset[0] > 0 else "right",
                va="center", zorder=5,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.75},
                arrowprops={"arrowstyle": "-", "color": "0.35", "lw": 0.7, "shrinkA": 0,
                            "shrinkB": 4})
            label.set_in_layout(False)   # the layout stays as the placement saw it
            label.update_positions(renderer)
            box = Text.get_window_extent(label, renderer).padded(2)   # the text, not its line
            inside = (box.x0 >= ax.bbox.x0 and box.x1 <= ax.bbox.x1 and box.y0 >= ax.bbox.y0
                      and box.y1 <= ax.bbox.y1)
            if (inside and not _covers(box, taken, markers)) or offset == LABEL_OFFSETS[-1]:
                break
            label.remove()
        taken.append(box)


def _covers(box, boxes: list, points: np.ndarray, radius: float = 6.0) -> bool:
    """Whether display box ``box`` overlaps any of ``boxes`` or comes within ``radius``
    (pixels: a marker's size) of any of ``points``."""
    inside = ((points[:, 0] >= box.x0 - radius) & (points[:, 0] <= box.x1 + radius)
              & (points[:, 1] >= box.y0 - radius) & (points[:, 1] <= box.y1 + radius))
    return bool(inside.any()) or any(box.overlaps(other) for other in boxes)


def _speed_axes(ax, runs: list[dict], metric: str, ylabel: str) -> None:
    """Scales, limits and labels of one speed-accuracy panel (a note when nothing ran)."""
    if runs:
        ax.set_xscale("log")
        _plain_log_ticks(ax.xaxis)
        if metric == CHAMFER:
            ax.set_yscale("log")
            _plain_log_ticks(ax.yaxis)
        else:
            ax.set_ylim(max(0.0, min(r[metric] for r in runs) - 0.05), 1.02)
    else:
        ax.text(0.5, 0.5, "every run failed: nothing to place", ha="center", va="center",
                transform=ax.transAxes, color="firebrick")
        ax.set_xticks([])
        ax.set_yticks([])
    ax.set_xlabel("wall time of the method [s] (log)")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)


def _cells(records, noise, density, outliers, value):
    """(outliers, noise, density) array of ``value(record)`` (None where no record)."""
    out = np.empty((len(outliers), len(noise), len(density)), dtype=object)
    for r in records:
        i = noise.index(r["noise_sigma3_m"])
        j = density.index(r["density"])
        k = outliers.index(r["outliers"])
        out[k, i, j] = value(r)
    return out


def _cell_axes(n_panels: int):
    """A row of ``n_panels`` square-ish panels for grid maps: (figure, axes)."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, n_panels, figsize=(4.2 * n_panels + 1.2, 4.2), squeeze=False,
                             constrained_layout=True)
    return fig, axes[0]


def _label_cells(ax, noise, density, outlier):
    ax.set_xticks(range(len(density)), [f"{d:g}" for d in density])
    ax.set_yticks(range(len(noise)), [f"{n:g}" for n in noise])
    ax.set_xlabel("density (fraction of points kept)")
    ax.set_ylabel("range noise, 3 sigma [m]")
    ax.set_title(f"outliers {outlier:g}", fontsize=10)


def failure_map(records, path, *, method, noise, density, outliers, rule: str = "") -> Path:
    """Per cell: green when the method succeeded, else the colour and name of its failure
    (``collapse``: an accuracy collapse, ``rule`` saying what counts as one)."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    kinds = ["ok", *FAILURE_KINDS, "task", "collapse"]
    code = _cells(records, noise, density, outliers,
                 lambda r: "collapse" if r.get("failure") == "collapse" else
                 "ok" if r["status"] == "ok" else (r.get("failure") or "error"))
    fig, axes = _cell_axes(len(outliers))
    cmap = ListedColormap([OUTCOME_COLOURS[k] for k in kinds])
    for k, ax in enumerate(axes):
        index = np.array([[kinds.index(c) if c in kinds else kinds.index("error")
                           for c in row] for row in code[k]], dtype=float)
        ax.imshow(index, cmap=cmap, vmin=-0.5, vmax=len(kinds) - 0.5, origin="lower",
                  aspect="auto")
        for i in range(len(noise)):
            for j in range(len(density)):
                ax.text(j, i, code[k][i, j], ha="center", va="center", fontsize=9,
                        color="black" if code[k][i, j] in ("ok", "collapse") else "white")
        _label_cells(ax, noise, density, outliers[k])
    seen = sorted({c for c in code.ravel() if c}, key=kinds.index)
    fig.legend(handles=[Patch(color=OUTCOME_COLOURS[c], label=c) for c in seen],
               loc="outside right center", fontsize=8)
    failed = sum(c != "ok" for c in code.ravel())
    fig.suptitle(f"{method}: failure map ({failed} of {code.size} cells failed)"
                 + (f"\n{rule}" if rule else ""), fontsize=11)
    return _save(fig, path)


def accuracy_map(records, path, *, method, noise, density, outliers) -> Path:
    """Per cell the Chamfer distance (log colour scale, shared by the panels); failed cells
    hatched grey with their failure kind."""
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Rectangle

    chamfer = _cells(records, noise, density, outliers,
                    lambda r: r.get(CHAMFER) if r["status"] == "ok" else None)
    fscore = _cells(records, noise, density, outliers,
                   lambda r: r.get(FSCORE) if r["status"] == "ok" else None)
    kind = _cells(records, noise, density, outliers, lambda r: r.get("failure"))
    values = np.array([[np.nan if v is None else float(v) for v in row]
                       for panel in chamfer for row in panel]).reshape(chamfer.shape)
    finite = values[np.isfinite(values) & (values > 0)]
    norm = LogNorm(vmin=finite.min(), vmax=max(finite.max(), finite.min() * 1.01)) \
        if len(finite) else None
    fig, axes = _cell_axes(len(outliers))
    image = None
    for k, ax in enumerate(axes):
        ax.set_facecolor("0.85")
        masked = np.ma.masked_invalid(values[k])
        image = ax.imshow(masked, cmap="viridis_r", norm=norm, origin="lower", aspect="auto")
        for i in range(len(noise)):
            for j in range(len(density)):
                if np.isfinite(values[k, i, j]):
                    f = fscore[k][i, j]
                    text = f"{values[k, i, j]:.3g} m" + ("" if f is None else f"\nF {f:.2f}")
                    if kind[k][i, j] == "collapse":
                        text += "\ncollapse"
                    ax.text(j, i, text, ha="center", va="center", fontsize=8, color="white",
                            path_effects=_outline())
                else:
                    ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False,
                                           hatch="//", edgecolor="0.55", lw=0))
                    ax.text(j, i, f"failed\n{kind[k][i, j] or ''}", ha="center", va="center",
                            fontsize=8, color="firebrick")
        _label_cells(ax, noise, density, outliers[k])
    if image is not None and norm is not None:
        bar = fig.colorbar(image, ax=list(axes), label="Chamfer distance [m] (lower is better)")
        _plain_log_ticks(bar.ax.yaxis)
    fig.suptitle(f"{method}: accuracy (Chamfer distance to the truth)", fontsize=11)
    return _save(fig, path)


def _outline():
    import matplotlib.patheffects as pe

    return [pe.withStroke(linewidth=1.5, foreground="black")]


def choice_vs_ranking(summaries: Sequence[Mapping], path, *, title: str) -> Path:
    """Per cloud, every run's truth score relative to the best (dots), the median run (bar),
    ``-m auto``'s choice (red star) and the visibility method's best run (blue diamond, where
    it ran): F-score ratio (higher is better) and Chamfer ratio (log, lower is better).

    Parameters
    ----------
    summaries : sequence of dict
        ``cloud``, ``ranking`` (runs with ``chamfer_m`` and ``fscore``), ``verdict``
        (``f_ratio``, ``chamfer_ratio``, unless ``failed``) and optionally ``visibility``
        (``present``, ``f_ratio``, ``chamfer_ratio``), as ``benchmarks/suite.py`` makes.
    """
    plt = _pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(max(10.0, 0.55 * len(summaries) + 5), 8.5),
                             sharex=True, constrained_layout=True)
    for ax, key, ratio, lower in ((axes[0], FSCORE, "f_ratio", False),
                                  (axes[1], CHAMFER, "chamfer_ratio", True)):
        for i, s in enumerate(summaries):
            _ranking_column(ax, i, s, key, ratio, lower)
        _ranking_axis(ax, lower)
    axes[1].set_xticks(np.arange(len(summaries)), [s["cloud"] for s in summaries], rotation=35,
                       ha="right", fontsize=8)
    _title(fig, title)
    return _save(fig, path)


def _ranking_column(ax, i: int, summary: Mapping, key: str, ratio: str, lower: bool) -> None:
    """Cloud ``i`` of ``choice_vs_ranking``: its runs, their median, auto's choice and the
    visibility method's best run, each relative to the best run; legend labels once."""
    values = np.array([r[key] for r in summary["ranking"] if r.get(key) is not None], float)
    if not values.size:
        return
    best = values.min() if lower else values.max()
    rel = values / best if best > 0 else np.full_like(values, np.nan)
    labelled = {text for text in ax.get_legend_handles_labels()[1]}

    def once(text):
        return None if text in labelled else text

    if summary.get("held_out"):
        ax.axvspan(i - 0.5, i + 0.5, color="gold", alpha=0.25, lw=0, zorder=0,
                   label=once("held-out cloud"))
    ax.scatter(np.full(rel.size, i), rel, s=14, color="0.55", alpha=0.7, zorder=2,
               label=once("a run"))
    ax.hlines(np.median(rel), i - 0.3, i + 0.3, color="0.2", lw=1.6, zorder=3,
              label=once("median run"))
    verdict = summary["verdict"]
    if not verdict.get("failed"):
        ax.scatter([i], [verdict[ratio]], marker="*", s=180, color="crimson",
                   edgecolors="black", linewidths=0.6, zorder=4, label=once("auto's choice"))
    seen = summary.get("visibility") or {}
    if seen.get("present"):
        ax.scatter([i + 0.18], [seen[ratio]], marker="D", s=40, color="tab:blue",
                   edgecolors="black", linewidths=0.5, zorder=4,
                   label=once("visibility method (its best run)"))


def _ranking_axis(ax, lower: bool) -> None:
    """The target band, scale, labels and legend of one ``choice_vs_ranking`` panel."""
    ax.axhline(1.10 if lower else 0.95, color="crimson", ls=":", lw=1.2,
               label="target: within 10% of the best Chamfer" if lower else
               "target: within 5% of the best F")
    if lower:
        ax.set_yscale("log")
        _plain_log_ticks(ax.yaxis)
    ax.set_ylabel("Chamfer / best Chamfer" if lower else "F-score / best F-score")
    ax.set_title(f"{'Chamfer distance' if lower else 'F-score'} relative to the truth's best"
                 f" run ({_better(lower)})", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.005, 1.0))


# Legend rows of the predicted-against-true chart: as many as its height holds at 7 pt.
LEGEND_ROWS = 40


def predicted_vs_true(summaries: Sequence[Mapping], path, *, title: str,
                      group: Callable[[Mapping], str] | None = None) -> Path:
    """Truth-free predicted Chamfer distance against the true one, every run of every cloud
    (log-log, the line of equality dashed); auto's choices drawn with their predicted band.

    Parameters
    ----------
    summaries : sequence of dict
        ``cloud``, ``held_out``, ``predicted`` (``runs``: ``truth_m``, ``predicted_m``) and
        ``auto`` (``chamfer_m``, ``predicted``: ``chamfer_m``, ``lo_m``, ``hi_m``), as
        ``benchmarks/suite.py`` makes.
    group : callable, optional
        A summary's group (e.g. the kind of target): a colour and a legend entry per group,
        the held-out clouds apart. Default: one per cloud, each named.
    """
    plt = _pyplot()
    name = group or (lambda s: s["cloud"])

    def entry(s):
        return name(s) + (" (held out)" if s.get("held_out") else "")
    entries = list(dict.fromkeys(map(entry, summaries)))
    # a legend column per LEGEND_ROWS entries, each beside the axes, so that every one is named
    ncol = max(1, -(-len(entries) // LEGEND_ROWS))
    fig, ax = plt.subplots(figsize=(9.4 + 2.6 * ncol, 7.5), constrained_layout=True)
    # a few groups: distinct hues (tab20 pairs a hue with its pale twin)
    palette = list(plt.get_cmap("tab10").colors) if group else \
        [*plt.get_cmap("tab20").colors, *plt.get_cmap("tab20b").colors]
    groups = list(dict.fromkeys(name(s) for s in summaries))

    def colours(s):
        return palette[groups.index(name(s)) % len(palette)]
    values, named = [], set()
    for s in summaries:
        runs = s["predicted"]["runs"]
        if not runs:
            continue
        truth = np.array([r["truth_m"] for r in runs])
        pred = np.array([r["predicted_m"] for r in runs])
        values += [truth, pred]
        ax.scatter(truth, pred, s=12, color=colours(s), alpha=0.6,
                   marker="^" if s.get("held_out") else "o",
                   label=None if entry(s) in named else entry(s))
        named.add(entry(s))
        a = s["auto"]
        if a.get("predicted") and a.get("chamfer_m") is not None:
            p = a["predicted"]
            ax.errorbar([a["chamfer_m"]], [p["chamfer_m"]],
                        yerr=[[p["chamfer_m"] - p["lo_m"]], [p["hi_m"] - p["chamfer_m"]]],
                        fmt="*", ms=13, color=colours(s), mec="black", mew=0.6,
                        ecolor="black", elinewidth=0.8, capsize=3, zorder=4)
    if values:
        both = np.concatenate(values)
        both = both[both > 0]
        lo, hi = both.min() / 1.5, both.max() * 1.5
        ax.plot([lo, hi], [lo, hi], ls="--", color="0.3", lw=1, label="predicted = true")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
    ax.set_xscale("log")
    ax.set_yscale("log")
    _plain_log_ticks(ax.xaxis)
    _plain_log_ticks(ax.yaxis)
    ax.set_xlabel("true Chamfer distance [m]")
    ax.set_ylabel("predicted Chamfer distance, without the truth [m]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=ncol, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_title("every run (dots; triangles: held-out clouds), auto's choice (star, its "
                 "predicted band)", fontsize=9)
    _title(fig, title)
    return _save(fig, path)


def coverage_and_effort(panels: Sequence[Mapping], path, *, title: str,
                        levels: Sequence[float] = ()) -> Path:
    """Coverage against time (top) and the total slew angle (below it) per target, at most
    three targets to a row, a line per attitude law.

    Parameters
    ----------
    panels : sequence of dict
        ``title`` and ``curves``: each a dict of ``label``, ``x`` (n,) hours, ``coverage`` (n,),
        ``slew_deg`` (n,) cumulative slew angle and optionally ``style``.
    levels : sequence of float
        Coverage levels drawn as dotted lines (the hours-to-level thresholds).
    """
    plt = _pyplot()
    columns = min(len(panels), 3)
    rows = -(-len(panels) // columns)
    fig, axes = plt.subplots(2 * rows, columns, figsize=(4.6 * columns, 7.0 * rows),
                             squeeze=False, constrained_layout=True)
    for index in range(len(panels), rows * columns):
        axes[2 * (index // columns), index % columns].set_visible(False)
        axes[2 * (index // columns) + 1, index % columns].set_visible(False)
    for index, panel in enumerate(panels):
        row, column = divmod(index, columns)
        top, bottom = axes[2 * row, column], axes[2 * row + 1, column]
        for curve in panel["curves"]:
            style = {"marker": "o", "ms": 3.0, "lw": 1.6} | dict(curve.get("style", {}))
            top.plot(curve["x"], curve["coverage"], label=curve["label"], **style)
            bottom.plot(curve["x"], np.maximum(curve["slew_deg"], 1.0), **style)
        for level in levels:
            top.axhline(level, color="0.6", ls=":", lw=1.0)
        for ax in (top, bottom):
            ax.set_xscale("log")
            _plain_log_ticks(ax.xaxis)
            ax.grid(True, which="both", alpha=0.3)
        top.set_title(panel["title"], fontsize=10.5)
        top.set_ylabel("coverage (area within τ; higher is better)")
        top.set_ylim(0.0, 1.0)
        bottom.set_yscale("log")
        _plain_log_ticks(bottom.yaxis)
        bottom.set_ylabel("total angle slewed [deg] (lower is cheaper)")
        bottom.set_xlabel("time [h] (log scale)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=9,
               frameon=False)
    _title(fig, title, "dotted: " + ", ".join(f"{level:.0%}" for level in levels)
           + " coverage" if levels else "")
    return _save(fig, path)
