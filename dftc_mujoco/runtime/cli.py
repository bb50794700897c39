"""What every command line shares: its program name in help and ``--version``, its
one-line errors, and the notice that the onboard code is being compiled."""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path
from typing import TextIO

from .. import __version__
from ..errors import DftcError


def prog(module: str, script: str) -> str:
    """``script`` (e.g. ``dftc-run``) when run as the installed command, else
    ``python -m module``, so that help and errors name what the user typed."""
    return script if Path(sys.argv[0]).name == script else f"python -m {module}"


def parser(
    module: str, script: str, description: str, epilog: str | None = None
) -> argparse.ArgumentParser:
    """An ArgumentParser with the right program name and ``--version``; ``epilog`` (examples
    and where the documentation is) is printed after the options as it is written."""
    p = argparse.ArgumentParser(
        prog=prog(module, script),
        description=description,
        epilog=epilog,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


def stray_arguments(extra: list[str], overrides: list[str]) -> str:
    """The message for arguments the parser did not expect; where one follows a ``--set``
    given without ``=`` (``--set gains.ko 3``), it says how to write it."""
    loose = [item for item in overrides if "=" not in item]
    if loose and extra:
        return (
            f"--set {loose[0]} {extra[0]}: write KEY=VALUE as one word, with no space around "
            f"'=' (--set {loose[0]}={extra[0]})"
        )
    return f"unrecognized arguments: {' '.join(extra)}"


def print_error(exc: BaseException) -> None:
    """One ``error:`` line on stderr per problem the exception reports."""
    for line in str(exc).splitlines() or [type(exc).__name__]:
        print(f"error: {line}", file=sys.stderr)


def fail(exc: DftcError) -> int:
    """Print ``exc`` as :func:`print_error` does; return its exit code (``errors.py``)."""
    print_error(exc)
    return exc.exit_code


def add_set_option(p: argparse.ArgumentParser, what: str) -> None:
    """``--set KEY=VALUE`` (repeatable, into ``args.overrides``): a scenario key by dotted
    path, the value in TOML syntax; ``what`` completes the help."""
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"override a key of {what} by dotted path, value in TOML syntax "
        "(e.g. --set gains.ko=3 --set mission.formation.side=1.0); repeatable",
    )


class CompileNotice:
    """Says on ``stream`` that the onboard code is being compiled, while it is.

    numba compiles the onboard code the first time a machine runs it (tens of seconds) and
    keeps it in its cache; without a word a person cannot tell that from a hang. A watcher
    thread reads the process's compile clock (:func:`~.numba_cache.clock`) and, once a
    compilation has gone on for ``after`` seconds, prints one line; on a terminal
    (``live``) it keeps the seconds on that line up to date until the notice is closed
    (leaving the context), and then ends the line with the time spent. Wrap it around the
    work that compiles (a run's set-up and its first period): what compiles later is
    short, and counted in the run's summary only."""

    TEXT = "compiling the onboard code for this machine (once: later runs reuse it)"

    def __init__(self, stream: TextIO | None = None, live: bool | None = None, after: float = 0.5):
        from . import numba_cache

        self.stream = stream if stream is not None else sys.stderr
        self.live = self.stream.isatty() if live is None else live
        self.after = after
        self.said = False
        self._clock = numba_cache.clock()
        self._start = 0.0
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._watch, name="compile-notice", daemon=True)

    def __enter__(self) -> CompileNotice:
        self._start = self._clock.total()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop watching; on a terminal, end the line with the time spent (once)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join()
        if self.said and self.live:
            spent = self._clock.total() - self._start
            self._write(f"\r\x1b[K{self.TEXT}: done in {spent:.1f} s\n")

    def _watch(self) -> None:
        while not self._stop.wait(0.25):
            since = self._clock.since
            compiling = since is not None and time.perf_counter() - since >= self.after
            if compiling and not self.said:
                self.said = True
                self._write(f"{self.TEXT} ..." + ("" if self.live else "\n"))
            elif compiling and self.live:
                spent = self._clock.total() - self._start
                self._write(f"\r\x1b[K{self.TEXT} ... {spent:.0f} s")

    def _write(self, text: str) -> None:
        with self._lock:
            try:
                self.stream.write(text)
                self.stream.flush()
            except (OSError, ValueError):  # a closed or broken stream: nothing to say it on
                self._stop.set()
