"""Fault injection: real ``flexcal`` processes interrupted by SIGINT / SIGTERM at chosen
points, ``--out`` folders that cannot be used, outputs that must be strict JSON and
HTML reports fed hostile strings.

A run is stopped at a point it announces itself: off a terminal every progress stage
prints one line (``progress.LineProgress``), the test waits for that line and sends
the signal then. Afterwards: the right exit status (130 Ctrl-C, 143 SIGTERM), one line
that says so, no ``--out`` folder, no staging folder, nothing in the working directory,
and the same command run again succeeds.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from flexcal.validation import cli
from flexcal.validation.output import dumps_strict, staged_output, write_json
from flexcal.validation.out_lock import lock_paths, read_holder

# a command line, runnable in a child process, that starts with SIGINT delivered as Python's
# KeyboardInterrupt even when pytest itself was started in the background (SIGINT ignored)
FLEXCAL = [sys.executable, "-c", "import sys; from flexcal.validation.cli import main; sys.exit(main())"]
TRUTH = ["truth", "--scenario", "table1", "--provider", "analytic", "--seed", "3"]
# the paper's method: its Sobol and PSO stages are the named points to interrupt at
VERIFY = ["verify", "--scenario", "table1", "--provider", "analytic", "--model", "second-order",
          "--model-stiffness", "closed-form",
          "--method", "paper", "--sobol-n", "8", "--particles", "40", "--iterations", "3"]
# fTetWild (not the default mapped mesher): its meshing stage is the one to interrupt
HINGE = ["hinge", "--type", "circular", "--radius-mm", "5", "--thickness-mm", "1", "--width-mm", "10",
         "--elements-through", "2", "--mesher", "tetwild"]
WAIT_S = 120  # the longest a stage line may take to appear on a loaded 2-core machine


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _strict(text: str):
    def refuse(constant):
        raise ValueError(f"non-strict JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


class Run:
    """A flexcal child process whose stderr lines are collected as they come."""

    def __init__(self, argv: list[str], cwd: Path, env: dict[str, str] | None = None):
        self.lines: list[str] = []
        self.process = subprocess.Popen([*FLEXCAL, *argv], cwd=cwd, stdin=subprocess.DEVNULL,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                        preexec_fn=_default_sigint, env={**os.environ, **(env or {})})
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.process.stderr:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, text: str) -> bool:
        """True once a stderr line contains ``text``; False if the process ended first."""
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            if any(text in line for line in self.lines):
                return True
            if self.process.poll() is not None:
                self._reader.join(5)
                return any(text in line for line in self.lines)
            time.sleep(0.02)
        raise AssertionError(f"no line with {text!r} within {WAIT_S} s: {self.lines}")

    def finish(self) -> int:
        status = self.process.wait(WAIT_S)
        self._reader.join(5)
        return status


def _interrupt_at(argv, tmp_path, stage, signum, *, delay_s=0.0, env=None):
    """Run ``argv`` with ``--out tmp_path/out``, send ``signum`` once ``stage`` is printed
    (plus ``delay_s``); returns (status, stderr lines)."""
    work = tmp_path / "work"
    work.mkdir(exist_ok=True)
    run = Run([*argv, "--out", str(tmp_path / "out")], work, env)
    assert run.wait_for(stage), run.lines
    time.sleep(delay_s)
    run.process.send_signal(signum)
    return run.finish(), run.lines, work


def _assert_stopped_cleanly(status, lines, tmp_path, work, signum):
    code, word = {signal.SIGINT: (130, "interrupted"), signal.SIGTERM: (143, "terminated (SIGTERM)")}[signum]
    assert status == code, lines
    assert not any("Traceback" in line for line in lines), lines
    assert word in lines[-1] and "nothing was written to --out" in lines[-1], lines
    assert sorted(p.name for p in tmp_path.iterdir()) == ["work"]  # no out, no .out.* staging folder
    assert list(work.iterdir()) == []  # no __tracked_surface.stl or temporaries in the working directory


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("stage, delay_s", [("prototype: started", 0.0), ("prototype: started", 0.3)],
                         ids=["first-point", "mid-points"])
def test_truth_interrupted_leaves_nothing_and_reruns(tmp_path, signum, stage, delay_s):
    status, lines, work = _interrupt_at(TRUTH, tmp_path, stage, signum, delay_s=delay_s)
    _assert_stopped_cleanly(status, lines, tmp_path, work, signum)
    assert cli.main([*TRUTH, "--out", str(tmp_path / "out"), "-q"]) == 0
    assert (tmp_path / "out" / "curves.csv").is_file()


@pytest.mark.parametrize("signum, stage", [(signal.SIGINT, "Sobol: started"), (signal.SIGTERM, "PSO: started")],
                         ids=["SIGINT-sobol", "SIGTERM-pso"])
def test_verify_interrupted_leaves_nothing(tmp_path, signum, stage):
    status, lines, work = _interrupt_at(VERIFY, tmp_path, stage, signum)
    if status == 0:  # the PSO stage is short: the run may finish before the signal lands
        pytest.skip("the run finished before the signal arrived")
    _assert_stopped_cleanly(status, lines, tmp_path, work, signum)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_hinge_interrupted_while_meshing(tmp_path, signum):
    # the case of issue 14: pytetwild reset the SIGINT handler and Ctrl-C killed flexcal silently
    # an empty FEM cache of its own (outside tmp_path, whose contents are checked): hinge
    # results are cached, and a served one never reaches the mesher
    cache = tmp_path.parent / f"{tmp_path.name}-cache"
    status, lines, work = _interrupt_at(HINGE, tmp_path, "tetwild mesh", signum, delay_s=0.5,
                                        env={"FLEXCAL_CACHE_DIR": str(cache)})
    _assert_stopped_cleanly(status, lines, tmp_path, work, signum)


def test_hinge_terminated_while_rendering(tmp_path):
    # VTK renders the pictures off-screen inside the staging step; SIGTERM there removes the staging folder
    status, lines, work = _interrupt_at(HINGE, tmp_path, "VTU, pictures", signal.SIGTERM, delay_s=0.2)
    _assert_stopped_cleanly(status, lines, tmp_path, work, signal.SIGTERM)


@pytest.mark.slow
def test_hinge_interrupted_while_solving_then_rerun(tmp_path):
    status, lines, work = _interrupt_at(HINGE, tmp_path, "FEM solve", signal.SIGINT, delay_s=0.5)
    _assert_stopped_cleanly(status, lines, tmp_path, work, signal.SIGINT)
    rerun = subprocess.run([*FLEXCAL, *HINGE, "--out", str(tmp_path / "out"), "-q"], cwd=work,
                           capture_output=True, text=True, preexec_fn=_default_sigint)
    assert rerun.returncode == 0, rerun.stderr
    assert rerun.stderr == ""  # no VTK 'bad X server connection' warning either
    assert {"report.json", "hinge.png", "hinge.vtu"} <= {p.name for p in (tmp_path / "out").iterdir()}


def test_ctrl_c_still_works_after_meshing(tmp_path):
    # in-process check of the mechanism: after a mesh, SIGINT is still Python's KeyboardInterrupt
    script = """
