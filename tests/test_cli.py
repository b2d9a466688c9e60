"""The command line's frame: help, unknown commands, error exit status."""

import subprocess
import sys

from flexcal.validation import cli


def test_help_lists_available_commands(capsys):
    assert cli.main([]) == 2  # no command: help and a usage error status
    out = capsys.readouterr().out
    assert "flexcal" in out and "<command>" in out


def test_console_script_help_runs():
    result = subprocess.run([sys.executable, "-m", "flexcal.validation.cli", "--help"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0
    assert "usage: flexcal" in result.stdout
