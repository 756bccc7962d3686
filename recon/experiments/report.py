"""``recon report``: one self-contained HTML page of a study, of all studies, or of a comparison.

The page needs nothing but itself: charts are embedded as base64 ``data:`` URIs, the style is
inline, links point only inside the page. It shows, per study directory (``recon study``), the
paper's claims with our numbers and verdicts, the charts, the CSV tables and the rest of
``summary.json``; for ``recon study all`` the index of studies first; for a ``recon compare``
directory the ranked runs, the Pareto fronts and the speed-against-accuracy chart.

The directory may come from anyone: the report reads only inside it. Every file it reads
(``summary.json``, ``index.json``, ``results.json``, the files ``summary.json`` lists, the
charts beside them) is resolved and must lie under DIR: a listed name that is absolute, climbs
with ``..`` or is a symbolic link leaving DIR is refused, as is a damaged file (JSON of the
wrong shape, a CSV that is binary or not UTF-8, a chart that is not a PNG), with one line
naming the file and what is wrong.
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
from formats.errors import ReconError

# Rows of a CSV table shown in the page (the file keeps them all).
MAX_TABLE_ROWS = 300
# Significant digits of the non-integer numbers shown in tables (the files keep every digit).
TABLE_DIGITS = 4
# Columns of a ``recon compare`` results.csv shown, when present (the file has every score).
COMPARE_COLUMNS = ("label", "status", "failure", "wall_time_s", "peak_memory_mb", "n_faces",
                   "watertight", "chamfer_m", "fscore", "coverage", "edge_score", "reason")
# summary.json keys shown elsewhere in a study's section (not repeated in "more data").
_SHOWN = {"study", "title", "size", "claims", "files", "failures", "n_cases", "n_failed",
          "wall_time_s"}
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
pre { background: #f7f7f7; padding: 0.6em; overflow: auto; font-size: 0.8em; max-height: 30em; }
nav ul { columns: 2; }
"""


