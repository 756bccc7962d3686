"""``recon report``: one self-contained HTML page of a study, of all studies, of a comparison or
of a stability run.

The page needs nothing but itself: charts are embedded as base64 ``data:`` URIs (their alt text
the chart's own title), the style is inline, links point only inside the page. It shows, per
study directory (``recon study``), the paper's claims with our numbers and verdicts, the charts,
the CSV tables and the rest of ``summary.json`` as tables (numbers to 4 significant digits,
columns under readable headers); for ``recon study all`` the index of studies first; for a
``recon compare`` directory the ranked runs, the Pareto fronts and the speed-against-accuracy
chart; for a ``recon stability`` directory the failure rates, the maps and every cell.

A reduced run (``--quick``) cannot refute a claim: its "not reproduced" verdicts read "not
tested" on the page, with what the run found beside them.

The directory may come from anyone: the report reads only inside it. Every file it reads
(``summary.json``, ``index.json``, ``results.json``, ``stability.json``, the files
``summary.json`` lists, the charts beside them) is resolved and must lie under DIR: a listed
name that is absolute, climbs with ``..`` or is a symbolic link leaving DIR is refused, as is a
damaged file (JSON of the wrong shape, a CSV that is binary or not UTF-8, a chart that is not a
PNG), with one line naming the file and what is wrong.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
import math
from pathlib import Path

from formats.atomic import write_text_atomically
from formats.errors import InputError

# Rows of a CSV table shown in the page (the file keeps them all).
MAX_TABLE_ROWS = 300
# Significant digits of the non-integer numbers shown in tables (the files keep every digit).
TABLE_DIGITS = 4
# Columns of a ``recon compare`` results.csv shown, when present (the file has every score).
COMPARE_COLUMNS = ("label", "status", "failure", "wall_time_s", "peak_memory_mb", "n_faces",
                   "watertight", "chamfer_m", "fscore", "coverage", "edge_score", "reason")
# summary.json keys shown elsewhere in a study's section (not repeated in "more data").
_SHOWN = {"study", "title", "size", "claims", "files", "failures", "n_cases", "n_failed",
          "wall_time_s", "case_wall_time_s"}
VERDICT_COLOURS = {"reproduced": "#d9f2d9", "partly": "#fff2cc", "not reproduced": "#f8d7d7",
                   "not tested": "#e8e8e8"}
STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto;
       max-width: 1250px; color: #222; line-height: 1.4; padding: 0 1em; }
h1 { font-size: 1.6em; } h2 { border-bottom: 2px solid #ccc; padding-top: 1em; }
h3 { margin-top: 1.4em; }
table { border-collapse: collapse; font-size: 0.82em; margin: 0.5em 0 1em; }
th, td { border: 1px solid #ccc; padding: 3px 6px; vertical-align: top; text-align: left; }
th { background: #f0f0f0; position: sticky; top: 0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.scroll { overflow: auto; max-height: 32em; border: 1px solid #eee; }
img { max-width: 100%; border: 1px solid #ddd; margin: 0.5em 0; }
.meta { color: #555; font-size: 0.9em; }
nav ul { columns: 2; }
"""


# Column headers a reader knows, by key; other keys read as words with their unit in brackets
# (``header``).
HEADERS = {
    "wall_time_s": "wall time [s]", "process_time_s": "job time [s]",
    "load_time_s": "load time [s]", "score_time_s": "scoring time [s]",
    "case_wall_time_s": "worker time [s]", "peak_memory_mb": "peak memory [MB]",
    "n_faces": "faces", "n_points": "points", "n_cases": "cases", "n_failed": "failed",
    "watertight": "watertight", "chamfer_m": "Chamfer distance [m]", "fscore": "F-score",
    "edge_score": "edge score", "coverage": "coverage", "tau_m": "τ [m]",
    "accuracy_mean_m": "accuracy, mean [m]", "completeness_mean_m": "completeness, mean [m]",
    "hausdorff_m": "Hausdorff distance [m]", "noise_sigma3_m": "range noise, 3 sigma [m]",
    "false_edge_rate": "false-edge rate", "missed_edge_rate": "missed-edge rate",
    "feature_missed_rate": "feature edges missed", "n_edge_points": "edge points",
}
# Unit suffixes of keys, and how a header shows them.
UNITS = (("_deg", "deg"), ("_mb", "MB"), ("_m", "m"), ("_s", "s"), ("_h", "h"))
# Levels of tables within tables in the summary's further data.
MAX_DEPTH = 3
# Table rows of the summary's further data (a list longer than this is cut, saying so).
MAX_DATA_ROWS = 60


