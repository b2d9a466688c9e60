"""``flexcal report DIR``: one self-contained HTML page from a run folder."""

import base64
import html
import json
import os
import re
import subprocess
import sys
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flexcal.fem.owners import host_hash, process_state
from flexcal.validation import cli
from flexcal.validation.out_lock import LOCK_NAME
from flexcal.validation.reports.html import json_depth, render_run_folder
from flexcal.validation.reports.safe_markdown import markdown_html, md_text

# the smallest valid PNG (1 x 1 pixel), so the test needs no plotting library
PNG = base64.b64decode("iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNk+M9QDwADhgGAWjR9awAAAABJRU5ErkJggg==")


@pytest.fixture
def run_folder(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "report.md").write_text("# Hinge check\n\nSome *text*.\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n"
                                      "![the fit](fit.png)\n")
    (folder / "report.json").write_text(json.dumps({
        "fit_rms_urad": 0.0123456789, "kind": "hinge", "ok": True, "missing": None,
        "theta_urad": [1.0, 2.0, 3.0],
        "compliance": [[1.0, 2.0], [3.0, None]],
        "parameters": [{"name": "D1.CL", "identified": 0.42}, {"name": "D1.mu", "identified": 0.83}],
        "mesh": {"n_nodes": 120, "quality": {"min": 0.3}},
        "long": list(range(100)),
    }))
    (folder / "fit.png").write_bytes(PNG)
    (folder / "extra.png").write_bytes(PNG)
    (folder / "hinge.vtu").write_text("<VTKFile/>")
    return folder


def test_page_is_self_contained_and_complete(run_folder):
    page = render_run_folder(run_folder)
    assert "<title>Hinge check</title>" in page
    assert "<table>" in page and "<td>1</td>" in page               # the markdown table
    assert 'src="fit.png"' not in page                              # markdown image embedded ...
    assert page.count("data:image/png;base64,") == 2                # ... and only the other PNG in the gallery
    assert page.count('alt="fit.png"') == 0 and page.count('alt="extra.png"') == 1  # each picture once
    assert base64.b64encode(PNG).decode() in page
    assert not re.search(r"<script|<link|src=\"https?:|url\(", page)  # nothing fetched from elsewhere
    assert "0.0123457" in page                                      # scalars at 6 significant digits
    assert "D1.CL" in page and "0.83" in page                       # records as a table
    # nested tables: a heading per level, each leaf under its full dotted name with its value
    assert "<h3><code>mesh</code></h3>" in page and "<h4><code>mesh.quality</code></h4>" in page
    assert "<td><code>mesh.n_nodes</code></td><td>120</td>" in page
    assert "<td><code>mesh.quality.min</code></td><td>0.3</td>" in page
    assert "100 values" in page                                     # long vectors folded
    assert '<a href="./hinge.vtu">hinge.vtu</a>' in page            # other files listed


def test_same_folder_same_bytes(run_folder):
    assert render_run_folder(run_folder) == render_run_folder(run_folder)


