"""One self-contained HTML page from a run folder (``flexcal report DIR``).

The page holds, in this order: report.md rendered (python-markdown, tables and fenced
code), every PNG of the folder embedded as base64 (so the page can be mailed or
archived alone): those report.md shows where it shows them, the others under "Figures",
each picture once; every figure of report.json as tables (scalars in one key/value table,
lists of records as tables, matrices as grids with the row and column names found beside
them, long vectors folded), and the list of the other files (VTU for ParaView, CSV
data). No scripts, no external resources, no time stamp: the same folder gives the same
bytes.

Safe to share: the page addresses nothing outside itself. Every string from the folder is
escaped (raw HTML in report.md is shown as text: a scenario named
``<img src=x onerror=alert(1)>`` stays text); report.md's links keep their text and lose
their address, and its images are kept only as the folder's own PNGs held in the page
(``safe_markdown.markdown_html``); the only ``src`` in the page is
``data:image/png;base64``, the only ``href`` the ``./NAME`` of a listed file beside it.
Only the folder's own regular files are read: a symbolic link is never followed (a
``x.png`` linked to ``/etc/passwd`` is listed, not read; a linked report.md or
report.json is an error), a PNG is embedded only when its first 8 bytes are the PNG
signature, a file with a second name (a hard link, which may be a file from anywhere) is
listed and not read, and a report.json nested deeper than ``MAX_JSON_DEPTH`` is refused before it
is parsed. Tables wider than the page scroll sideways.
"""

from __future__ import annotations

import base64
import html
import json
import math
import re
import urllib.parse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["render_run_folder", "json_section", "json_depth", "RunFolderError", "MAX_JSON_DEPTH", "PNG_SIGNATURE"]

MAX_TABLE_ROWS = 60      # longer lists of records / matrices are folded (<details>)
MAX_INLINE_VECTOR = 12   # numeric vectors up to this length are shown inline

_CSS = """
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; color: #1d2430;
       max-width: 1100px; margin: 2em auto; padding: 0 1.5em; }
h1 { border-bottom: 2px solid #2b6cb0; padding-bottom: .2em; }
h2 { margin-top: 1.8em; color: #2b4c7e; } h3 { margin-top: 1.3em; color: #35557f; }
table { border-collapse: collapse; margin: .6em 0 1.2em; font-size: 13px; display: block; max-width: 100%;
        overflow-x: auto; }
th, td { border: 1px solid #cfd6e0; padding: 3px 8px; text-align: right; }
th { background: #edf2f7; } td:first-child, th:first-child { text-align: left; }
code, pre { font-family: ui-monospace, Menlo, Consolas, monospace; font-size: 13px; }
pre { background: #f6f8fa; padding: .8em; overflow-x: auto; }
figure { margin: 1em 0 2em; } figure img { max-width: 100%; border: 1px solid #e2e8f0; }
figcaption { color: #4a5568; font-size: 13px; }
.meta { color: #4a5568; font-size: 13px; } table.kv td:last-child { text-align: left; } details { margin: .4em 0 1em; }
"""

