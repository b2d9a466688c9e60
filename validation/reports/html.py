"""One self-contained HTML page from a run folder (``flexcal report DIR``).

The page holds, in this order: report.md rendered (python-markdown, tables and fenced
code), every PNG of the folder embedded as base64 (so the page can be mailed or
archived alone): those report.md shows where it shows them, the others under "Figures",
each picture once; every figure of report.json as tables (scalars in one key/value table,
lists of records as tables, matrices as grids with the row and column names found beside
them, long vectors folded), and the list of the other files (VTU for ParaView, CSV
data). No scripts, no external resources, no time stamp: the same folder gives the same
bytes.

Every string from the folder is escaped: raw HTML in report.md is shown as text (a
scenario named ``<img src=x onerror=alert(1)>`` stays text), links and images whose
address has a scheme other than http(s)/mailto lose it. Tables wider than the page
scroll sideways.
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

__all__ = ["render_run_folder", "json_section", "RunFolderError"]

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
{% for f in files %}<tr><td><a href="./{{ f.href }}">{{ f.name }}</a></td><td>{{ f.size }}</td></tr>
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
    href: str  # percent-encoded relative address (a file named "javascript:..." stays a file)
    size: str


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


_SAFE_SCHEMES = ("http", "https", "mailto")


def _markdown_html(text: str) -> str:
    """report.md as HTML with raw HTML escaped (shown as text, never interpreted) and
    link/image addresses with a scheme other than http(s)/mailto removed."""
    import markdown
    from markdown.treeprocessors import Treeprocessor

    class SafeAddresses(Treeprocessor):
        def run(self, root):
            for element in root.iter():
                for attribute in ("href", "src"):
                    address = element.get(attribute)
                    if address is None:
                        continue
                    scheme = urllib.parse.urlsplit(address.strip()).scheme.lower()
                    if scheme and scheme not in _SAFE_SCHEMES:
                        element.set(attribute, "")

    md = markdown.Markdown(extensions=["tables", "fenced_code"])
    md.preprocessors.deregister("html_block")  # the documented way to escape raw HTML (Python-Markdown 3)
    md.inlinePatterns.deregister("html")
    md.treeprocessors.register(SafeAddresses(md), "flexcal_safe_addresses", 0)
    return md.convert(text)


def _embed_markdown_images(page: str, images: dict[str, str]) -> tuple[str, set[str]]:
    """<img src="x.png"> of the folder's PNGs -> data URIs; also the names embedded."""
    used: set[str] = set()

    def replace(match: re.Match) -> str:
        src = html.unescape(match.group(2))
        if src in images:
            used.add(src)
            return f'{match.group(1)}data:image/png;base64,{images[src]}{match.group(3)}'
        return match.group(0)

    return re.sub(r'(<img[^>]*?src=")([^"]+)(")', replace, page), used


def render_run_folder(folder: str | Path) -> str:
    """The HTML page of a run folder (str). ``FileNotFoundError`` if it does not exist,
    ``RunFolderError`` if it holds no report.json, report.md or PNG, ``ValueError`` for a
    report.json that is not valid JSON."""
    import jinja2

    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"run folder {folder} does not exist (give the --out folder of a flexcal run)")
    entries = sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith("."))
    md_path, json_path = folder / "report.md", folder / "report.json"
    pngs = [p for p in entries if p.suffix.lower() == ".png"]
    if not md_path.is_file() and not json_path.is_file() and not pngs:
        raise RunFolderError(f"{folder} holds no report.json, report.md or PNG: not a flexcal run folder")
    data = None
    if json_path.is_file():
        try:
            data = json.loads(json_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as error:
            raise ValueError(f"{json_path}: not valid JSON ({error})") from None
    encoded = {p.name: base64.b64encode(p.read_bytes()).decode("ascii") for p in pngs}
    md_html, title, shown = "", folder.resolve().name, set()
    if md_path.is_file():
        text = md_path.read_text()
        heading = re.search(r"^#\s+(.+)$", text, flags=re.MULTILINE)
        title = heading.group(1).strip() if heading else title
        md_html, shown = _embed_markdown_images(_markdown_html(text), encoded)
    if isinstance(data, dict):
        json_html = json_section(data)
    elif data is not None:
        json_html = json_section({"report": data})
    else:
        json_html = ""
    skip = {"report.md", "report.json", "report.html"} | set(encoded)
    files = [_File(p.name, urllib.parse.quote(p.name), f"{p.stat().st_size / 1e3:.1f}")
             for p in entries if p.name not in skip]
    template = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined).from_string(_PAGE)
    return template.render(title=title, css=_CSS, folder=folder.name, markdown=md_html,
                           images=[_Image(n, d) for n, d in encoded.items() if n not in shown], json_html=json_html,
                           files=files)