def header(key: str) -> str:
    """A column header for ``key``: ``wall_time_s`` -> "wall time [s]"."""
    if key in HEADERS:
        return HEADERS[key]
    words, unit = key, ""
    for suffix, name in UNITS:
        if key.endswith(suffix) and len(key) > len(suffix):
            words, unit = key[: -len(suffix)], f" [{name}]"
            break
    if words.startswith("n_"):
        words = "number of " + words[2:]
    return words.replace("_", " ") + unit


def verdict_shown(verdict, size) -> tuple[str, str]:
    """The verdict the page shows and a note under it, by the page's rule: a reduced run
    (``size`` not ``full``) cannot refute a claim, so its "not reproduced" reads "not tested"
    (what it found in the note)."""
    verdict = str(verdict)
    if size != "full" and verdict == "not reproduced":
        return "not tested", "reduced run: not reproduced at this size"
    return verdict, ""


# The first bytes of every PNG file (the PNG specification, section 5.2).
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def member(directory: Path, name, source: Path) -> Path:
    """The file ``name`` that ``source`` lists, resolved, refused unless it lies under
    ``directory``.

    Parameters
    ----------
    directory : Path
        The report's input directory.
    name : str or Path
        Relative to ``directory`` (a name from a JSON file, or a path found in the directory).
    source : Path
        Where the name comes from, for the message.

    Returns
    -------
    Path
        Resolved (symbolic links followed); it may not exist.

    Raises
    ------
    InputError
        ``name`` is not a relative path under ``directory`` (absolute, with ``..``, or a
        symbolic link whose target leaves it).
    """
    if not isinstance(name, str | Path) or not str(name) or "\x00" in str(name):
        raise InputError(f"{source}: lists {str(name)[:80]!r}, not a file name")
    relative = Path(name)
    if relative.is_absolute() or ".." in relative.parts:
        raise InputError(f"{source}: lists {str(name)[:200]!r}, outside {directory} (the report "
                          "reads only files inside its directory)")
    root = directory.resolve()
    try:
        resolved = (directory / relative).resolve()
    except (OSError, RuntimeError) as exc:   # a symbolic-link loop
        raise InputError(f"{source}: lists {str(name)[:200]!r}, which cannot be resolved "
                          f"({exc})") from None
    if not resolved.is_relative_to(root):
        raise InputError(f"{source}: lists {str(name)[:200]!r}, a link to {resolved}, outside "
                          f"{directory} (the report reads only files inside its directory)")
    return resolved


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror or exc})") from None


def _read_text(path: Path) -> str:
    try:
        return _read_bytes(path).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {exc.start})") from None


def read_json(directory: Path, name: str) -> dict:
    """``directory/name`` (inside ``directory``), which must hold a JSON object."""
    path = member(directory, name, directory)
    try:
        value = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise InputError(f"{directory / name}: not valid JSON ({exc})") from None
    except RecursionError:
        raise InputError(f"{directory / name}: JSON nested too deeply") from None
    if not isinstance(value, dict):
        raise InputError(f"{directory / name}: holds a JSON {type(value).__name__}, not an "
                          "object")
    return value


def _field(data: dict, key: str, kind: type | tuple, default, source: Path):
    """``data[key]`` (``default`` when absent or null), refused unless of type ``kind``; a list
    of ``dict`` (``kind=(list, dict)``) has every item checked."""
    value = data.get(key)
    if value is None:
        return default
    outer, item = (kind if isinstance(kind, tuple) and kind[0] is list else (kind, None))
    if not isinstance(value, outer):
        raise InputError(f"{source}: {key!r} must be {_kinds[outer]}, got "
                          f"{type(value).__name__}")
    if item is not None and not all(isinstance(v, item) and not isinstance(v, bool)
                                    for v in value):
        raise InputError(f"{source}: every item of {key!r} must be {_kinds[item]}")
    return value


