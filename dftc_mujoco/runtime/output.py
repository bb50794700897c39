"""Output folders that are never mixed, half-written or silently replaced.

A run writes into a private folder beside its destination
(``.<name>.<random>.tmp``, with its owner's process id in ``.owner`` inside) and
moves it into place only at the end, so a reader sees either the previous folder or
the complete new one. A destination that holds another run is refused unless
``overwrite`` (which then replaces it as a whole); a folder that is not a run folder
is never replaced. A lock file beside the destination (``.<name>.lock``) refuses a
second process while the first writes (runs, ``plot`` and campaigns alike).

Whoever takes the lock first removes the private folders that killed processes left
beside the destination (only those whose owner is dead), and puts back a destination
that a process killed in the middle of a replacement had set aside.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import os
import re
import shutil
import stat
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from ..errors import OutputError

RUN_FILES = ("summary.json", "log.npz", "scenario.toml")
OWNER = ".owner"  # inside a private folder: "<pid> <process start time>"
PUBLISHED = ".published"  # inside a private folder whose records are already at --out


def os_problem(exc: OSError, what: str, where: Path | str | None = None) -> OutputError:
    """An OutputError (one line) for an OSError met while doing ``what`` (naming
    ``where``, default the file the error names); a full disk says so and how to get
    out of it."""
    where = str(where or exc.filename or "")
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return OutputError(
            f"{where}: no space left on the device while {what}; free some space or "
            "choose another --out".lstrip(": ")
        )
    lines = (exc.strerror or str(exc)).strip().splitlines()
    reason = lines[0] if lines else type(exc).__name__
    return OutputError(f"{where}: {what}: {reason}".lstrip(": "))


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


def _started(pid: int) -> str:
    """When process ``pid`` started (clock ticks since boot, Linux), or '' if unknown:
    tells a live owner from a new process that reuses its id."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return ""
    return stat.rsplit(")", 1)[-1].split()[19]


def _owner_alive(folder: Path) -> bool:
    """Whether the process recorded in ``folder/.owner`` still runs (True when unknown)."""
    try:
        pid_text, _, started = (folder / OWNER).read_text().strip().partition(" ")
        pid = int(pid_text)
    except (OSError, ValueError):
        return True  # no owner recorded (yet): leave it alone
    if not _alive(pid):
        return False
    now = _started(pid)
    return not (started and now and now != started)


def special_file(folder: Path) -> str | None:
    """The first entry of ``folder`` (not recursive) that is neither a regular file nor a
    folder, in words ("results.jsonl is a FIFO"), or None. Opening a FIFO waits for a
    writer forever, a device reads without end: a run or campaign folder is never opened
    with one in it."""
    kinds = {
        stat.S_IFIFO: "a FIFO (named pipe)",
        stat.S_IFCHR: "a character device",
        stat.S_IFBLK: "a block device",
        stat.S_IFSOCK: "a socket",
    }
    try:
        entries = sorted(folder.iterdir())
    except OSError:
        return None
    for entry in entries:
        try:
            mode = entry.stat().st_mode  # a link is judged by what it points to
        except OSError:
            continue  # a dangling link opens nothing
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            return f"{entry.name} is {kinds.get(stat.S_IFMT(mode), 'not a regular file')}"
    return None


def destination(out: Path | str) -> Path:
    """``out`` as an absolute path with ``.`` and ``..`` taken as the shell takes them
    (``p/new/..`` is ``p``, whether ``p/new`` exists or not); OutputError for a path that
    names no folder a run can be moved to (``/``)."""
    path = Path(os.path.normpath(Path(out).absolute()))
    if path.name in ("", ".", ".."):
        raise OutputError(f"{out}: --out must name a folder below an existing one, not {path}")
    return path


