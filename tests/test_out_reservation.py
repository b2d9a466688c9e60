"""``--out`` is reserved for one run at a time, and ``--force`` replaces only a run folder
that holds none of the command's inputs (issue 23): real ``flexcal`` processes where the
command line is the subject, as in ``test_faults.py``."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from flexcal.fem.owners import host_hash, process_state
from flexcal.validation import cli
from flexcal.validation.cli.signals import Terminated, termination_raises
from flexcal.validation.output import atomic_path, staged_output
from flexcal.validation.out_lock import LOCK_NAME, lock_paths, read_holder, reserved
from flexcal.validation.run_folder import MARKER_NAME, inputs_inside

FLEXCAL = [sys.executable, "-c", "import sys; from flexcal.validation.cli import main; sys.exit(main())"]
TRUTH = ["truth", "--scenario", "table1", "--provider", "analytic", "--seed", "3"]
# identify and verify at their smallest: the paper's method, a short Sobol and PSO, the closed-form model
FAST_CALIBRATION = {"identify": ["--model", "second-order",
                                 "--model-stiffness", "closed-form", "--method", "paper", "--particles", "40",
                                  "--iterations", "3"]}
FAST_CALIBRATION["verify"] = [*FAST_CALIBRATION["identify"], "--sobol-n", "8"]
TRUTH_FILES = [MARKER_NAME, "curves.csv", "curves.json", "curves.png", "report.json", "report.md", "timings.json"]
WAIT_S = 120  # the longest a run may take on a loaded 2-core machine


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _flexcal(argv, cwd, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([*FLEXCAL, *argv], cwd=cwd, capture_output=True, text=True, timeout=WAIT_S,
                          stdin=subprocess.DEVNULL, **kwargs)


def _one_error_line(done: subprocess.CompletedProcess, *words: str) -> str:
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    for word in words:
        assert word in lines[0], (word, lines[0])
    return lines[0]


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def truth_run(tmp_path_factory) -> Path:
    """A finished ``flexcal truth`` run folder (curves.csv and its sidecar inside)."""
    out = tmp_path_factory.mktemp("truth") / "run1"
    assert cli.main([*TRUTH, "--out", str(out), "-q"]) == 0
    return out


# ----------------------------------------------------------------------------------------
# --force


@pytest.mark.parametrize("command", ["identify", "verify"])
def test_force_never_replaces_the_folder_holding_the_commands_data(tmp_path, truth_run, command):
    # before: 'identify --data run1/curves.csv --force --out run1' deleted the measurement, exit 0
    run1 = tmp_path / "run1"
    subprocess.run(["cp", "-a", str(truth_run), str(run1)], check=True)
    before = _snapshot(run1)
    argv = [command, "--data", "run1/curves.csv", *FAST_CALIBRATION[command], "--force", "--out", "run1", "-q"]
    done = _flexcal(argv, tmp_path)
    _one_error_line(done, "holds an input", "--data run1/curves.csv", "choose another --out")
    assert _snapshot(run1) == before  # the measurement, its sidecar and the rest: untouched


def test_force_never_replaces_a_folder_that_is_not_a_run(tmp_path):
    # before: '--force --out photos' emptied any folder, recursively, exit 0
    photos = tmp_path / "photos"
    (photos / "2024").mkdir(parents=True)
    (photos / "a.jpg").write_bytes(b"a picture")
    (photos / "2024" / "b.jpg").write_bytes(b"another")
    before = _snapshot(photos)
    done = _flexcal([*TRUTH, "--force", "--out", "photos", "-q"], tmp_path)
    _one_error_line(done, "not a flexcal run folder", "a.jpg", "choose a new or empty folder")
    assert _snapshot(photos) == before


def test_force_replaces_a_run_folder_and_keeps_the_marker(tmp_path, truth_run):
    run1 = tmp_path / "run1"
    subprocess.run(["cp", "-a", str(truth_run), str(run1)], check=True)
    (run1 / "stale.png").write_bytes(b"a picture of an older run")
    assert cli.main([*TRUTH, "--seed", "4", "--force", "--out", str(run1), "-q"]) == 0
    assert sorted(p.name for p in run1.iterdir()) == TRUTH_FILES  # stale.png gone, no lock left
    assert (run1 / MARKER_NAME).read_text() == "truth\n"


def test_inputs_are_found_in_any_option_and_in_the_toml_files_they_name(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "traj.csv").write_text("xa1_mm,xa2_mm,xa3_mm\n")
    scenario = tmp_path / "scenario.toml"  # outside --out, but it names a file inside
    scenario.write_text('name = "s"\n[trajectory]\nfile = "out/traj.csv"\n')
    (tmp_path / "link.csv").symlink_to(out / "traj.csv")
    found = inputs_inside(out, [("--scenario", str(scenario)), ("--a-new-option", str(out / "traj.csv")),
                                ("--list", ["x", str(tmp_path / "link.csv")]), ("--seed", 3), ("--name", "table1"),
                                ("--folder", str(out))])
    assert [f.split()[0] for f in found] == ["--scenario", "--a-new-option", "--list", "--folder"]
    (tmp_path / "other.csv").write_text("")
    assert inputs_inside(out, [("--scenario", str(tmp_path / "missing.toml")),
                               ("--data", str(tmp_path / "other.csv"))]) == []


def test_design_force_replaces_its_earlier_run(tmp_path, capsys):
    # before: design --force computed everything, then refused the folder (staged_output without replace)
    fast = ["design", "--model", "second-order",
            "--model-stiffness", "closed-form", "--inadequacy", "none", "--points", "13",
            "--candidates", "40", "-q"]
    out = tmp_path / "d"
    assert cli.main([*fast, "--out", str(out)]) == 0
    assert cli.main([*fast, "--design-seed", "1", "--force", "--out", str(out)]) == 0, capsys.readouterr().err
    assert json.loads((out / "report.json").read_text())["design_seed"] == 1


# ----------------------------------------------------------------------------------------
# the reservation


def _long_trajectory(path: Path) -> None:
    """301 postures: a truth run of ~8 s (77 take ~2.5 s) to overlap a second run with."""
    from flexcal.model.trajectory import standard_trajectory

    trajectory = standard_trajectory(n_points=301)
    rows = ["xa1_mm,xa2_mm,xa3_mm,leg"] + [f"{a * 1e3:.9f},{b * 1e3:.9f},{c * 1e3:.9f},{int(leg)}"
                                           for (a, b, c), leg in zip(trajectory.inputs, trajectory.leg)]
    path.write_text("\n".join(rows) + "\n")


def test_a_second_run_to_the_same_out_is_refused_while_the_first_runs(tmp_path):
    # before: both reported success and the folder held a mix of the two runs
    _long_trajectory(tmp_path / "long.csv")
    first = subprocess.Popen([*FLEXCAL, *TRUTH, "--trajectory", "long.csv", "--out", "out"], cwd=tmp_path,
                             stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                             preexec_fn=_default_sigint)
    try:
        while "prototype: started" not in first.stderr.readline():  # the first run holds --out and computes
            assert first.poll() is None, "the first run ended early"
        for force in ([], ["--force"]):
            second = _flexcal([*TRUTH, "--seed", "4", "--out", "out", *force, "-q"], tmp_path)
            _one_error_line(second, "--out out is in use", f"flexcal truth, pid {first.pid}", "wait for it to end")
            assert first.poll() is None, "the first run must still be running, or this test proves nothing"
        first.stderr.read()
        assert first.wait(WAIT_S) == 0
    finally:
        first.kill()
        first.wait()
    out = tmp_path / "out"
    assert sorted(p.name for p in out.iterdir()) == TRUTH_FILES  # only the first run's files, lock released
    assert json.loads((out / "curves.json").read_text())["seed"] == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.csv", "out"]  # no lock beside it either
    assert _flexcal([*TRUTH, "--seed", "4", "--out", "out", "--force", "-q"], tmp_path).returncode == 0


def _gone_pid() -> int:
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def _write_lock(path: Path, pid: int, start: int, host: str = None) -> None:
    owner = f"{host or host_hash()}-{pid}-{start}"
    path.write_text(json.dumps({"owner": owner, "command": "truth", "since": time.time() - 60}) + "\n")


@pytest.mark.parametrize("existing_out", [False, True], ids=["new-out", "existing-out"])
def test_the_lock_of_a_killed_run_is_cleared(tmp_path, existing_out, capsys):
    out = tmp_path / "out"
    if existing_out:
        out.mkdir()
    lock = lock_paths(out)[0 if existing_out else 1]
    _write_lock(lock, _gone_pid(), 0)
    assert cli.main([*TRUTH, "--out", str(out), "-q"]) == 0, capsys.readouterr().err
    assert not lock.exists() and not any(p.name.endswith("flexcal-lock") for p in tmp_path.iterdir())


def test_a_live_or_foreign_lock_is_respected(tmp_path, capsys):
    out = tmp_path / "out"
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        beside = lock_paths(out)[1]
        _write_lock(beside, sleeper.pid, process_state(sleeper.pid)[1])
        status = cli.main([*TRUTH, "--out", str(out), "-q"])
        err = capsys.readouterr().err
        assert status == 2 and len(err.strip().splitlines()) == 1, err
        assert f"pid {sleeper.pid} on this host" in err and "in use" in err
        _write_lock(beside, sleeper.pid, 0, host="0badc0de")  # another host's: its pids mean nothing here
        assert cli.main([*TRUTH, "--out", str(out), "-q"]) == 2
        assert f"remove {beside}" in capsys.readouterr().err and beside.exists()
    finally:
        sleeper.kill()
        sleeper.wait()
    assert not out.exists()


def test_the_reservation_is_reentrant_and_released_on_error(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with reserved(out, command="test"):
            with staged_output(out) as staging:  # inside the command's own reservation: no second lock
                (staging / "a.txt").write_text("a")
            assert (out / MARKER_NAME).read_text() == "test\n"
            holder = read_holder(lock_paths(out)[1])
            assert holder.pid == os.getpid() and holder.command == "test"
            raise RuntimeError("boom")
    assert sorted(p.name for p in tmp_path.rglob("*")) == [MARKER_NAME, "a.txt", "out"]
    with reserved(out, command="again"):  # released: a new run takes it, now inside the folder
        assert (out / LOCK_NAME).is_file()
    assert not (out / LOCK_NAME).exists()


def test_a_ctrl_c_before_the_release_is_deferred_still_releases_the_lock(tmp_path, monkeypatch):
    """The race CI met once (session 16): Ctrl-C lands in the reservation's end before its
    interrupts are held back. Made deterministic: the first deferral raises KeyboardInterrupt
    on entry, as the signal would; the lock must be gone and the Ctrl-C still raised."""
    import flexcal.validation.out_lock as out_lock

    real = out_lock.interrupts_deferred
    calls = []

    def interrupted_once():
        calls.append(1)
        if len(calls) == 1:  # the first try of the release (patched after the lock was taken)
            raise KeyboardInterrupt
        return real()

    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        with reserved(out, command="test"):
            assert any(path.exists() for path in lock_paths(out))
            monkeypatch.setattr(out_lock, "interrupts_deferred", interrupted_once)
    assert len(calls) == 2  # the release was tried again after the interrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no lock left beside or inside



@pytest.fixture
def ctrl_c_raises():
    """SIGINT as KeyboardInterrupt for the test (pytest started in the background by a
    non-interactive shell, or as a pytest-xdist worker, may have SIGINT ignored)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("signum, raised", [(signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, Terminated)],
                         ids=["ctrl-c", "sigterm"])