_kinds = {list: "a list", dict: "an object", str: "a string", (int, float): "a number"}
_NUMBER = (int, float)


def _e(value) -> str:
    return html.escape("" if value is None else str(value))


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _shown(value: str) -> str:
    """A table cell's text: non-integer numbers to ``TABLE_DIGITS`` significant digits."""
    if not _is_number(value) or value.lstrip("+-").isdigit():
        return value
    number = float(value)
    return value if not math.isfinite(number) else f"{number:.{TABLE_DIGITS}g}"


def png_title(raw: bytes) -> str:
    """The ``Title`` text of a PNG file (recon's charts carry their title there), or "": a
    ``tEXt`` (Latin-1) or uncompressed ``iTXt`` (UTF-8) chunk (PNG specification, 11.3.4)."""
    at = len(PNG_SIGNATURE)
    while at + 8 <= len(raw):
        length = int.from_bytes(raw[at:at + 4], "big")
        kind = raw[at + 4:at + 8]
        keyword, _, text = raw[at + 8:at + 8 + length].partition(b"\x00")
        if kind == b"tEXt" and keyword == b"Title":
            return text.decode("latin-1").strip()
        if kind == b"iTXt" and keyword == b"Title" and text[:1] == b"\x00":  # uncompressed
            return text[2:].split(b"\x00", 2)[-1].decode("utf-8", "replace").strip()
        if kind in (b"IDAT", b"IEND"):   # text chunks of interest come before the image data
            return ""
        at += 12 + length
    return ""


def image(path: Path, alt: str) -> str:
    """An ``<img>`` with the PNG embedded as a data URI (refused unless it is a PNG); its alt
    text is the chart's own title when the file carries one, else ``alt``."""
    raw = _read_bytes(path)
    if not raw.startswith(PNG_SIGNATURE):
        raise InputError(f"{path}: not a PNG image")
    data = base64.b64encode(raw).decode("ascii")
    text = " ".join((png_title(raw) or alt).split())
    return f'<img alt="{_e(text)}" src="data:image/png;base64,{data}">'


def csv_table(path: Path, *, columns: tuple[str, ...] | None = None,
              max_rows: int = MAX_TABLE_ROWS) -> str:
    """A CSV file as an HTML table (at most ``max_rows`` rows; ``columns``: a subset).

    Raises
    ------
    InputError
        Not UTF-8 text, or not a CSV table (NUL bytes, a field over csv's size limit).
    """
    text = _read_text(path)
    if "\x00" in text:
        raise InputError(f"{path}: not a readable CSV table (binary: it holds NUL bytes)")
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise InputError(f"{path}: not a readable CSV table ({exc})") from None
    if not rows:
        return f"<p class=meta>{_e(path.name)} is empty.</p>"
    names, body = rows[0], rows[1:]
    keep = list(range(len(names)))
    if columns:
        keep = [i for i, name in enumerate(names) if name in columns] or keep
    parts = ["<div class=scroll><table><tr>"
             + "".join(f"<th title=\"{_e(names[i])}\">{_e(header(names[i]))}</th>"
                      for i in keep) + "</tr>"]
    for row in body[:max_rows]:
        cells = []
        for i in keep:
            value = row[i] if i < len(row) else ""
            cls = " class=num" if value and _is_number(value) else ""
            cells.append(f"<td{cls}>{_e(_shown(value))}</td>")
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</table></div>")
    if len(body) > max_rows:
        parts.append(f"<p class=meta>First {max_rows} of {len(body)} rows; all of them are in "
                     f"{_e(path.name)}.</p>")
    return "".join(parts)