def check_destination(out: Path, overwrite: bool) -> Path:
    """The absolute destination, or an OutputError saying why it cannot be used."""
    out = destination(out)
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
def locked(out: Path) -> Iterator[Path]:
    """Hold the lock of destination ``out`` (``.<name>.lock`` beside it) while inside,
    after tidying what killed writers left beside it; yields the absolute ``out``.

    Raises OutputError when another live process holds the lock or the parent folder
    cannot be created or written.
    """
    out = destination(out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise os_problem(exc, "creating the folder") from None
    lock = out.parent / f".{out.name}.lock"
    _acquire(lock, out)
    try:
        tidy(out)
        yield out
    finally:
        lock.unlink(missing_ok=True)


def _private_name(out: Path) -> re.Pattern[str]:
    # tempfile's names: 8 characters from [a-z0-9_]; ".<name>.x.abcdefgh.tmp" is another
    # destination's (named "<name>.x"), not this one's
    return re.compile(rf"^\.{re.escape(out.name)}\.[a-z0-9_]{{8}}\.(tmp|old)$")


def tidy(out: Path) -> list[Path]:
    """Remove the private folders of dead writers beside ``out`` and put back a
    destination left set aside by a replacement that was killed half-way (call with the
    lock held). A dead writer's folder that holds finished records (``summary.json``: a
    run killed while drawing its figures or video) is never removed: it is kept beside
    ``out`` as ``<name>.recovered-<k>`` and said on stderr. Returns what was removed."""
    pattern = _private_name(out)
    try:
        beside = [p for p in out.parent.iterdir() if pattern.match(p.name) and p.is_dir()]
    except OSError:
        return []
    removed = []
    for p in sorted(beside, key=lambda p: p.stat().st_mtime, reverse=True):
        if p.name.endswith(".old"):
            if not out.exists():  # killed between setting the old one aside and the swap
                os.rename(p, out)
                continue
        elif _owner_alive(p):
            continue
        elif (p / "summary.json").is_file():
            _recover(p, out)
            continue
        shutil.rmtree(p, ignore_errors=True)
        removed.append(p)
    return removed


def _recover(work: Path, out: Path) -> Path:
    """Keep the finished records a killed writer left in ``work`` as a run folder beside
    ``out`` (its unfinished figures or video dropped); says where on stderr."""
    for tmp in [*work.glob(".*.tmp*"), work / OWNER]:
        tmp.unlink(missing_ok=True)
    k = 1
    while (kept := out.parent / f"{out.name}.recovered-{k}").exists():
        k += 1
    os.rename(work, kept)
    print(
        f"note: a run writing {out} was killed after its records were written (while "
        f"drawing); they are kept in {kept} (python -m dftc_mujoco.plot {kept} draws the rest)",
        file=sys.stderr,
    )
    return kept


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def private_folder(out: Path) -> Path:
    """A new private folder beside ``out``, owned (``.owner``) by this process."""
    try:
        work = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
        os.chmod(work, 0o777 & ~_umask())  # a run folder as mkdir makes it, not mkdtemp's 0700
        (work / OWNER).write_text(f"{os.getpid()} {_started(os.getpid())}")
    except OSError as exc:
        raise os_problem(exc, "creating a private folder") from None
    return work


@contextlib.contextmanager
def run_folder(out: Path, overwrite: bool = False) -> Iterator[Path]:
    """A private work folder for a run to write into; moved to ``out`` when the block
    ends normally, removed if it raises. Refuses (OutputError) a destination that
    holds another run (unless ``overwrite``), is not a run folder, or is being
    written by another process. After :func:`publish` (the records moved into place
    early), what the folder holds when the block ends joins them, each item whole."""
    out = check_destination(out, overwrite)
    with locked(out):
        work = private_folder(out)
        try:
            yield work
            if (work / PUBLISHED).exists():
                (work / PUBLISHED).unlink()
                (work / OWNER).unlink(missing_ok=True)
                replace_into(work, out, sorted(p.name for p in work.iterdir()))
            else:
                _move_into_place(work, out, overwrite)
        finally:
            shutil.rmtree(work, ignore_errors=True)


def publish(work: Path, out: Path, overwrite: bool) -> None:
    """Move a run's finished records from its private folder ``work`` into place at ``out``
    now (inside :func:`run_folder`, with its lock), and leave ``work`` as a new, empty
    private folder for what is drawn from them (figures, video): a process killed while
    drawing, even by SIGKILL, leaves the records at ``out``, never only in a hidden
    folder."""
    _move_into_place(work, out, overwrite)
    try:
        work.mkdir()
        os.chmod(work, 0o777 & ~_umask())
        (work / OWNER).write_text(f"{os.getpid()} {_started(os.getpid())}")
        (work / PUBLISHED).write_text("")
    except OSError as exc:
        raise os_problem(exc, "creating a private folder") from None


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
                    f"{out}: another process ({pid}) is writing this folder; wait for it "
                    "or choose another --out"
                ) from None
            lock.unlink(missing_ok=True)  # left by a process that died: take it over
            continue
        except OSError as exc:
            raise os_problem(exc, "writing the lock file") from None
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(str(os.getpid()))
        except OSError as exc:
            lock.unlink(missing_ok=True)
            raise os_problem(exc, "writing the lock file", where=out) from None
        return
    raise OutputError(f"{out}: cannot lock the folder ({lock})")


def _move_into_place(work: Path, out: Path, overwrite: bool) -> None:
    """Rename ``work`` to ``out``; an existing ``out`` is set aside first and removed after."""
    out = check_destination(out, overwrite)  # nothing else appeared there meanwhile
    (work / OWNER).unlink(missing_ok=True)
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
        os.rmdir(old)
        os.rename(out, old)
    os.rename(work, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


_RENAME_EXCHANGE = 2


def exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux ``renameat2(RENAME_EXCHANGE)``); False when the
    system cannot, so that the caller falls back to two renames."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    done = renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
    return done == 0


def replace_into(work: Path, out: Path, names: list[str]) -> None:
    """Move each of ``names`` from ``work`` into ``out``, replacing what is there: a file
    with one rename, a folder by swapping the two folders (the old one ends in ``work``,
    removed with it). Each item appears whole or not at all."""
    for name in names:
        new, old = work / name, out / name
        if new.is_dir() and old.is_dir():
            if not exchange(new, old):
                aside = work / f".{name}.old"
                os.rename(old, aside)
                os.rename(new, old)
        else:
            if old.is_dir():
                shutil.rmtree(old)
            os.replace(new, old)


def free_space_check(work: Path, needed: int) -> None:
    """OutputError when the disk holding ``work`` has less than ``needed`` bytes free."""
    free = shutil.disk_usage(work).free
    if needed > free:
        raise OutputError(
            f"{work.parent}: {needed / 2**20:.0f} MB may be needed for the records and only "
            f"{free / 2**20:.0f} MB are free; free some space, shorten the run, lower "
            "physics.log_rate or choose another --out"
        )
