"""``flexcal report DIR``: one self-contained HTML page from a run folder."""

import base64
import json
import re

import pytest

from flexcal.validation import cli
from flexcal.validation.reports.html import render_run_folder

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
