"""Run folders: never overwritten silently, never mixed, never half-written."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from dftc_mujoco import open_run, plot, run
from dftc_mujoco.runtime.output import OWNER
from tests.conftest import needs_gl


def _run(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "dftc_mujoco.run", "paper_case", *args],
        capture_output=True,
        text=True,
        timeout=900,
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
        assert f"another process ({first.pid}) is writing this folder" in second.stderr
        assert not out.exists()  # nothing half-written appears at the destination
    finally:
        first.send_signal(signal.SIGINT)
        _, err = first.communicate(timeout=900)
    assert first.returncode == 130
    if "before the run started: nothing was written" in err:
        # stopped while it still compiled or built (a cold cache): no folder, nothing half
        assert sorted(p.name for p in tmp_path.iterdir()) == []
    else:
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
    proc.wait(timeout=900)
    assert not out.exists()  # only a private .run.*.tmp folder and a stale lock remain
    names = [p.name for p in tmp_path.iterdir()]
    assert ".run.lock" in names and all(n.startswith(".run.") for n in names)
    again = _run("--duration", "1", "--no-video", "--out", str(out))
    assert again.returncode == 0, again.stderr
    assert json.loads((out / "summary.json").read_text())["status"] == "ok"
    # the killed run's private folder (its owner is dead) went with the next run
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_outputs_default_to_renders_in_the_working_directory(tmp_path):
    done = _run("--duration", "1", "--no-video", "--no-progress", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "renders" / "paper_case" / "summary.json").is_file()


def test_only_private_folders_of_dead_owners_are_removed(tmp_path):
    """A run cleans up what killed runs left beside its destination, and nothing else."""
    dead = subprocess.Popen(["true"])
    dead.wait()
    stale = tmp_path / ".run.abcd1234.tmp"
    busy = tmp_path / ".run.efgh5678.tmp"  # a live process owns it
    other = tmp_path / ".run.x.ijkl9012.tmp"  # another destination's (run.x)
    for folder, pid in ((stale, dead.pid), (busy, os.getpid()), (other, dead.pid)):
        folder.mkdir()
        (folder / OWNER).write_text(str(pid))
        (folder / "log.npz").write_text("half")
    done = _run("--duration", "1", "--no-video", "--out", str(tmp_path / "run"))
    assert done.returncode == 0, done.stderr
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [".run.efgh5678.tmp", ".run.x.ijkl9012.tmp", "run"]
    assert not (tmp_path / "run" / OWNER).exists()


def _video_run(out: Path, duration: str = "60") -> subprocess.Popen:
    return subprocess.Popen(
        [
            *(sys.executable, "-m", "dftc_mujoco.run", "paper_case", "--duration", duration),
            *("--no-progress", "--out", str(out)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for(pattern: str, folder: Path, proc: subprocess.Popen, timeout: float = 900) -> Path:
    deadline = time.time() + timeout
    while time.time() < deadline and proc.poll() is None:
        found = sorted(folder.glob(pattern))
        if found:
            return found[0]
        time.sleep(0.02)
    raise AssertionError(f"{pattern} never appeared in {folder}")


@needs_gl
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_a_signal_during_the_video_leaves_no_tmp_file(tmp_path, sig):
    """SIGTERM while the video renders: the records and figures land, no video and no
    temporary file; SIGKILL: the records are at --out already (moved there before the
    drawing), and the next process on that --out removes the unfinished drawing."""
    out = tmp_path / "run"
    proc = _video_run(out)
    _wait_for(".run.*.tmp/.video.mp4.tmp.mp4", tmp_path, proc)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=900)
    if sig == signal.SIGTERM:
        assert proc.returncode == 143, err
        assert "Traceback" not in err
        assert "interrupted by SIGTERM while drawing: the records and figures are in" in err
        assert sorted(p.name for p in out.iterdir()) == [
            "figures",
            "log.npz",
            "scenario.toml",
            "summary.json",
        ]
        assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    else:
        assert proc.returncode == -signal.SIGKILL
        assert sorted(p.name for p in out.iterdir()) == ["log.npz", "scenario.toml", "summary.json"]
        assert open_run(out).summary["simulated_time"] > 1.0
        assert len([p for p in tmp_path.iterdir() if p.name.startswith(".run.")]) == 2
        plot = subprocess.run(
            [sys.executable, "-m", "dftc_mujoco.plot", str(out), "--no-video"],
            capture_output=True,
            text=True,
        )
        assert plot.returncode == 0, plot.stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # lock and folder gone
        assert (out / "figures").is_dir()
    assert not [p for p in tmp_path.rglob("*") if ".tmp" in p.name]


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("saved") / "run"
    assert run.main(["paper_case", "--duration", "4", "--no-video", "--out", str(out)]) == 0
    return out


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()
    }


@pytest.mark.parametrize("damage", ["truncated", "garbage", "not_a_log"])
def test_plot_on_a_damaged_log_is_one_line_exit_2(saved_run, tmp_path, capsys, damage):
    folder = tmp_path / "run"
    shutil.copytree(saved_run, folder)
    log = folder / "log.npz"
    if damage == "truncated":
        log.write_bytes(log.read_bytes()[: log.stat().st_size // 2])
    elif damage == "garbage":
        log.write_bytes(os.urandom(4000))
    else:
        with zipfile.ZipFile(log, "w") as z:
            z.writestr("t.npy", b"nonsense")
    before = _snapshot(folder)
    assert plot.main([str(folder)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {log}:"), err
    assert _snapshot(folder) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


@pytest.fixture
def small_disk(tmp_path):
    """A 64 MB tmpfs that a test can fill (needs root, as in CI; skipped otherwise)."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs for a full disk needs root (CI runs as root)")
    mnt = tmp_path / "disk"
    mnt.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=64m", "tmpfs", str(mnt)],
        capture_output=True,
        text=True,
    )
    if done.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def _fill(disk: Path, leave: int = 0) -> None:
    """Fill ``disk`` up, then give back ``leave`` bytes."""
    filler = disk / "filler"
    # unbuffered: a buffered file that hit ENOSPC raises again when it is closed
    with open(filler, "wb", buffering=0) as fh:
        chunk = b"\0" * 2**16
        try:
            while True:
                fh.write(chunk)
        except OSError:
            pass
    os.truncate(filler, max(0, filler.stat().st_size - leave))