import os, signal, sys, time
import numpy as np
from flexcal.fem.tetwild_process import tetrahedralize_in_child
corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.int32)
nodes, tets = tetrahedralize_in_child(corners, faces, edge_length_fac=0.5, quiet=True)
assert len(tets) > 0 and nodes.shape[1] == 3
try:
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(5)
except KeyboardInterrupt:
    print("KeyboardInterrupt")
    sys.exit(0)
sys.exit(3)
"""
    result = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True,
                            preexec_fn=_default_sigint, timeout=WAIT_S)
    assert result.returncode == 0 and "KeyboardInterrupt" in result.stdout, result.stderr
    assert list(tmp_path.iterdir()) == []  # fTetWild's __tracked_surface.stl stayed in its own folder


def test_sigterm_during_the_final_moves_lets_them_finish(tmp_path, monkeypatch):
    from flexcal.validation.cli.signals import Terminated, termination_raises

    out = tmp_path / "out"
    out.mkdir()
    original = os.replace

    def replace_then_terminate(src, dst):
        original(src, dst)
        os.kill(os.getpid(), signal.SIGTERM)

    with termination_raises(), pytest.raises(Terminated):
        with staged_output(out) as staging:
            for name in ("a.txt", "b.txt"):
                (staging / name).write_text("new")
            monkeypatch.setattr(os, "replace", replace_then_terminate)
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.rglob("*")) == [".flexcal-run", "a.txt", "b.txt", "out"]


# the default mapped mesher: a hinge run of a few seconds whose staging step (VTU and pictures) lasts ~1 s
MAPPED_HINGE = ["hinge", "--type", "circular", "--radius-mm", "5", "--thickness-mm", "1", "--width-mm", "10",
                "--elements-through", "2"]


def _staging_folders(where: Path) -> list[Path]:
    return sorted(p for p in where.iterdir() if p.name.startswith(".out.") and p.is_dir())


@pytest.mark.parametrize("existing_out", [False, True], ids=["new-out", "existing-out"])
def test_staging_folder_of_a_killed_run_is_removed_by_the_next_run(tmp_path, existing_out):
    """SIGKILL cannot be caught: the run's staging folder stays (beside a new --out, inside
    an existing one). The next run that stages there sees its owner is gone and removes it."""
    out = tmp_path / "out"
    extra = []
    if existing_out:
        out.mkdir()
        (out / "old.txt").write_text("an earlier run")
        (out / ".flexcal-run").write_text("hinge\n")  # the marker: --force replaces only a run folder
        extra = ["--force"]
    where = out if existing_out else tmp_path
    env = {"FLEXCAL_CACHE_DIR": str(tmp_path.parent / f"{tmp_path.name}-cache")}
    run = Run([*MAPPED_HINGE, "--out", str(out), *extra], tmp_path, env)
    assert run.wait_for("VTU, pictures"), run.lines
    deadline = time.monotonic() + WAIT_S
    while not _staging_folders(where) and run.process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    run.process.send_signal(signal.SIGKILL)
    assert run.finish() == -signal.SIGKILL
    left = _staging_folders(where)
    assert len(left) == 1 and f"-{run.process.pid}-" in left[0].name, left  # the pid is in the name
    assert (out / "old.txt").is_file() if existing_out else not out.exists()  # --out untouched
    lock = lock_paths(out)[0 if existing_out else 1]  # its reservation of --out is left too, naming it
    assert read_holder(lock).pid == run.process.pid

    assert subprocess.run([*FLEXCAL, *MAPPED_HINGE, "--out", str(out), "--force", "-q"], cwd=tmp_path,
                          env={**os.environ, **env}, timeout=WAIT_S).returncode == 0
    assert _staging_folders(where) == [] and (out / "report.json").is_file()
    assert not lock.exists()  # cleared (its owner is gone), then taken and released by the next run


def test_only_the_staging_folders_of_gone_processes_are_removed(tmp_path):
    from flexcal.fem.owners import host_hash, process_state
    from flexcal.validation.output import remove_stale_staging

    def folder(name: str) -> Path:
        path = tmp_path / name
        path.mkdir()
        (path / "report.json").write_text("{}")
        return path

    def staging_name(pid: int, start: int, host: str = host_hash()) -> str:
        return f".out.flexcal-{host}-{pid}-{start}.abcd_123"

    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    zombie = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    try:
        zombie.kill()  # killed but not reaped: a zombie, which counts as gone
        while process_state(zombie.pid)[0] != "Z":
            time.sleep(0.01)
        start = process_state(alive.pid)[1]
        keep = [folder(staging_name(alive.pid, start)),                # a live process
                folder(staging_name(os.getpid(), 0)),                  # this one (start unknown)
                folder(staging_name(gone.pid, 0, host="0badc0de")),    # another host's: its pids mean nothing here
                folder(".out.abcd_123"),                               # the older name, no owner recorded
                folder("out.flexcal-00000000-1-1.abcd_123")]           # not hidden: not a staging folder
        removed = [folder(staging_name(gone.pid, 0)),                  # exited
                   folder(staging_name(zombie.pid, 0)),                # killed, not reaped
                   folder(staging_name(alive.pid, start + 1))]         # the pid now belongs to another process
        assert sorted(remove_stale_staging(tmp_path)) == sorted(p.name for p in removed)
        assert all(p.is_dir() for p in keep) and not any(p.exists() for p in removed)
    finally:
        for process in (alive, zombie):
            process.kill()
            process.wait()


# ----------------------------------------------------------------------------------------
# --out


def _one_line(capsys, status, code, *words):
    err = capsys.readouterr().err
    assert status == code, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    for word in words:
        assert word in lines[0], (word, lines[0])


def test_out_holding_another_run_is_refused_and_force_replaces_it(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "fit.png").write_bytes(b"stale picture of an earlier identify")
    (out / "report.json").write_text("{}")
    (out / "timings.json").write_text("{}")  # report.json with timings.json: a run of before the marker
    start = time.monotonic()
    status = cli.main([*TRUTH, "--out", str(out), "-q"])
    _one_line(capsys, status, 2, "already holds files", "fit.png", "--force")
    assert time.monotonic() - start < 2  # refused before the virtual prototype ran (it takes seconds)
    assert (out / "fit.png").is_file()
    assert cli.main([*TRUTH, "--out", str(out), "-q", "--force"]) == 0
    assert not (out / "fit.png").exists()
    assert cli.main(["report", str(out)]) == 0
    assert "fit.png" not in (out / "report.html").read_text()


def test_force_keeps_the_old_run_when_the_new_one_fails(tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main([*TRUTH, "--out", str(out), "-q"]) == 0
    before = (out / "curves.csv").read_bytes()
    status = cli.main([*TRUTH, "--noise-urad", "-1", "--out", str(out), "-q", "--force"])
    _one_line(capsys, status, 2, "--noise-urad")
    assert (out / "curves.csv").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"] and not (out / ".flexcal-lock").exists()  # released


@pytest.fixture
def locked_folder(tmp_path):
    """A folder this user cannot write in. Root ignores mode bits: for root the folder is
    made immutable (``chattr +i``, ext4 and friends) or the test is skipped."""
    folder = tmp_path / "locked"
    folder.mkdir()
    if os.geteuid() != 0:
        folder.chmod(0o555)
        yield folder
        folder.chmod(0o755)
        return
    if shutil.which("chattr") is None or subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode:
        pytest.skip("running as root and the file system has no immutable attribute (chattr +i)")
    try:
        yield folder
    finally:
        subprocess.run(["chattr", "-i", str(folder)], check=True)


@pytest.mark.parametrize("case", ["read-only-folder", "unwritable-parent"])
def test_unwritable_out_is_refused_before_any_computation(locked_folder, case, capsys):
    out = locked_folder if case == "read-only-folder" else locked_folder / "new" / "run"
    start = time.monotonic()
    status = cli.main([*TRUTH, "--out", str(out)])
    assert time.monotonic() - start < 2  # before the virtual prototype ran (it takes seconds)
    _one_line(capsys, status, 2, "cannot write", str(locked_folder), "choose a folder")
    assert list(locked_folder.iterdir()) == []


def test_moves_across_file_systems_are_copied(tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    original = os.replace

    def cross_device(src, dst):  # what a rename onto another file system answers
        if ".partial" not in str(src):
            raise OSError(errno.EXDEV, "Invalid cross-device link", str(src))
        return original(src, dst)

    with staged_output(out) as staging:
        write_json(staging / "report.json", {"a": 1})
        (staging / "cases").mkdir()
        (staging / "cases" / "c.json").write_text("{}")
        monkeypatch.setattr(os, "replace", cross_device)  # for the final moves only
    monkeypatch.undo()
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == [
        "out", "out/.flexcal-run", "out/cases", "out/cases/c.json", "out/report.json"]


# ----------------------------------------------------------------------------------------
# strict JSON


def test_non_finite_numbers_become_null_with_a_note():
    data = {"condition_number": float("inf"), "sd": [1.0, float("nan")], "x": -float("inf"), "ok": 2.0}
    parsed = _strict(dumps_strict(data))
    assert parsed["condition_number"] is None and "rank deficient" in parsed["condition_number_note"]
    assert parsed["sd"] == [1.0, None] and "1 non-finite" in parsed["sd_note"]
    assert parsed["x"] is None and "-infinity" in parsed["x_note"]
    assert parsed["ok"] == 2.0 and "ok_note" not in parsed


def test_verify_report_and_json_summary_are_strict_json(tmp_path):
    # 8-sample Sobol and a 3-iteration swarm: the identifiability analysis is rank deficient
    # (condition number infinite), which report.json used to write as Infinity
    out = tmp_path / "out"
    result = subprocess.run([*FLEXCAL, *VERIFY, "--out", str(out), "--json"], capture_output=True, text=True,
                            cwd=tmp_path, timeout=WAIT_S)
    assert result.returncode == 0, result.stderr
    report = _strict((out / "report.json").read_text())
    _strict(result.stdout)
    identifiability = report["identifiability"]
    if identifiability["condition_number"] is None:
        assert "infinite" in identifiability["condition_number_note"]


# ----------------------------------------------------------------------------------------
# HTML report


def test_hostile_scenario_name_is_escaped_in_the_html_report(tmp_path):
    scenario = tmp_path / "x.toml"
    scenario.write_text('name = "<img src=x onerror=alert(1)>"\ndraw_unset = false\n')
    out = tmp_path / "out"
    assert cli.main(["truth", "--scenario", str(scenario), "--provider", "analytic", "--out", str(out), "-q"]) == 0
    assert cli.main(["report", str(out), "-q"]) == 0
    page = (out / "report.html").read_text()
    assert "<img src=x" not in page
    assert "<title>Virtual prototype: scenario &lt;img src=x onerror=alert(1)&gt;" in page
    assert page.count("data:image/png") == 1  # curves.png, shown once where report.md places it


def test_html_report_names_matrix_rows_and_columns_and_scrolls(tmp_path):
    from flexcal.validation.reports.html import render_run_folder

    names = [f"P{j}.x<0>" for j in range(45)]
    write_json(tmp_path / "report.json", {"names": names, "outputs": ["overall", "tx", "ty", "tz"],
                                          "ST": [[0.01 * j for j in range(45)]] * 4})
    (tmp_path / "report.md").write_text("# run\n\n[a link](javascript:alert(1))\n")
    page = render_run_folder(tmp_path)
    assert "<th>P44.x&lt;0&gt;</th>" in page and "<th>ty</th>" in page
    assert "<th>44</th>" not in page
    assert "overflow-x: auto" in page.split("</style>")[0]
    assert "javascript:" not in page


# ----------------------------------------------------------------------------------------
# progress off a terminal


def test_progress_off_a_terminal_is_one_line_per_stage(tmp_path):
    result = subprocess.run([*FLEXCAL, *TRUTH, "--out", str(tmp_path / "out")], capture_output=True, text=True,
                            cwd=tmp_path, timeout=WAIT_S)
    assert result.returncode == 0, result.stderr
    lines = result.stderr.strip().splitlines()
    assert [line.split("] ", 1)[1].split(",")[0] for line in lines] == ["prototype: started", "prototype: done"]
    assert all(line.startswith("[") and " s] " in line for line in lines)
    assert "\r" not in result.stderr  # no tqdm redraws in a log
    quiet = subprocess.run([*FLEXCAL, *TRUTH, "--out", str(tmp_path / "q"), "-q"], capture_output=True, text=True,
                           cwd=tmp_path, timeout=WAIT_S)
    assert quiet.returncode == 0 and quiet.stderr == ""


@pytest.fixture(autouse=True)
def _no_litter():
    before = set(os.listdir("."))
    yield
    assert "__tracked_surface.stl" not in set(os.listdir(".")) - before


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_parallel_fem_build_stopped_while_meshing_stops_at_once_and_leaves_no_mesher(tmp_path, signum):
    """A cold FEM truth on 2 local worker processes, stopped while both workers' fTetWild
    children mesh. Before: 4-5 Dask warning lines after the signal, 4 s of the nanny's
    graceful wait, and the children went on meshing after the command had ended, their
    temporary folders left behind. Now: one line, the children stopped with the jobs,
    nothing left in the temporary directory (TMPDIR of the run)."""
    import psutil

    temporary = tmp_path / "tmp"
    temporary.mkdir()
    env = {"FLEXCAL_CACHE_DIR": str(tmp_path / "cache"), "TMPDIR": str(temporary)}
    place = tmp_path / "place"  # holds only the working directory and --out
    work = place / "work"
    work.mkdir(parents=True)
    # fTetWild's children are what this stops (the default mapped mesher has none)
    run = Run(["truth", "--scenario", "table1", "--seed", "3", "--provider", "fem-tetwild", "--workers", "2",
               "--out", str(place / "out")], work, env)
    assert run.wait_for("FEM segments: 18 to build on 2 threads of this process"), run.lines

    def meshers() -> list:
        return [p for p in psutil.Process(run.process.pid).children(recursive=True)
                if "flexcal.fem.tetwild_process" in " ".join(p.cmdline())]

    deadline = time.monotonic() + WAIT_S
    while len(meshers()) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    children = meshers()
    assert len(children) == 2, run.lines
    time.sleep(1.0)  # past their imports (0.3 s idle), inside fTetWild (~8 s a leaf segment)
    n_lines = len(run.lines)
    start = time.monotonic()
    run.process.send_signal(signum)
    status = run.finish()
    # the nanny's graceful wait alone would be 4 s (measured with the children stopped: 0.8 s)
    assert time.monotonic() - start < 4.0
    _assert_stopped_cleanly(status, run.lines, place, work, signum)
    assert len(run.lines) == n_lines + 1, run.lines[n_lines:]  # the one line, no Dask warnings
    assert psutil.wait_procs(children, timeout=5)[1] == []  # 5 s: reaping on a loaded machine
    assert [p.name for p in temporary.iterdir() if p.name.startswith("flexcal-")] == []


@pytest.mark.slow
def test_finished_fem_chains_stay_cached_after_an_interrupt(tmp_path):
    # cold cache: the FEM truth builds its tied chains (by default on one thread per core;
    # until session 25 it built chain segments, whose "FEM segment [" line this test waited
    # for in vain since); stop it once the first one is reported, the others mid-build, then
    # every cache file must be whole and readable
    from flexcal.fem.cache import load_cached

    cache = tmp_path / "cache"
    status, lines, work = _interrupt_at(["truth", "--scenario", "table1", "--seed", "3"], tmp_path, "FEM tied chain (",
                                        signal.SIGINT, env={"FLEXCAL_CACHE_DIR": str(cache)})
    assert status == 130 and "interrupted" in lines[-1], lines
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache", "work"]  # no out, no staging folder
    files = sorted(cache.iterdir())
    assert files and all(p.suffix == ".npz" for p in files), files  # no temporaries left
    assert all(load_cached(p.stem, cache) is not None for p in files)


def test_force_never_empties_the_working_directory(tmp_path, monkeypatch, capsys):
    (tmp_path / "my-notes.txt").write_text("keep")
    monkeypatch.chdir(tmp_path)
    status = cli.main([*TRUTH, "--out", ".", "-q", "--force"])
    _one_line(capsys, status, 2, "--force would empty", "folder of its own")
    assert [p.name for p in tmp_path.iterdir()] == ["my-notes.txt"]


def test_an_error_caused_by_ctrl_c_counts_as_the_interrupt(tmp_path, capsys, monkeypatch):
    # Ctrl-C while an extension module initialises surfaces as ImportError('initialization
    # failed') raised from the KeyboardInterrupt (seen when truth was stopped while importing
    # its plotting modules): still exit 130 and the interrupt line, not 'internal error'
    from flexcal.validation.prototype import providers

    def interrupted_import(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as interrupt:
            raise ImportError("initialization failed") from interrupt

    monkeypatch.setattr(providers, "stiffness_provider", interrupted_import)
    status = cli.main([*TRUTH, "--out", str(tmp_path / "out")])
    _one_line(capsys, status, 130, "interrupted")
    assert list(tmp_path.iterdir()) == []


# a SIGTERM whose exception Python can only report as "ignored": raised inside a destructor, as
# it was inside VTK's DataObject.__del__ while the hinge's pictures rendered (the flaky
# test_hinge_terminated_while_rendering: the run went on and published its results with status 0)
SWALLOWED_IN_A_DESTRUCTOR = """
import signal, sys
import flexcal.validation.output as output

class SignalsWhenDropped:
    def __del__(self):
        signal.raise_signal(signal.SIGTERM)

write_report = output.write_report

def write_report_after_a_swallowed_signal(*args, **kwargs):
    SignalsWhenDropped()  # dropped at once: the handler's Terminated is raised inside __del__
    return write_report(*args, **kwargs)

output.write_report = write_report_after_a_swallowed_signal
from flexcal.validation.cli import main
sys.exit(main())
"""


def test_a_signal_swallowed_in_a_destructor_still_stops_the_run_before_out(tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    run = subprocess.run([sys.executable, "-c", SWALLOWED_IN_A_DESTRUCTOR, *TRUTH, "--out", str(tmp_path / "out")],
                         cwd=work, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=WAIT_S)
    lines = run.stderr.splitlines()
    assert not any("Exception ignored" in line for line in lines), lines  # recorded, not printed
    _assert_stopped_cleanly(run.returncode, lines, tmp_path, work, signal.SIGTERM)