def claims_table(claims: list[dict], size="full") -> str:
    """The paper's claims with our numbers and the verdict (``verdict_shown``: by the run's
    ``size``), coloured by verdict."""
    if not claims:
        return "<p class=meta>No claims checked.</p>"
    parts = ["<table><tr><th>figure</th><th>claim of the paper</th><th>paper</th>"
             "<th>ours</th><th>verdict</th><th>rule</th></tr>"]
    for c in claims:
        verdict, note = verdict_shown(c.get("verdict"), size)
        colour = VERDICT_COLOURS.get(verdict, "#fff")
        note = f"<br><span class=meta>{_e(note)}</span>" if note else ""
        parts.append(f"<tr><td>{_e(c.get('figure'))}</td><td>{_e(c.get('claim'))}</td>"
                     f"<td>{_e(c.get('paper'))}</td><td>{_e(c.get('ours'))}</td>"
                     f"<td style=\"background:{colour}\"><b>{_e(verdict)}</b>{note}</td>"
                     f"<td class=meta>{_e(c.get('rule'))}</td></tr>")
    parts.append("</table>")
    return "".join(parts)


def _seconds(value, spec: str) -> str:
    """A number of seconds formatted with ``spec``; "" when it is not a finite number."""
    ok = isinstance(value, _NUMBER) and not isinstance(value, bool) and math.isfinite(value)
    return format(value, spec) if ok else ""


def _charts(directory: Path) -> list[Path]:
    """The PNG files directly in ``directory``, resolved; one that is a link leaving it is
    refused."""
    found = (member(directory, p.name, directory) for p in directory.glob("*.png"))
    return sorted(p for p in found if p.is_file())


def _anchor(text: str) -> str:
    return "".join(ch if ch.isalnum() else "-" for ch in text.lower())


def _value_text(value) -> str:
    """A JSON value as table text: non-integer numbers to ``TABLE_DIGITS`` significant
    digits, lists of scalars joined by commas, anything else as compact rounded JSON."""
    if isinstance(value, bool) or value is None:
        return "" if value is None else str(value).lower()
    if isinstance(value, float):
        return f"{value:.{TABLE_DIGITS}g}" if math.isfinite(value) else str(value)
    if isinstance(value, int | str):
        return str(value)
    if isinstance(value, list) and all(not isinstance(v, list | dict) for v in value):
        return ", ".join(_value_text(v) for v in value)
    if isinstance(value, dict) and all(not isinstance(v, list | dict) for v in value.values()):
        return "; ".join(f"{header(k)}: {_value_text(v)}" for k, v in value.items())
    try:
        return json.dumps(_rounded(value), ensure_ascii=False)
    except RecursionError:
        return "(nested too deeply to show; see the file)"


def _rounded(value):
    """``value`` with every float rounded to ``TABLE_DIGITS`` significant digits."""
    if isinstance(value, float) and math.isfinite(value):
        return float(f"{value:.{TABLE_DIGITS}g}")
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    return value


def _cell(value) -> str:
    number = isinstance(value, int | float) and not isinstance(value, bool)
    return f"<td{' class=num' if number else ''}>{_e(_value_text(value))}</td>"


def _records_table(rows: list) -> str:
    """A list of JSON objects as one table, a column per key (at most ``MAX_DATA_ROWS``)."""
    columns = list(dict.fromkeys(k for row in rows for k in row))
    parts = ["<div class=scroll><table><tr>" + "".join(
        f"<th title=\"{_e(k)}\">{_e(header(k))}</th>" for k in columns) + "</tr>"]
    for row in rows[:MAX_DATA_ROWS]:
        parts.append("<tr>" + "".join(_cell(row.get(k)) for k in columns) + "</tr>")
    parts.append("</table></div>")
    if len(rows) > MAX_DATA_ROWS:
        parts.append(f"<p class=meta>First {MAX_DATA_ROWS} of {len(rows)} rows.</p>")
    return "".join(parts)


def data_table(data: dict, depth: int = 0) -> str:
    """A JSON object as a readable table: a row per key with its value (numbers to
    ``TABLE_DIGITS`` significant digits); a list of objects or an object of objects becomes a
    table of its own under the key's name, an object holding more a table in its cell (to
    ``MAX_DEPTH`` levels; deeper, compact JSON)."""
    simple, nested = [], []
    for key, value in data.items():
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            nested.append((key, _records_table(value)))
        elif isinstance(value, dict) and value and all(isinstance(v, dict)
                                                        for v in value.values()):
            nested.append((key, _records_table([{"": k, **v} for k, v in value.items()])))
        else:
            cell = (f"<td>{data_table(value, depth + 1)}</td>" if depth < MAX_DEPTH
                    and isinstance(value, dict)
                    and any(isinstance(v, dict | list) for v in value.values())
                    else _cell(value))
            simple.append(f"<tr><th title=\"{_e(key)}\">{_e(header(key))}</th>{cell}</tr>")
    parts = [f"<table>{''.join(simple)}</table>"] if simple else []
    parts += [f"<p><b>{_e(header(key))}</b></p>{table}" for key, table in nested]
    return "".join(parts)