@pytest.mark.parametrize("when", ["taking", "releasing"])
def test_a_signal_while_the_lock_is_taken_or_released_leaves_no_lock(tmp_path, monkeypatch, ctrl_c_raises, signum,
                                                                       raised, when):
    # before: a Ctrl-C right after a run's last line landed in the release: the process ended
    # 130 with its results whole, but .out.flexcal-lock stayed beside the folder (flaky
    # test_ctrl_c_after_the_results_are_written[at-once])
    import flexcal.validation.out_lock as out_lock

    step = {"taking": "_acquire", "releasing": "_release"}[when]
    original = getattr(out_lock, step)

    def signalled(*args, **kwargs):  # the signal lands in the step, as a real Ctrl-C or kill can
        if when == "releasing":
            signal.raise_signal(signum)  # before the lock file is removed
        result = original(*args, **kwargs)
        if when == "taking":
            signal.raise_signal(signum)  # the lock file made, not yet recorded as this run's
        return result

    monkeypatch.setattr(out_lock, step, signalled)
    out = tmp_path / "out"
    with termination_raises(), pytest.raises(raised):  # the command line's handlers
        with reserved(out, command="test"):
            out.mkdir()
            if when == "taking":
                pytest.fail("the signal was not delivered before the block")  # it ends the run, after the lock is whole
    assert sorted(p.name for p in tmp_path.iterdir()) == (["out"] if when == "releasing" else [])
    assert not any(tmp_path.rglob("*flexcal-lock*"))
    assert out_lock._held == {}


