"""A worker process never outlives the process that started it.

:func:`die_with_parent` is called first thing in each campaign worker. On Linux
it asks the kernel to send the worker SIGKILL when its parent dies
(``prctl(PR_SET_PDEATHSIG)``), which also covers ``kill -9`` of the parent; on
every system a daemon thread checks ``os.getppid()`` once a second and ends the
worker when the parent has changed (a parent that died before the ``prctl`` call,
or a platform without it).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1
POLL_SECONDS = 1.0


def _pdeathsig(signum: int) -> bool:
    """Ask Linux to send ``signum`` to this process when its parent dies."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(signum), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent: int) -> None:
    while True:
        if os.getppid() != parent:
            os._exit(1)  # the parent is gone: nobody will read this worker's results
        time.sleep(POLL_SECONDS)


def die_with_parent(parent: int) -> None:
    """End this process as soon as process ``parent`` (its parent) is gone."""
    _pdeathsig(signal.SIGKILL)
    if os.getppid() != parent:  # it died before the prctl call took effect
        os._exit(1)
    threading.Thread(target=_watch, args=(parent,), name="lifeline", daemon=True).start()