def _study_meta(summary: dict, name: str, directory: Path) -> str:
    wall = _seconds(summary.get("wall_time_s"), ".0f")
    work = _seconds(summary.get("case_wall_time_s"), ".0f")
    text = (f"<p class=meta>study <b>{_e(name)}</b>, size <b>{_e(summary.get('size'))}</b>"
            f", {_e(summary.get('n_cases'))} cases ({_e(summary.get('n_failed'))} failed)"
            + (f"; last run {wall} s" if wall else "")
            + (f" (cases: {work} s of worker time, resumed ones included)" if work else "")
            + f"; directory {_e(directory)}</p>")
    if summary.get("size") != "full":
        text += ("<p class=meta>A reduced run (shorter runs than the paper's) cannot refute a "
                 "claim: a claim it does not reproduce, or cannot test, reads 'not tested', "
                 "with what it found beside it; see the full run for the verdicts.</p>")
    return text


def _chart_images(directory: Path, files: list[Path], what: str, level: int) -> list[str]:
    """The charts ``files`` lists, then the other PNG files of ``directory``, embedded."""
    root = directory.resolve()
    pngs = [f for f in files if f.suffix == ".png" and f.is_file()]
    pngs += sorted(p for p in _charts(directory) if p not in pngs)
    if not pngs:
        return []
    return [f"<h{level}>Charts</h{level}>"] + [
        f"<p class=meta>{_e(png.relative_to(root))}</p>"
        + image(png, f"{what}: {png.stem.replace('_', ' ')}") for png in pngs]


def study_section(directory: Path, *, level: int = 2, heading: bool = True) -> str:
    """The section of one study directory (``summary.json`` and the files it lists); without
    its ``heading`` when the page's title already says it."""
    summary = read_json(directory, "summary.json")
    source = directory / "summary.json"
    claims = _field(summary, "claims", (list, dict), [], source)
    failures = _field(summary, "failures", (list, dict), [], source)
    listed = _field(summary, "files", (list, str), [], source)
    name = str(summary.get("study", directory.name))
    title = summary.get("title", name)
    parts = [f'<h{level} id="{_anchor(name)}">{_e(title)}</h{level}>'][:int(heading)]
    parts.append(_study_meta(summary, name, directory))
    parts.append(f"<h{level + 1}>Claims</h{level + 1}>"
                 + claims_table(claims, summary.get("size")))
    if failures:
        parts.append(f"<h{level + 1}>Failed cases</h{level + 1}><ul>" + "".join(
            f"<li>{_e(f.get('key'))}: {_e(f.get('reason'))}</li>" for f in failures)
            + "</ul>")
    files = [member(directory, f, source) for f in listed]
    parts += _chart_images(directory, files, f"chart of {title}", level + 1)
    for table in (f for f in files if f.suffix == ".csv" and f.is_file()):
        parts.append(f"<h{level + 1}>{_e(table.name)}</h{level + 1}>" + csv_table(table))
    more = {k: v for k, v in summary.items() if k not in _SHOWN}
    if more:
        parts.append(f"<details><summary>more data (summary.json)</summary>{data_table(more)}"
                     "</details>")
    return "\n".join(parts)


# Columns of ``recon stability``'s stability.csv shown (the file has every score).
STABILITY_COLUMNS = ("method", "noise_sigma3_m", "density", "outliers", "status", "failure",
                     "wall_time_s", "n_faces", "chamfer_m", "fscore", "coverage")