# ----------------------------------------------------------------------------------------
# options and messages


@pytest.mark.parametrize("option", [["--workers", "-1"], ["--workers", "two"], ["--scheduler", "not an address"],
                                    ["--scheduler", "tcp://10.0.0.5:99999"]])
def test_bad_executor_options_are_refused_up_front(tmp_path, capsys, option):
    # before: accepted silently by a run that builds no FEM segment (exit 0)
    status = cli.main([*TRUTH, *option, "--out", str(tmp_path / "out"), "-q"])
    err = capsys.readouterr().err
    assert status == 2 and len(err.strip().splitlines()) == 1 and option[0] in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("address", ["tcp://10.0.0.5:8786", "10.0.0.5:8786", "tls://host.example:8786",
                                     "tcp://[::1]:8786", "scheduler"])
def test_scheduler_addresses_dask_takes_pass(address):
    from flexcal.validation.cli.options import scheduler_address

    assert scheduler_address(address) == address


@pytest.mark.parametrize("command", ["sensitivity", "design"])
def test_sensitivity_and_design_build_the_model_where_the_options_say(tmp_path, monkeypatch, capsys, command):
    # before: their model's FEM segment builds ignored --workers and --scheduler
    from flexcal.validation.runs import model_correction

    seen = {}

    def record(*args, **kwargs):
        seen.update(kwargs)
        raise ValueError("stop here")

    monkeypatch.setattr(model_correction, "model_space", record)
    source = ["--scenario", "table1", "--provider", "analytic"] if command == "sensitivity" else []
    status = cli.main([command, *source, "--workers", "3", "--scheduler", "tcp://10.0.0.5:8786",
                       "--out", str(tmp_path / "out"), "-q"])
    assert status == 2 and "stop here" in capsys.readouterr().err
    assert seen["workers"] == 3 and seen["scheduler"] == "tcp://10.0.0.5:8786"
    # the default consistent model with quadratic dimension terms: its chains in one batch
    # (dimension_terms.prepare_model_chains, called inside model_space)
    from flexcal.validation.runs.dimension_terms import prepare_model_chains

    assert seen["model"] == "consistent" and seen["also_build"] is prepare_model_chains


