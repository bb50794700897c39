"""SIGINT (Ctrl-C) and SIGTERM for the command lines: stop cleanly, say so in one line.

A command line wraps its work in :func:`catch`; a caught signal then

- stops a running :class:`~dftc_mujoco.closed_loop.loop.Simulation` at its next control period
  (inside :meth:`Signals.stopping`: the run keeps its records);
- is only recorded inside :meth:`Signals.deferred` (work that must not be cut in
  two, or a loop that polls :attr:`Signals.signum` itself), and raised as
  :class:`Interrupted` when that block ends;
- raises :class:`Interrupted` at once anywhere else (setting up, drawing figures,
  rendering the video).

The command then exits with ``128 + signum``: 130 for SIGINT, 143 for SIGTERM.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

from ..errors import exit_interrupted

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(BaseException):
    """A SIGINT or SIGTERM asked the command to stop (a BaseException, like
    KeyboardInterrupt, so that ``except Exception`` does not swallow it)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def name(self) -> str:
        """SIGINT or SIGTERM."""
        return signal.Signals(self.signum).name

    @property
    def exit_code(self) -> int:
        """128 + the signal number: 130 for SIGINT, 143 for SIGTERM."""
        return exit_interrupted(self.signum)


class Signals:
    """What SIGINT / SIGTERM do while a command runs (see the module's docstring)."""

    def __init__(self) -> None:
        self.caught: list[int] = []
        self._sim: Any = None
        self._defer = 0
        self._previous: dict[int, Any] = {}

    @property
    def signum(self) -> int | None:
        """The first signal caught, or None."""
        return self.caught[0] if self.caught else None

    def install(self) -> None:
        """Install (or re-install, after a library replaced them) the handlers."""
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in SIGNALS:
            old = signal.signal(sig, self._handle)
            self._previous.setdefault(sig, old)

    def restore(self) -> None:
        """Put back the handlers that were there before :meth:`install`."""
        for sig, old in self._previous.items():
            signal.signal(sig, old)
        self._previous.clear()

    def _handle(self, signum: int, frame: Any) -> None:
        self.caught.append(signum)
        if self._sim is not None:
            self._sim.request_stop(f"interrupted by {signal.Signals(signum).name}")
        elif not self._defer and len(self.caught) == 1:
            raise Interrupted(signum)

    def check(self) -> None:
        """Raise :class:`Interrupted` if a signal was caught."""
        if self.caught:
            raise Interrupted(self.caught[0])

    @contextlib.contextmanager
    def deferred(self, check: bool = True) -> Iterator[Signals]:
        """Inside, a signal is only recorded; it is raised when the block ends if
        ``check`` (else the caller looks at :attr:`signum`)."""
        self._defer += 1
        try:
            yield self
        finally:
            self._defer -= 1
        if check and not self._defer:
            self.check()

    @contextlib.contextmanager
    def active(self) -> Iterator[Signals]:
        """Inside (within a :meth:`deferred` block), a signal raises at once again."""
        saved, self._defer = self._defer, 0
        try:
            if self.caught:
                self.check()
            yield self
        finally:
            self._defer = saved

    @contextlib.contextmanager
    def stopping(self, sim: Any) -> Iterator[Signals]:
        """Inside, a signal asks ``sim`` to stop at its next control period."""
        previous, self._sim = self._sim, sim
        try:
            if self.caught:
                sim.request_stop(f"interrupted by {signal.Signals(self.caught[0]).name}")
            yield self
        finally:
            self._sim = previous


@contextlib.contextmanager
def catch() -> Iterator[Signals]:
    """Handle SIGINT and SIGTERM as :class:`Signals` says while inside."""
    signals = Signals()
    signals.install()
    try:
        yield signals
    finally:
        signals.restore()


def guarded(body: Callable[[Signals], int], said: str) -> int:
    """A command's ``body(signals)`` under :func:`catch`, its work deferring signals; a
    signal that stops it prints "interrupted by NAME" + ``said`` and gives 130 / 143."""
    with catch() as signals:
        try:
            with signals.deferred(check=False):
                return body(signals)
        except Interrupted as exc:
            print(f"interrupted by {exc.name}{said}", file=sys.stderr)
            return exc.exit_code
        except Exception:
            if not signals.caught:
                raise
            # the signal surfaced wrapped: raised inside a ctypes call's argument conversion
            # (an EGL call while rendering) it arrives as ctypes.ArgumentError
            wrapped = Interrupted(signals.caught[0])
            print(f"interrupted by {wrapped.name}{said}", file=sys.stderr)
            return wrapped.exit_code