def stability_section(directory: Path, *, level: int = 2, heading: bool = True) -> str:
    """The section of a ``recon stability`` directory (``stability.json``, its maps and
    ``stability.csv``; ``heading``: as for ``study_section``)."""
    source = directory / "stability.json"
    data = read_json(directory, "stability.json")
    rates = _field(data, "failure_rate", dict, {}, source)
    parts = [f'<h{level} id="{_anchor(directory.name)}">Stability: '
             f"{_e(directory.name)}</h{level}>"][:int(heading)]
    grid = ", ".join(f"{header(k)}: {_value_text(data.get(k))}"
                     for k in ("noise_sigma3_m", "density", "outliers") if k in data)
    parts.append(f"<p class=meta>Grid: {_e(grid)}. A cell fails on a crash, a timeout, an "
                 "empty or degenerate mesh, or an accuracy collapse (Chamfer distance over "
                 f"{_e(_value_text(data.get('collapse_ratio')))} times the method's clean "
                 "cell's, plus the cell's noise).</p>")
    if rates:
        parts.append(f"<h{level + 1}>Failure rate per method</h{level + 1}>" + _records_table(
            [{"method": m, "failed cells": f"{r:.0%}" if isinstance(r, _NUMBER) else r}
             for m, r in rates.items()]))
    parts += _chart_images(directory, [], "stability map", level + 1)
    table = member(directory, "stability.csv", directory)
    if table.is_file():
        parts.append(f"<h{level + 1}>Every cell</h{level + 1}>"
                     + csv_table(table, columns=STABILITY_COLUMNS))
    return "\n".join(parts)


def compare_section(directory: Path, *, level: int = 2, heading: bool = True) -> str:
    """The section of a ``recon compare`` directory (``heading``: as for ``study_section``)."""
    parts = [f'<h{level} id="{_anchor(directory.name)}">Method comparison: '
             f"{_e(directory.name)}</h{level}>"][:int(heading)]
    results = read_json(directory, "results.json")
    for metric, name in (("chamfer", "Chamfer distance"), ("fscore", "F-score")):
        front = _field(results, f"pareto_{metric}", (list, dict), [],
                       directory / "results.json")
        if front:
            parts.append(f"<p><b>Pareto front (time against {name}):</b> " + ", ".join(
                f"{_e(r.get('label'))} ({_seconds(r.get('wall_time_s'), '.2g')} s)"
                for r in front) + "</p>")
    for png in _charts(directory):
        parts.append(image(png, f"speed against accuracy of the methods on {directory.name}"))
    table = member(directory, "results.csv", directory)
    if table.is_file():
        parts.append(f"<h{level + 1}>Runs, ranked by Chamfer</h{level + 1}>"
                     + csv_table(table, columns=COMPARE_COLUMNS))
    extra = {k: v for k, v in results.items() if k not in ("runs", "pareto_chamfer",
                                                           "pareto_fscore")}
    if extra:
        parts.append(f"<details><summary>input</summary>{data_table(extra)}</details>")
    return "\n".join(parts)


def index_section(directory: Path, studies: list[Path]) -> str:
    """The index of a ``recon study all`` directory: wall times and verdicts per study."""
    index_file = directory / "index.json"
    index = read_json(directory, "index.json") if index_file.is_file() else {}
    entries = _field(index, "studies", dict, {}, index_file)
    parts = ["<h2 id=index>Studies</h2><table><tr><th>study</th><th>title</th>"
             "<th>last run [s]</th><th>worker time [s]</th><th>cases (failed)</th>"
             "<th>verdicts</th></tr>"]
    for study in studies:
        summary = read_json(study, "summary.json")
        entry = entries.get(study.name)
        entry = entry if isinstance(entry, dict) else {}
        counts: dict[str, int] = {}
        for c in _field(summary, "claims", (list, dict), [], study / "summary.json"):
            verdict = verdict_shown(c.get("verdict"), summary.get("size"))[0]
            counts[verdict] = counts.get(verdict, 0) + 1
        wall = _seconds(summary.get("wall_time_s", entry.get("wall_time_s")), ".0f")
        work = _seconds(summary.get("case_wall_time_s"), ".0f")
        parts.append(f"<tr><td><a href=\"#{_anchor(summary.get('study', study.name))}\">"
                     f"{_e(study.name)}</a></td><td>{_e(summary.get('title'))}</td>"
                     f"<td class=num>{wall}</td><td class=num>{work}</td>"
                     f"<td class=num>{_e(summary.get('n_cases'))} "
                     f"({_e(summary.get('n_failed'))})</td><td>"
                     + ", ".join(f"{n} {_e(v)}" for v, n in sorted(counts.items()))
                     + "</td></tr>")
    parts.append("</table><p class=meta>Last run: wall time of the latest invocation (a resumed "
                 "run skips finished cases). Worker time: the cases' own time, summed over "
                 "workers, resumed cases included.</p>")
    if _seconds(index.get("wall_time_s"), ".0f"):
        parts.append(f"<p class=meta>All studies ({_e(index.get('size'))}): "
                     f"{_seconds(index['wall_time_s'], '.0f')} s in total.</p>")
    return "\n".join(parts)