def test_a_folder_given_for_a_file_says_so(tmp_path, truth_run, capsys):
    # before: 'measurement file ... does not exist', for a folder that does
    status = cli.main(["identify", "--data", str(truth_run), "--out", str(tmp_path / "out"), "-q"])
    err = capsys.readouterr().err
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    assert f"--data {truth_run} is a folder, not a file" in err and "curves.csv" in err


def test_a_full_disk_names_the_out_folder(tmp_path):
    # /dev/full answers every write with ENOSPC, as a full disk does: no file name in the error
    out = tmp_path / "out"
    with pytest.raises(OSError) as caught:
        with staged_output(out):
            with open("/dev/full", "w") as stream:
                stream.write("x" * 100_000)
    assert caught.value.filename == str(out)
    line = cli.common.error_line("truth", caught.value)
    assert line.startswith(f"flexcal truth: error: No space left on device: {out}") and "free space" in line
    target = tmp_path / "table.csv"
    with pytest.raises(OSError) as caught:
        with atomic_path(target) as tmp:
            tmp.symlink_to("/dev/full")
            with open(tmp, "w") as stream:
                stream.write("x" * 100_000)
    assert caught.value.filename == str(target) and list(tmp_path.iterdir()) == []


def test_a_write_error_without_a_path_names_out(tmp_path):
    # a real command line whose file writes fail (a 20 kB file-size limit: EFBIG, no path in the error)
    def limited():
        _default_sigint()
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))

    done = subprocess.run([*FLEXCAL, *TRUTH, "--out", "out", "-q"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=WAIT_S, preexec_fn=limited)
    line = _one_error_line(done, "File too large")
    # the file where the writer named it (a path in --out, never the hidden staging folder), else --out itself
    assert line.endswith(": out") or ": out/" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.parametrize("delay_s", [0.0, 0.3], ids=["at-once", "in-the-shutdown"])
def test_ctrl_c_after_the_results_are_written(tmp_path, delay_s):
    # before: killed by SIGINT with no line (-2) in the interpreter's shutdown, or a line saying
    # 'nothing was written to --out' about a folder that was complete
    run = subprocess.Popen([*FLEXCAL, *TRUTH, "--out", "out"], cwd=tmp_path, stdin=subprocess.DEVNULL,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)
    assert "wrote out/curves.csv" in run.stdout.readline()  # the results are written
    time.sleep(delay_s)
    run.send_signal(signal.SIGINT)
    status = run.wait(WAIT_S)
    lines = run.stderr.read().strip().splitlines()
    assert status in (0, 130) and "Traceback" not in "\n".join(lines), (status, lines)
    if status == 130:  # it landed before the run had ended: one line that says the results are whole
        assert "interrupted after the run wrote its results" in lines[-1] and "are complete" in lines[-1], lines
    else:  # in the shutdown: held back, the run's own status
        assert not any("interrupted" in line for line in lines), lines
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == TRUTH_FILES
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_an_interrupt_that_got_ahead_of_a_release_leaves_no_lock(tmp_path, monkeypatch):
    # a Ctrl-C that lands between a reserved block's end and its release (CI, session 29: the
    # lock beside out/ was left): here the block is entered and never left, then Ctrl-C
    out = tmp_path / "out"
    never_left = []  # kept alive: a dropped generator would release its lock when collected

    def interrupted_main(argv, command):
        never_left.append(reserved(out, command="truth"))
        never_left[-1].__enter__()
        out.mkdir()
        raise KeyboardInterrupt

    outer = tmp_path / "outer"
    with reserved(outer, command="sweep"):  # one the process held before: not this command's to release
        monkeypatch.setattr(cli, "_main", interrupted_main)
        assert cli._run(["truth"], "truth") == 130
        assert read_holder(lock_paths(outer.resolve())[1]) is not None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert list(out.iterdir()) == []
