"""Run records: the sampled log (``log.npz``), events, and ``summary.json``.

Both files are written atomically (a temporary file in the same folder, then
``os.replace``), so a crash never leaves a half-written file behind.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

# name -> (shape after the time axis, in units of N; dtype; fill). The N × N fields are
# float32 (7 significant digits): at N = 100, 60 s at 50 Hz they take 480 MB, not 960.
LOG_FIELDS: dict[str, tuple[str, type, Any]] = {
    "t": ("", np.float64, np.nan),
    "x": ("N2", np.float64, np.nan),
    "x_hat": ("NN2", np.float32, np.nan),
    "u": ("N2", np.float64, np.nan),
    "phi": ("N2", np.float64, np.nan),
    "phi_hat": ("N2", np.float64, np.nan),
    "residual": ("NN", np.float32, np.nan),
    "threshold": ("NN", np.float32, np.nan),
    "reactive": ("N", np.bool_, False),
    "active": ("N", np.bool_, False),
    "sigma_err": ("2", np.float64, np.nan),
    "x_d": ("N2", np.float64, np.nan),
    "c_d": ("2", np.float64, np.nan),
    "flagged": ("N", np.bool_, False),
    "pose": ("N3", np.float64, np.nan),
    "ctrl": ("NA", np.float64, np.nan),  # actuator commands (A per robot), for φ of a stop
}
# derived from the other fields after the run (results.py), not sampled in the loop
DERIVED_FIELDS = ("phi", "sigma_err")
# arrays without a time axis stored beside them in log.npz
STATIC_FIELDS = ("obstacles",)  # (O, 4): x, y, radius, safe distance d


def _shape(code: str, n: int, n_act: int = 2) -> tuple[int, ...]:
    return tuple(n if c == "N" else n_act if c == "A" else int(c) for c in code)


class Log:
    """Preallocated arrays sampled at the log rate; ``arrays()`` returns the filled part."""

    def __init__(self, n_samples: int, n_robots: int, n_act: int = 2, **static: np.ndarray) -> None:
        self.n = n_robots
        self.size = 0
        self.static = static
        self.data = {
            name: np.full((n_samples, *_shape(code, n_robots, n_act)), fill, dtype=dtype)
            for name, (code, dtype, fill) in LOG_FIELDS.items()
            if name not in DERIVED_FIELDS
        }

    def sample(self, **values: Any) -> None:
        """Store one sample; fields not given keep their fill value (NaN / False)."""
        row = self.size
        for name, value in values.items():
            self.data[name][row] = value
        self.size += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """The samples taken so far, by field name, plus the static arrays."""
        return {**{name: a[: self.size] for name, a in self.data.items()}, **self.static}


@dataclass
class Events:
    """Time-stamped events of a run; robots are numbered from 1 (as in ``summary.json``)."""

    items: list[dict[str, Any]] = field(default_factory=list)

    def add(self, t: float, kind: str, **info: Any) -> None:
        self.items.append({"t": round(float(t), 6), "kind": kind, **info})

    def of_kind(self, kind: str) -> list[dict[str, Any]]:
        return [e for e in self.items if e["kind"] == kind]

    def ordered(self) -> list[dict[str, Any]]:
        return sorted(self.items, key=lambda e: e["t"])


def _atomic_write(path: Path, write) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual file mode
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_json(path: Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON, atomically."""
    text = json.dumps(obj, indent=2, allow_nan=False, default=_json_default) + "\n"
    _atomic_write(path, lambda fh: fh.write(text.encode()))


def write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8), atomically."""
    _atomic_write(path, lambda fh: fh.write(text.encode()))


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write arrays as a compressed ``.npz``, atomically."""
    _atomic_write(path, lambda fh: np.savez_compressed(fh, **arrays))


def _json_default(o: Any) -> Any:
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