def kind(directory: Path) -> str:
    """``study``, ``all``, ``compare`` or ``stability``.

    Raises
    ------
    InputError
        The directory holds none of them.
    """
    if not directory.is_dir():
        raise InputError(f"{directory}: " + ("is a file; give the directory a study or comparison "
                                             "wrote" if directory.exists() else
                                             "no such directory"))
    if (directory / "summary.json").is_file():
        return "study"
    if (directory / "index.json").is_file() or _study_dirs(directory):
        return "all"
    if (directory / "results.json").is_file():
        return "compare"
    if (directory / "stability.json").is_file():
        return "stability"
    raise InputError(f"{directory}: not a study or comparison directory, nor a stability "
                      "run (no summary.json, index.json, results.json or stability.json)")


def _study_dirs(directory: Path) -> list[Path]:
    from recon.experiments.studies import STUDIES

    found = [directory / n for n in STUDIES if (directory / n / "summary.json").is_file()]
    others = sorted(p.parent for p in directory.glob("*/summary.json")
                    if p.parent not in found)
    for study in found + others:   # a study directory that is a link leaving DIR is refused
        member(directory, study.name, directory)
    return found + others


def render(directory) -> str:
    """The whole HTML page of ``directory`` as text."""
    directory = Path(directory)
    what = kind(directory)
    body = []
    if what == "study":
        title = read_json(directory, "summary.json").get("title", "study")
        body.append(study_section(directory, level=1, heading=False))
    elif what == "compare":
        title = f"Method comparison: {directory.name}"
        body.append(compare_section(directory, level=1, heading=False))
    elif what == "stability":
        title = f"Stability: {directory.name}"
        body.append(stability_section(directory, level=1, heading=False))
    else:
        title = "Reproducing the paper's studies"
        studies = _study_dirs(directory)
        body.append(index_section(directory, studies))
        body.extend(study_section(s) for s in studies)
    return ("<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
            f"<meta name=viewport content=\"width=device-width, initial-scale=1\">"
            f"<title>{_e(title)}</title><style>{STYLE}</style></head><body>"
            f"<h1>{_e(title)}</h1><p class=meta>recon report of {_e(directory.resolve())}. "
            "Scores: edge score (our formalisation of the paper's edge metric, "
            "metrics/edges.py; lower is better), F-score and coverage at τ = 1 % of the "
            "truth's bounding-box diagonal (higher is better), Chamfer distance in metres "
            "(lower is better).</p>\n" + "\n".join(body) + "\n</body></html>\n")


def write_report(directory, output) -> Path:
    """Write the report of ``directory`` to ``output`` (an .html file); return its path.

    Raises
    ------
    InputError
        Bad input directory, or an output that is a directory or cannot be written.
    """
    output = Path(output)
    try:
        if output.is_dir():
            raise InputError(f"-o {output}: is a directory; give an .html file")
        inside = output.exists() and output.resolve().is_relative_to(Path(directory).resolve())
    except OSError as exc:   # a name too long, a loop of links
        shown = str(output) if len(str(output)) < 200 else f"{str(output)[:120]}..."
        raise InputError(f"-o {shown}: cannot be written ({exc.strerror or exc})") from None
    if inside and output.suffix.lower() not in (".html", ".htm"):
        raise InputError(f"-o {output}: is one of the files of {directory} the report reads; "
                          "give an .html file")
    text = render(directory)
    try:
        output.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"-o {output}: cannot create {output.parent} ({exc.strerror})") from None
    return write_text_atomically(output, text, error=InputError)
