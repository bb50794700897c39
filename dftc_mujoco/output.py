"""Run folders that are never mixed, half-written or silently replaced.

A run writes into a private folder beside its destination
(``.<name>.<random>.tmp``) and moves it into place only at the end, so a
reader sees either the previous folder or the complete new one. A destination
that holds another run is refused unless ``overwrite`` (which then replaces it
as a whole); a folder that is not a run folder is never replaced. A lock file
beside the destination refuses a second process while the first writes.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from .errors import DftcError

RUN_FILES = ("summary.json", "log.npz", "scenario.toml")


class OutputError(DftcError):
    """The output folder cannot be used (exists, locked, not writable, no space)."""


def _holds_a_run(folder: Path) -> bool:
    return any((folder / name).exists() for name in RUN_FILES)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def check_destination(out: Path, overwrite: bool) -> Path:
    """The absolute destination, or an OutputError saying why it cannot be used."""
    out = Path(out).absolute()
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: --out names a file, not a folder; choose a folder")
    if out.is_dir() and any(out.iterdir()):
        if not _holds_a_run(out):
            raise OutputError(
                f"{out}: the folder is not empty and holds no run; choose another --out "
                "(it is never replaced, even with --overwrite)"
            )
        if not overwrite:
            raise OutputError(
                f"{out}: holds another run; use --overwrite to replace it as a whole, "
                "or choose another --out"
            )
    return out


@contextlib.contextmanager
def run_folder(out: Path, overwrite: bool = False) -> Iterator[Path]:
    """A private work folder for a run to write into; moved to ``out`` when the block
    ends normally, removed if it raises. Refuses (OutputError) a destination that
    holds another run (unless ``overwrite``), is not a run folder, or is being
    written by another process."""
    out = check_destination(out, overwrite)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{out.parent}: cannot create the folder: {exc.strerror}") from None
    lock = out.parent / f".{out.name}.lock"
    _acquire(lock, out)
    try:
        try:
            work = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
        except OSError as exc:
            raise OutputError(f"{out.parent}: cannot write there: {exc.strerror}") from None
        try:
            yield work
            _move_into_place(work, out, overwrite)
        finally:
            shutil.rmtree(work, ignore_errors=True)
    finally:
        lock.unlink(missing_ok=True)


def _acquire(lock: Path, out: Path) -> None:
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                pid = int(lock.read_text().strip() or 0)
            except (OSError, ValueError):
                pid = 0
            if pid and _alive(pid):
                raise OutputError(
                    f"{out}: another run (process {pid}) is writing this folder; wait for it "
                    "or choose another --out"
                ) from None
            lock.unlink(missing_ok=True)  # left by a process that died: take it over
            continue
        except OSError as exc:
            raise OutputError(f"{out.parent}: cannot write there: {exc.strerror}") from None
        with os.fdopen(fd, "w") as fh:
            fh.write(str(os.getpid()))
        return
    raise OutputError(f"{out}: cannot lock the folder ({lock})")


def _move_into_place(work: Path, out: Path, overwrite: bool) -> None:
    """Rename ``work`` to ``out``; an existing ``out`` is set aside first and removed after."""
    out = check_destination(out, overwrite)  # nothing else appeared there meanwhile
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
        os.rmdir(old)
        os.rename(out, old)
    os.rename(work, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def free_space_check(work: Path, needed: int) -> None:
    """OutputError when the disk holding ``work`` has less than ``needed`` bytes free."""
    free = shutil.disk_usage(work).free
    if needed > free:
        raise OutputError(
            f"{work.parent}: {needed / 2**20:.0f} MB may be needed for the records and only "
            f"{free / 2**20:.0f} MB are free; free some space, shorten the run, lower "
            "physics.log_rate or choose another --out"
        )