def test_report_command_writes_report_html(run_folder, capsys):
    assert cli.main(["report", str(run_folder)]) == 0
    page = (run_folder / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and "Hinge check" in page
    assert "report.html" in capsys.readouterr().out
    # a second run does not list its own previous page as an 'other file'
    assert cli.main(["report", str(run_folder)]) == 0
    assert 'href="report.html"' not in (run_folder / "report.html").read_text()


def test_report_of_a_real_forward_run(tmp_path):
    out = tmp_path / "fw"
    assert cli.main(["forward", "--inputs-mm", "0.5,0,0", "--out", str(out), "-q"]) == 0
    assert cli.main(["report", str(out), "--html", str(tmp_path / "page.html"), "-q"]) == 0
    page = (tmp_path / "page.html").read_text()
    assert "point_class" in page and "theta_urad" in page


@pytest.mark.parametrize("setup, words", [
    (lambda d: None, ["does not exist"]),
    (lambda d: d.mkdir(), ["not a flexcal run folder"]),
    (lambda d: (d.mkdir(), (d / "report.json").write_text("{oops")), ["report.json", "not valid JSON"]),
], ids=["missing", "empty", "bad-json"])
def test_report_bad_folder(tmp_path, capsys, setup, words):
    folder = tmp_path / "run"
    setup(folder)
    assert cli.main(["report", str(folder)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words)
    assert not (folder / "report.html").exists()


# --- safe to share (issue 23): nothing from the folder's data becomes an address ---------

def _addresses(page):
    """Every src= and href= value of the page."""
    return re.findall(r'\b(?:src|href)\s*=\s*"([^"]*)"', page, flags=re.IGNORECASE)


def assert_addresses_nothing(page, listed=()):
    """The only src is an embedded PNG, the only href a ./NAME of a listed file; no URL."""
    for address in _addresses(page):
        assert address.startswith("data:image/png;base64,") or address in {f"./{n}" for n in listed}, address
    assert not re.search(r"<img(?![^>]*src=\"data:image/png;base64,)", page)  # no <img> without an embedded PNG
    assert not re.search(r"<a\b(?![^>]*href=\"\./)", page)                     # no <a> but the file list's
    assert not re.search(r"<script|<link|<iframe|<object|<embed|url\(|@import", page, flags=re.IGNORECASE)


SECRET = "root:x:0:0:root:/root:/bin/bash\n"


@pytest.mark.parametrize("target", ["text", "png"], ids=["link-to-a-text-file", "link-to-a-png-outside"])
def test_symlinked_png_is_not_embedded(run_folder, tmp_path, target):
    outside = tmp_path / "outside"
    outside.write_bytes(SECRET.encode() if target == "text" else PNG + b"outside")  # PNG bytes no folder file has
    (run_folder / "secret.png").symlink_to(outside)
    page = render_run_folder(run_folder)
    assert base64.b64encode(outside.read_bytes()).decode() not in page
    assert page.count("data:image/png;base64,") == 2                     # fit.png and extra.png only
    assert "secret.png (symbolic link, not read)" in page                 # listed, without a link or a size
    assert_addresses_nothing(page, listed=["hinge.vtu"])


def test_png_named_file_that_is_no_png_is_not_embedded(run_folder):
    (run_folder / "notes.png").write_text(SECRET)
    page = render_run_folder(run_folder)
    assert base64.b64encode(SECRET.encode()).decode() not in page
    assert page.count("data:image/png;base64,") == 2
    assert '<a href="./notes.png">notes.png</a> (not a PNG image, not embedded)' in page


def test_symlinked_report_md_is_refused(tmp_path, capsys):
    folder = tmp_path / "run"
    folder.mkdir()
    (tmp_path / "secret.txt").write_text(SECRET)
    (folder / "report.md").symlink_to(tmp_path / "secret.txt")
    assert cli.main(["report", str(folder)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "symbolic link" in err[0]
    assert not (folder / "report.html").exists()


EVIL_NAME = "![x](http://example.com/a.png) [click](example.com) <img src=x onerror=alert(1)>"


def test_markdown_in_a_scenario_name_shows_as_text(tmp_path):
    """The real writer (truth) and the real page: the name reads as typed, no address."""
    scenario = tmp_path / "evil.toml"
    scenario.write_text(f'name = "{EVIL_NAME}"\nseed = 1\n')
    out = tmp_path / "run"
    assert cli.main(["truth", "--scenario", str(scenario), "--provider", "analytic", "--out", str(out), "-q"]) == 0
    assert cli.main(["report", str(out), "-q"]) == 0
    page = (out / "report.html").read_text()
    shown = html.escape(EVIL_NAME, quote=False)
    assert f"<h1>Virtual prototype: scenario {shown} (seed 1)</h1>" in page
    assert f"<title>Virtual prototype: scenario {shown} (seed 1)</title>" in page
    assert_addresses_nothing(page, listed=["curves.csv", "curves.json", "timings.json"])


@pytest.mark.parametrize("markdown_text", [
    "![x](http://example.com/a.png)", "[click](example.com)", "[c](//example.com/x)", "<http://example.com>",
    "<someone@example.com>", "[ref][r]\n\n[r]: https://example.com", "![ref][i]\n\n[i]: https://example.com/a.png",
    "[j](javascript:alert(1))", "![x](fit.png \"t\") ![y](../run/fit.png) ![z](./fit.png)",
])
def test_report_md_written_without_escaping_still_addresses_nothing(run_folder, markdown_text):
    """A writer that forgot md_text: links keep their text only, images other than the
    folder's own PNGs become their alt text."""
    (run_folder / "report.md").write_text(f"# Title\n\n{markdown_text}\n")
    page = render_run_folder(run_folder)
    assert_addresses_nothing(page, listed=["hinge.vtu"])


@given(st.text(st.characters(blacklist_categories=("Cc", "Cs")), max_size=60)
       | st.sampled_from([EVIL_NAME, "[a](b)", "<b@c.d>", "*a*", "_a_", "`a`", "# a", "1. a", "- a", "a|b", "&amp;"]))
@settings(max_examples=300, deadline=None)  # python-markdown takes ~1 ms a call
def test_md_text_reads_back_as_the_same_text(value):
    """Whatever printable text a data string holds, the rendered Markdown shows it as
    typed (whitespace runs as one space): no syntax, no element, no address."""
    rendered, placed = markdown_html(f"| a |\n|---|\n| {md_text(value)} |\n\n- {md_text(value)}\n", {"x.png": "AA=="})
    expected = html.escape(" ".join(value.split()), quote=False)
    assert f"<td>{expected}</td>" in rendered and f"<li>{expected}</li>" in rendered
    assert not placed and "<img" not in rendered and "<a" not in rendered


def test_md_text_drops_control_characters():
    # python-markdown uses STX/ETX as its own placeholders; no control character belongs in a report
    assert md_text("a\x02b\x03c\x00d\x1be\x7f") == "abcde"
    assert md_text(" a\n\n# b\tc ") == "a # b c"  # one line: a "#" inside it starts no heading
    assert md_text("# b") == "\\# b"


def test_too_deep_report_json_is_one_line_and_exit_2(tmp_path):
    """The real command in its own process: 10 000 nested arrays were exit 1 (RecursionError)."""
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "report.json").write_text("[" * 10_000 + "]" * 10_000)
    done = subprocess.run([sys.executable, "-m", "flexcal.validation.cli", "report", str(folder)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "report.json" in lines[0] and "nested 10000 levels deep" in lines[0]
    assert not (folder / "report.html").exists()


def test_json_depth_counts_outside_strings():
    assert json_depth('{"a": [1, {"b": "[[[{{{"}], "c": "\\"]]"}') == 3
    assert json_depth("3") == 0
    data = {"a": {"b": [[1, 2], [3, 4]]}}
    assert json_depth(json.dumps(data)) == 4


def _parsed_depth(value) -> int:
    if isinstance(value, dict):
        return 1 + max((_parsed_depth(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_parsed_depth(v) for v in value), default=0)
    return 0


_JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.text(alphabet='[]{}"\\ab'),
                     lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(alphabet='[]{}"\\a'), inner,
                                                                                 max_size=4), max_leaves=30)


@settings(max_examples=300, deadline=None)
@given(_JSON, st.booleans())
def test_json_depth_is_the_parsed_depth(data, ascii_only):
    """Strings full of brackets, quotes and backslashes, escaped or not (ensure_ascii)."""
    assert json_depth(json.dumps(data, ensure_ascii=ascii_only)) == _parsed_depth(data)


def test_hard_linked_png_from_outside_is_not_embedded(run_folder, tmp_path):
    outside = tmp_path / "outside.png"
    outside.write_bytes(PNG + b"outside")  # a real PNG, bytes no folder file has
    os.link(outside, run_folder / "linked.png")  # used to be embedded: a hard link is a regular file
    page = render_run_folder(run_folder)
    assert base64.b64encode(outside.read_bytes()).decode() not in page
    assert page.count("data:image/png;base64,") == 2                       # fit.png and extra.png only
    assert "(hard link, not read)" in page


def test_report_of_a_folder_a_run_is_writing_is_refused(run_folder, capsys):
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = run_folder / LOCK_NAME
        owner = f"{host_hash()}-{sleeper.pid}-{process_state(sleeper.pid)[1]}"
        lock.write_text(json.dumps({"owner": owner, "command": "verify", "since": time.time()}) + "\n")
        status = cli.main(["report", str(run_folder)])  # used to render the half-written folder
        err = capsys.readouterr().err
        assert status == 2 and len(err.strip().splitlines()) == 1 and "in use" in err, err
        assert not (run_folder / "report.html").exists()
    finally:
        sleeper.kill()
        sleeper.wait()
    assert cli.main(["report", str(run_folder)]) == 0  # its owner gone, the lock is cleared
    assert (run_folder / "report.html").exists() and not (run_folder / LOCK_NAME).exists()
