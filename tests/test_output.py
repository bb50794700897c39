"""Run folders: never overwritten silently, never mixed, never half-written."""

import json
import os
import signal
import subprocess
import sys
import time

from dftc_mujoco import run


def _run(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "dftc_mujoco.run", "paper_case", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=cwd,
    )


def test_an_existing_run_is_refused_then_replaced_as_a_whole(tmp_path, capsys):
    out = tmp_path / "run"
    common = ["paper_case", "--duration", "1", "--no-video", "--no-progress", "--out", str(out)]
    assert run.main([*common, "--seed", "1"]) == 0
    (out / "notes.txt").write_text("mine")
    before = (out / "summary.json").read_text()
    capsys.readouterr()
    # a second run into the same folder: refused before simulating, nothing touched
    assert run.main([*common, "--seed", "2"]) == 5
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "holds another run; use --overwrite" in errors[0]
    assert (out / "summary.json").read_text() == before and (out / "notes.txt").exists()
    # --overwrite replaces the folder as a whole: the old extra file is gone
    assert run.main([*common, "--seed", "2", "--overwrite"]) == 0
    assert json.loads((out / "summary.json").read_text())["seed"] == 2
    assert not (out / "notes.txt").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no temp or lock left


def test_a_folder_that_is_not_a_run_is_never_replaced(tmp_path, capsys):
    (tmp_path / "thesis.tex").write_text("precious")
    for extra in ([], ["--overwrite"]):
        code = run.main(
            ["paper_case", "--duration", "1", "--no-video", "--out", str(tmp_path), *extra]
        )
        assert code == 5
        assert "holds no run" in capsys.readouterr().err
    assert (tmp_path / "thesis.tex").read_text() == "precious"
    (tmp_path / "file").write_text("x")
    assert run.main(["paper_case", "--no-video", "--out", str(tmp_path / "file")]) == 5
    assert "names a file, not a folder" in capsys.readouterr().err


def test_a_second_process_on_the_same_folder_is_refused(tmp_path):
    """Two runs into one --out used to interleave their files (one video alternating
    between two seeds); now the second is refused with one line while the first writes,
    and the first lands whole."""
    out = tmp_path / "run"
    first = subprocess.Popen(
        [
            *(sys.executable, "-m", "dftc_mujoco.run", "paper_case", "--duration", "3000"),
            *("--no-video", "--no-progress", "--out", str(out)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lock = tmp_path / ".run.lock"
        for _ in range(300):
            if lock.exists() and lock.read_text().strip():
                break
            time.sleep(0.1)
        assert lock.read_text().strip() == str(first.pid)
        second = _run("--duration", "1", "--no-video", "--out", str(out), "--overwrite")
        assert second.returncode == 5
        assert f"another run (process {first.pid}) is writing this folder" in second.stderr
        assert not out.exists()  # nothing half-written appears at the destination
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=60)
    assert first.returncode == 130
    assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_killed_run_leaves_no_half_written_folder_and_its_lock_is_taken_over(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [
            *(sys.executable, "-m", "dftc_mujoco.run", "paper_case", "--duration", "3000"),
            *("--no-video", "--no-progress", "--out", str(out)),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    time.sleep(5.0)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert not out.exists()  # only a private .run.*.tmp folder and a stale lock remain
    names = [p.name for p in tmp_path.iterdir()]
    assert ".run.lock" in names and all(n.startswith(".run.") for n in names)
    again = _run("--duration", "1", "--no-video", "--out", str(out))
    assert again.returncode == 0, again.stderr
    assert json.loads((out / "summary.json").read_text())["status"] == "ok"


def test_outputs_default_to_renders_in_the_working_directory(tmp_path):
    done = _run("--duration", "1", "--no-video", "--no-progress", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "renders" / "paper_case" / "summary.json").is_file()
