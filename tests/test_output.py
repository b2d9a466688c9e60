"""Outputs are written whole or not at all: errors and Ctrl-C inside the staged block,
inside a writer, or during the final moves leave no half-written file and no temporaries."""

from __future__ import annotations

import json
import os
import signal
import sys

import numpy as np
import pytest

from flexcal.validation.output import atomic_path, interrupts_deferred, staged_output, write_json, write_text


def _everything(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.parametrize("error", [RuntimeError("boom"), KeyboardInterrupt()])
def test_error_in_staged_block_leaves_nothing(tmp_path, error):
    out = tmp_path / "out"
    with pytest.raises(type(error)):
        with staged_output(out) as staging:
            write_json(staging / "report.json", {"a": 1})
            (staging / "half.csv").write_text("x,y\n1,")
            raise error
    assert _everything(tmp_path) == []  # no out folder, no staging folder


@pytest.mark.parametrize("error", [RuntimeError("boom"), KeyboardInterrupt()])
def test_error_keeps_previous_results_whole(tmp_path, error):
    out = tmp_path / "out"
    with staged_output(out) as staging:
        write_json(staging / "report.json", {"run": 1})
    with pytest.raises(type(error)):
        with staged_output(out, replace=True) as staging:
            write_json(staging / "report.json", {"run": 2})
            raise error
    assert json.loads((out / "report.json").read_text()) == {"run": 1}
    assert _everything(tmp_path) == ["out", "out/.flexcal-run", "out/report.json"]  # the marker of run 1


def test_success_moves_files_and_replaces_old_ones(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("old run, other file")
    (out / "report.json").write_text("old")
    with staged_output(out, resume=True) as staging:
        write_json(staging / "report.json", {"v": np.float64(2.5), "m": np.eye(2)})
        (staging / "sub").mkdir()
        write_text(staging / "sub" / "t.md", "# hi\n")
    assert json.loads((out / "report.json").read_text()) == {"v": 2.5, "m": [[1.0, 0.0], [0.0, 1.0]]}
    assert (out / "keep.txt").read_text() == "old run, other file"
    assert _everything(tmp_path) == ["out", "out/.flexcal-run", "out/keep.txt", "out/report.json", "out/sub",
                                     "out/sub/t.md"]
    assert os.stat(out / "report.json").st_mode & 0o044  # readable by others like any file the user writes


def test_out_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(ValueError, match="not a folder"):
        with staged_output(tmp_path / "f"):
            pass


@pytest.mark.parametrize("error", [TypeError, KeyboardInterrupt])
def test_writer_failure_leaves_old_file_and_no_temporary(tmp_path, error):
    target = tmp_path / "table.csv"
    target.write_text("old\n")
    with pytest.raises(error):
        with atomic_path(target) as tmp:
            assert tmp.parent == tmp_path and tmp.suffix == ".csv"  # writers pick the format by suffix
            tmp.write_text("new, half")
            raise error()
    assert target.read_text() == "old\n"
    assert _everything(tmp_path) == ["table.csv"]


def test_write_json_of_unserializable_data_leaves_nothing(tmp_path):
    with pytest.raises(TypeError):
        write_json(tmp_path / "r.json", {"x": object()})
    assert _everything(tmp_path) == []


def test_write_text_fsync_round_trips(tmp_path):
    write_text(tmp_path / "a.txt", "é\n", fsync=True)
    assert (tmp_path / "a.txt").read_text(encoding="utf-8") == "é\n"
    assert _everything(tmp_path) == ["a.txt"]


@pytest.fixture
def ctrl_c_raises():
    """SIGINT as KeyboardInterrupt for the test (pytest started in the background by a
    non-interactive shell inherits SIGINT ignored, and an ignored signal stays ignored)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_ctrl_c_during_the_moves_is_raised_after_them(tmp_path, monkeypatch, ctrl_c_raises):
    out = tmp_path / "out"
    with staged_output(out) as staging:  # an earlier run: --force replaces only a run folder
        (staging / "a.txt").write_text("old")
    original = os.replace

    def replace_then_interrupt(src, dst):  # Ctrl-C arrives after the first file moved
        original(src, dst)
        os.kill(os.getpid(), signal.SIGINT)

    with pytest.raises(KeyboardInterrupt):
        with staged_output(out, replace=True) as staging:
            for name in ("a.txt", "b.txt"):
                (staging / name).write_text("new")
            monkeypatch.setattr(os, "replace", replace_then_interrupt)
    monkeypatch.undo()
    assert (out / "a.txt").read_text() == "new" and (out / "b.txt").read_text() == "new"  # the moves completed
    assert _everything(tmp_path) == ["out", "out/.flexcal-run", "out/a.txt", "out/b.txt"]


def test_interrupts_deferred_without_signal_is_transparent(ctrl_c_raises):
    # the handler before the block is restored
    before = signal.getsignal(signal.SIGINT)
    with interrupts_deferred():
        value = 1
        assert signal.getsignal(signal.SIGINT) is not before  # held back inside the block
    assert value == 1
    assert signal.getsignal(signal.SIGINT) is before


def test_an_ignored_ctrl_c_stays_ignored():
    # a run started in the background by a non-interactive shell has SIGINT ignored: the
    # deferral must neither install a handler nor turn that signal into KeyboardInterrupt
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with interrupts_deferred():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            os.kill(os.getpid(), signal.SIGINT)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_an_interrupt_swallowed_in_the_block_leaves_out_untouched(tmp_path, monkeypatch):
    # a library that swallows the exception (a destructor's is only "ignored") does not stop
    # the run; staged_output must, before anything moves into out
    from flexcal.validation.cli.signals import Terminated, termination_raises

    class SignalsWhenDropped:
        def __del__(self):
            signal.raise_signal(signal.SIGTERM)

    reported = []
    monkeypatch.setattr(sys, "unraisablehook", reported.append)
    out = tmp_path / "out"
    with termination_raises(), pytest.raises(Terminated):
        with staged_output(out) as staging:
            (staging / "report.json").write_text("{}")
            SignalsWhenDropped()
            (staging / "more.json").write_text("{}")  # the block itself went on
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no out, no staging folder
    assert reported == []  # recorded, not printed as "Exception ignored"
    assert sys.unraisablehook == reported.append  # put back


def test_other_exceptions_of_destructors_are_still_reported(monkeypatch):
    from flexcal.validation.cli.signals import termination_raises

    class FailsWhenDropped:
        def __del__(self):
            raise ValueError("a destructor's own error")

    reported = []
    monkeypatch.setattr(sys, "unraisablehook", reported.append)
    with termination_raises():
        FailsWhenDropped()
    assert [type(r.exc_value) for r in reported] == [ValueError]
