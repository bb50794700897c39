"""numba's on-disk cache, emptied when any source of the package changed.

numba keys a cached function on its own file only: a compiled caller keeps the code of the
callees it was compiled with, even after a callee's file (or a record type it passes)
changed. After an update in place (``git pull`` on an editable install, say) a stale caller
can compute with old code, or crash the process outright (a segmentation fault when a
record's fields changed). :func:`refresh` compares the package's sources (names, sizes,
modification times) with a stamp kept beside the caches and removes every cached function
when they differ; numba then compiles afresh, once.
"""

from __future__ import annotations

import hashlib
import os
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

STAMP = "numba_sources.stamp"


def sources_digest(package: Path) -> str:
    """A digest of every ``.py`` file under ``package``: name, size and modification time."""
    h = hashlib.sha1()
    for path in sorted(package.rglob("*.py")):
        st = path.stat()
        h.update(f"{path.relative_to(package)}:{st.st_size}:{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def refresh(package: Path) -> bool:
    """Remove numba's cached functions under ``package`` if its sources changed since the
    stamp was written; returns whether it did. A read-only install is left as it is."""
    try:
        digest = sources_digest(package)
        stamp = package / "__pycache__" / STAMP
        if stamp.is_file() and stamp.read_text() == digest:
            return False
        for pattern in ("*.nbi", "*.nbc"):
            for cached in package.rglob(f"__pycache__/{pattern}"):
                cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest)
        return True
    except OSError:
        return False


class CompileClock:
    """The seconds numba has spent compiling in this process, counted as it happens.

    A listener on numba's ``numba:compile`` events: the outermost compilation of each
    burst is timed (a function's callees compile inside it). :attr:`since` is when the
    compilation now under way began (None: none is), for a progress display in another
    thread. Compilations run one at a time (numba holds a lock around them)."""

    def __init__(self) -> None:
        self.seconds = 0.0  # finished compilations
        self.since: float | None = None
        self.functions = 0  # outermost functions compiled
        self._depth = 0

    def total(self) -> float:
        """Seconds spent compiling so far, the one under way included."""
        since = self.since
        return self.seconds + (0.0 if since is None else time.perf_counter() - since)

    def _started(self) -> None:
        if self._depth == 0:
            self.since = time.perf_counter()
        self._depth += 1

    def _ended(self) -> None:
        self._depth -= 1
        if self._depth == 0 and self.since is not None:
            self.seconds += time.perf_counter() - self.since
            self.functions += 1
            self.since = None


_CLOCK: CompileClock | None = None


def clock() -> CompileClock:
    """The process's :class:`CompileClock` (listening from the first call on)."""
    global _CLOCK
    if _CLOCK is None:
        from numba.core import event

        watch = CompileClock()

        class _Listener(event.Listener):
            def on_start(self, ev: event.Event) -> None:
                watch._started()

            def on_end(self, ev: event.Event) -> None:
                watch._ended()

        event.register("numba:compile", _Listener())
        _CLOCK = watch
    return _CLOCK


def is_cached(dispatcher: Any) -> bool:
    """Whether ``dispatcher`` (a ``numba.njit(cache=True)`` function) has machine code ready:
    compiled in this process, or in numba's on-disk cache (its index file exists). A signature
    the cache does not hold yet still compiles at the first call; this only tells a cold
    cache from a warm one without compiling anything."""
    if dispatcher.overloads:
        return True
    folder = Path(dispatcher.stats.cache_path)
    func = dispatcher.py_func
    name = f"{func.__module__.rsplit('.', 1)[-1]}.{func.__qualname__}-"
    return any(p.stat().st_size > 0 for p in folder.glob(f"{name}*.nbi"))


def unwritable_note(package: Path) -> str | None:
    """None when numba can keep its cache of this package's compiled code; else one line
    that says where it cannot, what that costs and how to fix it. Beside the sources
    (``__pycache__``) first, else numba's own folder in the user's cache (or
    ``NUMBA_CACHE_DIR``); where neither can be written, ``NUMBA_CACHE_DIR`` is pointed at a
    temporary folder, so that the code still compiles, once per process."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        candidates = [Path(os.environ["NUMBA_CACHE_DIR"])]
    else:
        home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
        candidates = [package / "__pycache__", home / "numba"]
    for folder in candidates:
        if _writable(folder):
            return None
    fallback = Path(tempfile.mkdtemp(prefix="dftc-numba-"))
    os.environ["NUMBA_CACHE_DIR"] = str(fallback)
    where = " or ".join(str(c) for c in candidates)
    return (
        f"numba cannot write its cache in {where}: the onboard code compiles again in every "
        "process (tens of seconds); set NUMBA_CACHE_DIR to a folder you can write"
    )


def _writable(folder: Path) -> bool:
    """``folder`` exists (or can be made) and a file can be created in it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def traced_calls(run: Callable[[], object], package: str = "dftc_mujoco") -> list[Call]:
    """The compiled functions of ``package`` that Python code calls while ``run()`` runs,
    each with the numba types of its arguments, in the order of their first call; every
    such function runs as plain Python meanwhile (its ``py_func``: nothing compiles, and a
    period takes milliseconds). Calls from one compiled function to another are not listed
    (they compile with their caller). For :mod:`.precompile`, which compiles them in the
    opposite order while a run compiles them in this one."""
    from numba import typeof
    from numba.core.registry import CPUDispatcher

    calls: list[Call] = []
    seen: set[tuple[int, tuple[Any, ...]]] = set()
    depth = [0]

    def tracer(dispatcher: Any) -> Callable[..., Any]:
        py_func = dispatcher.py_func

        def call(*args: Any) -> Any:
            if depth[0] == 0:
                try:
                    types = tuple(typeof(a) for a in args)
                except (ValueError, TypeError):  # a type numba cannot name: not listed
                    types = None
                if types is not None and (id(dispatcher), types) not in seen:
                    seen.add((id(dispatcher), types))
                    calls.append(Call(dispatcher, types))
            depth[0] += 1
            try:
                return py_func(*args)
            finally:
                depth[0] -= 1

        call.py_func = py_func  # type: ignore[attr-defined]  # read as a dispatcher's
        return call

    stand_ins: dict[int, Callable[..., Any]] = {}
    replaced = []
    for name, module in list(sys.modules.items()):
        if module is None or not (name == package or name.startswith(package + ".")):
            continue
        for attr, value in list(vars(module).items()):
            if isinstance(value, CPUDispatcher):
                stand_in = stand_ins.setdefault(id(value), tracer(value))
                replaced.append((module, attr, value))
                setattr(module, attr, stand_in)
    try:
        run()
    finally:
        for module, attr, value in replaced:
            setattr(module, attr, value)
    return calls


@dataclass(frozen=True)
class Call:
    """A compiled function and the numba types of the arguments it was called with."""

    dispatcher: Any
    types: tuple[Any, ...]

    @property
    def name(self) -> str:
        """``module.qualname`` of the function."""
        func = self.dispatcher.py_func
        return f"{func.__module__}.{func.__qualname__}"

    def compile(self) -> None:
        """Compile it for these types (numba loads it from its cache instead where another
        process already compiled it, and keeps what it compiles there)."""
        self.dispatcher.compile(self.types)