@needs_gl
def test_a_full_disk_while_drawing_is_exit_5_and_keeps_the_records(small_disk):
    """The disk fills up after the records are written: exit 5 ("output/disk/OS"), not 2
    ("bad input"), one error line, the records and whatever was complete kept."""
    out = small_disk / "run"
    proc = _video_run(out, duration="20")
    _wait_for(".run.*.tmp/figures/fig10_inputs.png", small_disk, proc)
    _fill(small_disk)
    _, err = proc.communicate(timeout=900)
    assert proc.returncode == 5, err
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "no space left on the device" in errors[0], err
    assert "Traceback" not in err and "FFMPEG" not in err
    assert (out / "summary.json").is_file() and not (out / "video.mp4").exists()
    assert not [p for p in small_disk.rglob("*") if ".tmp" in p.name]


@needs_gl
@pytest.mark.parametrize("video", [False, True])
def test_plot_on_a_full_disk_leaves_the_old_figures(saved_run, small_disk, capsys, video):
    folder = small_disk / "run"
    shutil.copytree(saved_run, folder)
    before = _snapshot(folder)
    _fill(small_disk, leave=64 * 1024)  # room for the lock and a private folder, not figures
    assert plot.main([str(folder), *(["--video"] if video else [])]) == 5
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if line.startswith("error:")]
    assert len(errors) == 1 and "no space left on the device" in errors[0], err
    assert _snapshot(folder) == before  # old figures untouched, no video
    assert sorted(p.name for p in small_disk.iterdir()) == ["filler", "run"]


@needs_gl
def test_plot_replaces_figures_and_video_only_when_complete(tmp_path):
    """SIGTERM in the middle of `plot --video`: the run folder is exactly as before;
    a complete plot then replaces the figures as a whole and adds the video."""
    folder = tmp_path / "run"
    assert run.main(["paper_case", "--duration", "60", "--no-video", "--out", str(folder)]) == 0
    before = _snapshot(folder)
    proc = subprocess.Popen(
        [sys.executable, "-m", "dftc_mujoco.plot", str(folder), "--video"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait_for(".run.*.tmp/.video.mp4.tmp.mp4", tmp_path, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=900)
    assert proc.returncode == 143 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1].startswith("interrupted by SIGTERM")
    assert _snapshot(folder) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_signal_while_the_run_is_built_writes_nothing(tmp_path):
    """SIGINT as soon as the run holds its folder (the simulation is still being built):
    the run stops before its first period, says that nothing ran, and leaves neither a run
    folder nor its lock."""
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
    lock = tmp_path / ".run.lock"
    for _ in range(300):
        if lock.exists() and lock.read_text().strip():
            break
        time.sleep(0.01)
    first.send_signal(signal.SIGINT)
    _, err = first.communicate(timeout=900)
    assert first.returncode == 130 and "Traceback" not in err
    assert "before the run started: nothing was written" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == [], list(tmp_path.iterdir())