class ReportError(ReconError, ValueError):
    """The input is not a study or comparison directory, or the report cannot be written."""


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
    ReportError
        ``name`` is not a relative path under ``directory`` (absolute, with ``..``, or a
        symbolic link whose target leaves it).
    """
    if not isinstance(name, str | Path) or not str(name) or "\x00" in str(name):
        raise ReportError(f"{source}: lists {str(name)[:80]!r}, not a file name")
    relative = Path(name)
    if relative.is_absolute() or ".." in relative.parts:
        raise ReportError(f"{source}: lists {str(name)[:200]!r}, outside {directory} (the report "
                          "reads only files inside its directory)")
    root = directory.resolve()
    try:
        resolved = (directory / relative).resolve()
    except (OSError, RuntimeError) as exc:   # a symbolic-link loop
        raise ReportError(f"{source}: lists {str(name)[:200]!r}, which cannot be resolved "
                          f"({exc})") from None
    if not resolved.is_relative_to(root):
        raise ReportError(f"{source}: lists {str(name)[:200]!r}, a link to {resolved}, outside "
                          f"{directory} (the report reads only files inside its directory)")
    return resolved


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ReportError(f"{path}: cannot be read ({exc.strerror or exc})") from None


def _read_text(path: Path) -> str:
    try:
        return _read_bytes(path).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ReportError(f"{path}: not UTF-8 text (byte {exc.start})") from None


def read_json(directory: Path, name: str) -> dict:
    """``directory/name`` (inside ``directory``), which must hold a JSON object."""
    path = member(directory, name, directory)
    try:
        value = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise ReportError(f"{directory / name}: not valid JSON ({exc})") from None
    except RecursionError:
        raise ReportError(f"{directory / name}: JSON nested too deeply") from None
    if not isinstance(value, dict):
        raise ReportError(f"{directory / name}: holds a JSON {type(value).__name__}, not an "
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
        raise ReportError(f"{source}: {key!r} must be {_kinds[outer]}, got "
                          f"{type(value).__name__}")
    if item is not None and not all(isinstance(v, item) and not isinstance(v, bool)
                                    for v in value):
        raise ReportError(f"{source}: every item of {key!r} must be {_kinds[item]}")
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


def image(path: Path, alt: str) -> str:
    """An ``<img>`` with the PNG embedded as a data URI (refused unless it is a PNG)."""
    raw = _read_bytes(path)
    if not raw.startswith(PNG_SIGNATURE):
        raise ReportError(f"{path}: not a PNG image")
    data = base64.b64encode(raw).decode("ascii")
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{data}">'


def csv_table(path: Path, *, columns: tuple[str, ...] | None = None,
              max_rows: int = MAX_TABLE_ROWS) -> str:
    """A CSV file as an HTML table (at most ``max_rows`` rows; ``columns``: a subset).

    Raises
    ------
    ReportError
        Not UTF-8 text, or not a CSV table (NUL bytes, a field over csv's size limit).
    """
    text = _read_text(path)
    if "\x00" in text:
        raise ReportError(f"{path}: not a readable CSV table (binary: it holds NUL bytes)")
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise ReportError(f"{path}: not a readable CSV table ({exc})") from None
    if not rows:
        return f"<p class=meta>{_e(path.name)} is empty.</p>"
    header, body = rows[0], rows[1:]
    keep = list(range(len(header)))
    if columns:
        keep = [i for i, name in enumerate(header) if name in columns] or keep
    parts = ["<div class=scroll><table><tr>"
             + "".join(f"<th>{_e(header[i])}</th>" for i in keep) + "</tr>"]
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


def claims_table(claims: list[dict]) -> str:
    """The paper's claims with our numbers and the verdict, coloured by verdict."""
    if not claims:
        return "<p class=meta>No claims checked.</p>"
    parts = ["<table><tr><th>figure</th><th>claim of the paper</th><th>paper</th>"
             "<th>ours</th><th>verdict</th><th>rule</th></tr>"]
    for c in claims:
        colour = VERDICT_COLOURS.get(str(c.get("verdict")), "#fff")
        parts.append(f"<tr><td>{_e(c.get('figure'))}</td><td>{_e(c.get('claim'))}</td>"
                     f"<td>{_e(c.get('paper'))}</td><td>{_e(c.get('ours'))}</td>"
                     f"<td style=\"background:{colour}\"><b>{_e(c.get('verdict'))}</b></td>"
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


def study_section(directory: Path, *, level: int = 2, heading: bool = True) -> str:
    """The section of one study directory (``summary.json`` and the files it lists); without
    its ``heading`` when the page's title already says it."""
    summary = read_json(directory, "summary.json")
    source = directory / "summary.json"
    claims = _field(summary, "claims", (list, dict), [], source)
    failures = _field(summary, "failures", (list, dict), [], source)
    listed = _field(summary, "files", (list, str), [], source)
    name = str(summary.get("study", directory.name))
    parts = [f'<h{level} id="{_anchor(name)}">{_e(summary.get("title", name))}</h{level}>'
             ][:int(heading)]
    wall = _seconds(summary.get("wall_time_s"), ".0f")
    work = _seconds(summary.get("case_wall_time_s"), ".0f")
    parts.append(f"<p class=meta>study <b>{_e(name)}</b>, size <b>{_e(summary.get('size'))}</b>"
                 f", {_e(summary.get('n_cases'))} cases ({_e(summary.get('n_failed'))} failed)"
                 + (f"; last run {wall} s" if wall else "")
                 + (f" (cases: {work} s of worker time, resumed ones included)" if work else "")
                 + f"; directory {_e(directory)}</p>")
    if summary.get("size") != "full":
        parts.append("<p class=meta>A reduced run: claims it cannot test say 'not tested'; "
                     "see the full run for the verdicts.</p>")
    parts.append(f"<h{level + 1}>Claims</h{level + 1}>" + claims_table(claims))
    if failures:
        parts.append(f"<h{level + 1}>Failed cases</h{level + 1}><ul>" + "".join(
            f"<li>{_e(f.get('key'))}: {_e(f.get('reason'))}</li>" for f in failures)
            + "</ul>")
    root = directory.resolve()
    files = [member(directory, f, source) for f in listed]
    pngs = [f for f in files if f.suffix == ".png" and f.is_file()]
    pngs += sorted(p for p in _charts(directory) if p not in pngs)
    if pngs:
        parts.append(f"<h{level + 1}>Charts</h{level + 1}>")
        for png in pngs:
            parts.append(f"<p class=meta>{_e(png.relative_to(root))}</p>"
                         + image(png, png.stem))
    for table in (f for f in files if f.suffix == ".csv" and f.is_file()):
        parts.append(f"<h{level + 1}>{_e(table.name)}</h{level + 1}>" + csv_table(table))
    more = {k: v for k, v in summary.items() if k not in _SHOWN}
    if more:
        parts.append(f"<details><summary>more data (summary.json)</summary><pre>"
                     f"{_e(json.dumps(more, indent=1))}</pre></details>")
    return "\n".join(parts)


def compare_section(directory: Path, *, level: int = 2, heading: bool = True) -> str:
    """The section of a ``recon compare`` directory (``heading``: as for ``study_section``)."""
    parts = [f'<h{level} id="{_anchor(directory.name)}">Method comparison: '
             f"{_e(directory.name)}</h{level}>"][:int(heading)]
    results = read_json(directory, "results.json")
    for metric in ("chamfer", "fscore"):
        front = _field(results, f"pareto_{metric}", (list, dict), [],
                       directory / "results.json")
        if front:
            parts.append(f"<p><b>Pareto front (time against {metric}):</b> " + ", ".join(
                f"{_e(r.get('label'))} ({_seconds(r.get('wall_time_s'), '.2g')} s)"
                for r in front) + "</p>")
    for png in _charts(directory):
        parts.append(image(png, png.stem))
    table = member(directory, "results.csv", directory)
    if table.is_file():
        parts.append(f"<h{level + 1}>Runs, ranked by Chamfer</h{level + 1}>"
                     + csv_table(table, columns=COMPARE_COLUMNS))
    extra = {k: v for k, v in results.items() if k not in ("runs", "pareto_chamfer",
                                                           "pareto_fscore")}
    if extra:
        parts.append(f"<details><summary>input</summary><pre>{_e(json.dumps(extra, indent=1))}"
                     "</pre></details>")
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
            verdict = str(c.get("verdict"))
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
    """``study``, ``all`` or ``compare``.

    Raises
    ------
    ReportError
        The directory holds none of them.
    """
    if not directory.is_dir():
        raise ReportError(f"{directory}: no such directory")
    if (directory / "summary.json").is_file():
        return "study"
    if (directory / "index.json").is_file() or _study_dirs(directory):
        return "all"
    if (directory / "results.json").is_file():
        return "compare"
    raise ReportError(f"{directory}: not a study or comparison directory (no summary.json, "
                      "index.json or results.json)")


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
    ReportError
        Bad input directory, or an output that is a directory or cannot be written.
    """
    output = Path(output)
    try:
        if output.is_dir():
            raise ReportError(f"-o {output}: is a directory; give an .html file")
        inside = output.exists() and output.resolve().is_relative_to(Path(directory).resolve())
    except OSError as exc:   # a name too long, a loop of links
        shown = str(output) if len(str(output)) < 200 else f"{str(output)[:120]}..."
        raise ReportError(f"-o {shown}: cannot be written ({exc.strerror or exc})") from None
    if inside and output.suffix.lower() not in (".html", ".htm"):
        raise ReportError(f"-o {output}: is one of the files of {directory} the report reads; "
                          "give an .html file")
    text = render(directory)
    try:
        output.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ReportError(f"-o {output}: cannot create {output.parent} ({exc.strerror})") from None
    return write_text_atomically(output, text, error=ReportError)