_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{{ title }}</title>
<style>{{ css | safe }}</style>
</head>
<body>
<p class="meta">flexcal run folder <code>{{ folder }}</code></p>
{% if markdown %}{{ markdown | safe }}{% else %}<h1>{{ title }}</h1>{% endif %}
{% if images %}<h2>Figures</h2>
{% for image in images %}<figure id="{{ image.name }}"><img src="data:image/png;base64,{{ image.data }}" alt="{{ image.name }}">
<figcaption>{{ image.name }}</figcaption></figure>
{% endfor %}{% endif %}
{% if json_html %}<h2>All figures of report.json</h2>
{{ json_html | safe }}{% endif %}
{% if files %}<h2>Other files</h2>
<table><tr><th>file</th><th>size [kB]</th></tr>
{% for f in files %}<tr><td>{% if f.href %}<a href="./{{ f.href }}">{{ f.name }}</a>{% else %}{{ f.name }}{% endif %}\
{% if f.note %} ({{ f.note }}){% endif %}</td><td>{{ f.size }}</td></tr>
{% endfor %}</table>{% endif %}
</body>
</html>
"""


class RunFolderError(ValueError):
    """The folder is not a flexcal run folder (nothing to report)."""


@dataclass(frozen=True)
class _Image:
    name: str
    data: str


@dataclass(frozen=True)
class _File:
    name: str
    href: str  # percent-encoded relative address (a file named "javascript:..." stays a file); "": no link
    size: str
    note: str = ""


def _number(value: float) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if not math.isfinite(value):
        return str(value)
    return f"{value:.6g}"


def _cell(value: Any) -> str:
    if value is None:
        return "—"
    if isinstance(value, (bool, int, float)):
        return _number(value)
    if isinstance(value, str):
        return html.escape(value)
    if isinstance(value, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        return _vector(value)
    return f"<code>{html.escape(json.dumps(value, sort_keys=True))}</code>"


def _vector(values: list) -> str:
    text = ", ".join(_number(v) for v in values)
    if len(values) <= MAX_INLINE_VECTOR:
        return f"[{text}]"
    return f"<details><summary>{len(values)} values</summary><code>[{text}]</code></details>"


def _is_matrix(value: Any) -> bool:
    return (isinstance(value, list) and len(value) > 0 and all(isinstance(r, list) for r in value)
            and len({len(r) for r in value}) == 1 and len(value[0]) > 0
            and all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)) for r in value for v in r))


def _is_records(value: Any) -> bool:
    return isinstance(value, list) and len(value) > 0 and all(isinstance(r, dict) for r in value)


def _fold(rows_html: list[str], header: str, n_rows: int) -> str:
    table = f"<table>{header}{''.join(rows_html)}</table>"
    if n_rows <= MAX_TABLE_ROWS:
        return table
    return f"<details><summary>{n_rows} rows</summary>{table}</details>"


# sibling keys whose list of strings names the columns / rows of a matrix beside them
_COLUMN_KEYS = ("names", "parameter_names", "parameters", "columns")
_ROW_KEYS = ("outputs", "rows", "channels")


def _labels(siblings: dict[str, Any], n: int, preferred: tuple[str, ...], avoid: str | None = None) -> list[str] | None:
    """Names for n rows or columns: a sibling list of n strings, preferred keys first."""
    candidates = [k for k in preferred if k in siblings] + [k for k in siblings if k not in preferred]
    for key in candidates:
        value = siblings[key]
        if (key != avoid and isinstance(value, list) and len(value) == n
                and all(isinstance(v, str) for v in value)):
            return value
    return None


def _matrix(value: list[list], siblings: dict[str, Any] | None = None) -> str:
    n_rows, n_cols = len(value), len(value[0])
    siblings = siblings or {}
    columns = _labels(siblings, n_cols, _COLUMN_KEYS)
    column_key = next((k for k, v in siblings.items() if v is columns), None)
    rows_names = _labels(siblings, n_rows, _ROW_KEYS, avoid=column_key if n_rows != n_cols else None)
    columns = columns or [str(j) for j in range(n_cols)]
    rows_names = rows_names or [str(i) for i in range(n_rows)]
    header = "<tr><th></th>" + "".join(f"<th>{html.escape(c)}</th>" for c in columns) + "</tr>"
    rows = [f"<tr><th>{html.escape(name)}</th>" + "".join(f"<td>{_cell(v)}</td>" for v in row) + "</tr>"
            for name, row in zip(rows_names, value)]
    return _fold(rows, header, n_rows)


def _records(value: list[dict]) -> str:
    columns = list(dict.fromkeys(k for r in value for k in r))
    header = "<tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in columns) + "</tr>"
    rows = ["<tr>" + "".join(f"<td>{_cell(r.get(c))}</td>" for c in columns) + "</tr>" for r in value]
    return _fold(rows, header, len(value))


def json_section(data: dict[str, Any], level: int = 3, path: str = "") -> str:
    """HTML tables of a JSON object: its scalars and short vectors in one key/value table,
    then one sub-section per table-like entry (records, matrices, nested objects)."""
    simple, complex_ = [], []
    for key, value in data.items():
        if isinstance(value, dict) or _is_matrix(value) or _is_records(value):
            complex_.append((key, value))
        else:
            simple.append((key, value))
    parts = []
    if simple:
        parts.append("<table class=\"kv\"><tr><th>figure</th><th>value</th></tr>" + "".join(
            f"<tr><td><code>{html.escape(path + k)}</code></td><td>{_cell(v)}</td></tr>" for k, v in simple)
            + "</table>")
    h = f"h{min(level, 6)}"
    for key, value in complex_:
        name = html.escape(path + key)
        if isinstance(value, dict):
            body = json_section(value, level + 1, f"{path}{key}.") if value else "<p>(empty)</p>"
        elif _is_matrix(value):
            body = _matrix(value, data)
        else:
            body = _records(value)
        parts.append(f"<{h}><code>{name}</code></{h}>{body}")
    return "\n".join(parts)


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"  # the first 8 bytes of every PNG file (PNG spec, section 5.2)
# report.json nested deeper than this is refused before parsing: the run folders on the
# development machine nest at most 7 levels, and a few thousand levels exhaust the
# recursion of json.loads and of the tables below (exit 1, before this check)
MAX_JSON_DEPTH = 64


def _own_file_bytes(path: Path) -> bytes | None:
    """The bytes of ``path`` if it is a regular file of its folder (not a symbolic link,
    FIFO or device; its resolved path inside the folder; one name only: a hard link may be
    a file from anywhere else), else None."""
    import os
    import stat

    if path.resolve().parent != path.parent.resolve():
        return None
    try:  # O_NOFOLLOW: a link swapped in after the check is refused too; O_NONBLOCK: a FIFO never blocks
        handle = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    with os.fdopen(handle, "rb") as stream:
        status = os.fstat(stream.fileno())
        if not stat.S_ISREG(status.st_mode) or status.st_nlink > 1:
            return None
        return stream.read()


def _report_text(path: Path) -> str | None:
    """report.md / report.json of the folder as text, None if absent; ``ValueError`` if it
    is a symbolic link or not a regular file (its target is never read)."""
    if not path.is_symlink() and not path.exists():
        return None
    data = _own_file_bytes(path)
    if data is None:
        raise ValueError(f"{path} is a symbolic link, a hard link or not a regular file; flexcal report reads only "
                         "the run folder's own files (copy the file in)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ValueError(f"{path}: not UTF-8 text ({error})") from None


def json_depth(text: str) -> int:
    """How deeply arrays and objects nest in the JSON ``text`` (0 for a scalar), counted
    without parsing or recursion (brackets inside strings do not count): the brackets with
    an even number of unescaped quotes before them, summed +1 / -1 in one vectorized pass."""
    import numpy as np

    code = np.frombuffer(text.replace("\\\\", "").replace('\\"', "").encode(), np.uint8)
    quotes = np.flatnonzero(code == ord('"'))
    brackets = np.flatnonzero(np.isin(code, np.frombuffer(b"[]{}", np.uint8)))
    brackets = brackets[np.searchsorted(quotes, brackets) % 2 == 0]
    steps = np.where(np.isin(code[brackets], np.frombuffer(b"[{", np.uint8)), 1, -1)
    return int(max(np.cumsum(steps).max(initial=0), 0))


def _read_report_json(path: Path) -> Any:
    """report.json parsed, None if absent; ``ValueError`` (one line) if it cannot be read
    as JSON nested at most ``MAX_JSON_DEPTH`` deep."""
    text = _report_text(path)
    if text is None:
        return None
    depth = json_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise ValueError(f"{path}: nested {depth} levels deep; flexcal report reads at most {MAX_JSON_DEPTH}: "
                         "not a flexcal report.json")
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not valid JSON ({error})") from None


def _folder_files(folder: Path) -> tuple[dict[str, str], list[_File]]:
    """(name -> base64 of each PNG to embed, the other files to list). Embedded: regular
    files named *.png that start with the PNG signature; symbolic links are listed without
    a link or a size and never read."""
    pictures, files = {}, []
    for path in sorted(p for p in folder.iterdir() if not p.name.startswith(".")):
        if path.name in ("report.md", "report.json", "report.html") or (path.is_dir() and not path.is_symlink()):
            continue
        if path.is_symlink():
            files.append(_File(path.name, "", "—", "symbolic link, not read"))
            continue
        is_png = path.suffix.lower() == ".png"
        data = _own_file_bytes(path) if is_png else None
        if is_png and data is not None and data.startswith(PNG_SIGNATURE):
            pictures[path.name] = base64.b64encode(data).decode("ascii")
        elif path.is_file():
            hard_link = is_png and path.stat().st_nlink > 1
            note = "hard link, not read" if hard_link else "not a PNG image, not embedded" if is_png else ""
            files.append(_File(path.name, urllib.parse.quote(path.name), f"{path.stat().st_size / 1e3:.1f}", note))
    return pictures, files


def _heading_text(page_html: str) -> str | None:
    """The plain text of the first <h1> of rendered HTML, or None."""
    match = re.search(r"<h1>(.*?)</h1>", page_html, flags=re.DOTALL)
    return html.unescape(re.sub(r"<[^>]+>", "", match.group(1))).strip() if match else None


def render_run_folder(folder: str | Path) -> str:
    """The HTML page of a run folder (str). ``FileNotFoundError`` if it does not exist,
    ``RunFolderError`` if it holds no report.json, report.md or PNG, ``ValueError`` for a
    report.json that is not valid JSON or nests deeper than ``MAX_JSON_DEPTH``, and for a
    report.md / report.json that is a symbolic link."""
    import jinja2

    from .safe_markdown import markdown_html

    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"run folder {folder} does not exist (give the --out folder of a flexcal run)")
    md_path, json_path = folder / "report.md", folder / "report.json"
    named_png = any(p.suffix.lower() == ".png" and not p.name.startswith(".") for p in folder.iterdir())
    if not any(p.is_symlink() or p.exists() for p in (md_path, json_path)) and not named_png:
        raise RunFolderError(f"{folder} holds no report.json, report.md or PNG: not a flexcal run folder")
    data = _read_report_json(json_path)
    md_text = _report_text(md_path)
    pictures, files = _folder_files(folder)
    md_html, title, shown = "", folder.resolve().name, set()
    if md_text is not None:
        md_html, shown = markdown_html(md_text, pictures)
        title = _heading_text(md_html) or title
    if isinstance(data, dict):
        json_html = json_section(data)
    elif data is not None:
        json_html = json_section({"report": data})
    else:
        json_html = ""
    template = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined).from_string(_PAGE)
    return template.render(title=title, css=_CSS, folder=folder.name, markdown=md_html,
                           images=[_Image(n, d) for n, d in pictures.items() if n not in shown], json_html=json_html,
                           files=files)
