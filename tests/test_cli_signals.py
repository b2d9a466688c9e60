"""A real Ctrl-C or SIGTERM that stops ``cli.main`` called in-process (a test, a script) is
passed on to the caller once the command has cleaned up: pytest stops on it. Before, it
only failed the test inside ``main`` (status 143) and the run went on (SIGKILL needed)."""

from __future__ import annotations

import os
import signal

import pytest

from flexcal.validation import cli
from flexcal.validation.cli import forward as cmd_forward


@pytest.fixture
def ctrl_c_raises():
    """SIGINT as KeyboardInterrupt for the test (pytest in the background, or a pytest-xdist
    worker, may have SIGINT ignored)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def _signalled_while_printing(monkeypatch, signum):
    def print_then_signal(*args, **kwargs):  # inside the command, under its --out reservation
        os.kill(os.getpid(), signum)

    monkeypatch.setattr(cmd_forward, "print_point", print_then_signal)


def test_sigterm_inside_an_in_process_command_reaches_the_callers_handler(tmp_path, monkeypatch, capsys):
    caught = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: caught.append(signum))  # pytest's stand-in
    try:
        _signalled_while_printing(monkeypatch, signal.SIGTERM)
        status = cli.main(["forward", "--inputs-mm", "0.1,0,0", "--out", str(tmp_path / "out")])
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert status == 143 and "terminated (SIGTERM)" in capsys.readouterr().err  # the command's own line
    assert caught == [signal.SIGTERM]  # and then the caller's: a default handler ends the process
    assert list(tmp_path.iterdir()) == []  # cleaned up first: no staging folder, no lock


def test_ctrl_c_inside_an_in_process_command_stops_the_caller(tmp_path, monkeypatch, capsys, ctrl_c_raises):
    _signalled_while_printing(monkeypatch, signal.SIGINT)
    with pytest.raises(KeyboardInterrupt):
        cli.main(["forward", "--inputs-mm", "0.1,0,0", "--out", str(tmp_path / "out")])
    assert "interrupted" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_raised_keyboard_interrupt_is_not_passed_on(tmp_path, monkeypatch, capsys):
    # no signal came (a library raised it): the caller gets the status, as before
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cmd_forward, "print_point", interrupted)
    assert cli.main(["forward", "--inputs-mm", "0.1,0,0", "--out", str(tmp_path / "out")]) == 130
