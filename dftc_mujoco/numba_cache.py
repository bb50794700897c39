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
from pathlib import Path

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
