"""Run records: the sampled log (``log.npz``), events, and ``summary.json``.

Both files are written atomically (a temporary file in the same folder, then
``os.replace``), so a crash never leaves a half-written file behind.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from ..runtime.atomic import atomic_write, write_text
from .events import Event, Kind, make

__all__ = ["Events", "Log", "write_json", "write_npz", "write_text"]

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
    "v_cmd": ("N2", np.float64, np.nan),  # planar command the drive was asked for (φ of a stop)
}
# derived from the other fields after the run (reporting/results.py), not sampled in the loop
DERIVED_FIELDS = ("phi", "sigma_err")
# N × N fields: sampled every ``matrix_every`` log rows (the static "matrix_every" in log.npz)
MATRIX_FIELDS = ("x_hat", "residual", "threshold")
MATRIX_LOG_BUDGET = 256 * 2**20  # bytes the N × N fields may take at the "auto" rate


def matrix_every(n_robots: int, n_rows: int, log_every: int, dt: float, rate: float | str) -> int:
    """Log rows between two samples of the N × N fields (1: every row).

    ``rate`` in Hz, or "auto": every row while the N × N fields of ``n_rows`` rows fit in
    :data:`MATRIX_LOG_BUDGET`, else as many rows apart as needed.
    """
    if rate == "auto":
        per_row = n_robots * n_robots * (2 * 4 + 4 + 4)  # float32 x_hat, residual, threshold
        return max(1, -(-n_rows * per_row // MATRIX_LOG_BUDGET))
    return max(1, round(1.0 / (float(rate) * dt * log_every)))


def matrix_rows(log: dict[str, np.ndarray]) -> np.ndarray:
    """Indices of the log rows at which the N × N fields were sampled."""
    every = int(log["matrix_every"]) if "matrix_every" in log else 1
    return np.arange(len(log["residual"])) * every


# arrays without a time axis stored beside them in log.npz
# (O, 4): x, y, radius, safe distance d; and the log rows between two N × N samples
STATIC_FIELDS = ("obstacles", "matrix_every")


def _shape(code: str, n: int) -> tuple[int, ...]:
    return tuple(n if c == "N" else int(c) for c in code)


#: the fields :meth:`Log.sample` writes, in the order its compiled call takes them
SAMPLED = ("t", "x", "c_d", "v_cmd")


@njit(cache=True)
def _sample(log_t, log_x, log_c, log_v, row, t, x, c, cmd, limit):  # pragma: no cover - compiled
    """Row ``row`` of t, x, c_d and v_cmd (:data:`SAMPLED`): v_cmd is ``cmd`` within
    ±``limit`` (what the drives can be asked for; NaN stays NaN)."""
    log_t[row] = t
    for d in range(c.shape[0]):
        log_c[row, d] = c[d]
    for i in range(x.shape[0]):
        for d in range(x.shape[1]):
            log_x[row, i, d] = x[i, d]
            v = cmd[i, d]
            if v < -limit:
                v = -limit
            if v > limit:
                v = limit
            log_v[row, i, d] = v


class Log:
    """Preallocated arrays sampled at the log rate; ``arrays()`` returns the filled part.

    The N × N fields (:data:`MATRIX_FIELDS`) are kept every ``matrix_every`` rows
    only, so that large teams stay within a bounded memory; ``row_nn`` is the index
    of the N × N sample that goes with the current row (or -1 when none does).
    """

    def __init__(
        self,
        n_samples: int,
        n_robots: int,
        matrix_every: int = 1,
        **static: np.ndarray,
    ) -> None:
        self.n = n_robots
        self.size = 0
        self.matrix_every = matrix_every
        self.static = {**static, "matrix_every": np.array(matrix_every)}
        n_matrix = -(-n_samples // matrix_every)
        self.data: dict[str, np.ndarray] = {
            name: np.full(
                (n_matrix if name in MATRIX_FIELDS else n_samples, *_shape(code, n_robots)),
                fill,
                dtype=dtype,
            )
            for name, (code, dtype, fill) in LOG_FIELDS.items()
            if name not in DERIVED_FIELDS
        }
        d = self.data
        self._sampled = (d["t"], d["x"], d["c_d"], d["v_cmd"])  # :data:`SAMPLED`

    def sample(self, t: float, x: np.ndarray, c: np.ndarray, cmd: np.ndarray, limit: float) -> None:
        """The simulator's part of the current row (:attr:`size`): the time ``t``, the true
        positions ``x`` (N, 2), the desired centroid ``c`` and the commands ``cmd`` (N, 2)
        within the drives' range ±``limit`` (v_cmd), in one compiled call."""
        _sample(*self._sampled, self.size, t, x, c, cmd, limit)

    def add_field(self, name: str, shape: tuple[int, ...], dtype: type, fill: Any) -> None:
        """A field of this run only (the network's per-link fields), sampled every row."""
        rows = len(self.data["t"])
        self.data[name] = np.full((rows, *shape), fill, dtype=dtype)

    @property
    def row_nn(self) -> int:
        """Where the current row's N × N fields go, or -1 when this row has none."""
        return self.size // self.matrix_every if self.size % self.matrix_every == 0 else -1

    def arrays(self) -> dict[str, np.ndarray]:
        """The samples taken so far, by field name, plus the static arrays."""
        n_matrix = -(-self.size // self.matrix_every)
        return {
            **{
                name: a[: n_matrix if name in MATRIX_FIELDS else self.size]
                for name, a in self.data.items()
            },
            **self.static,
        }


@dataclass
class Events:
    """Time-stamped events of a run; robots are numbered from 1 (as in ``summary.json``)."""

    items: list[Event] = field(default_factory=list)

    def add(self, t: float, kind: Kind, **info: Any) -> None:
        self.items.append(make(round(float(t), 6), kind, **info))

    def of_kind(self, kind: Kind) -> list[Event]:
        return [e for e in self.items if e["kind"] == kind]

    def ordered(self) -> list[Event]:
        return sorted(self.items, key=lambda e: e["t"])


def write_json(path: Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON, atomically; a non-finite number (a run whose numbers
    blew up) is written as null rather than losing the file (JSON has no inf or NaN)."""
    try:
        text = json.dumps(obj, indent=2, allow_nan=False, default=_json_default) + "\n"
    except ValueError:
        text = json.dumps(_finite(obj), indent=2, allow_nan=False, default=_json_default) + "\n"
    atomic_write(path, lambda fh: fh.write(text.encode()))


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write arrays as a compressed ``.npz``, atomically."""
    atomic_write(path, lambda fh: np.savez_compressed(fh, **arrays))  # type: ignore[arg-type]


def _finite(o: Any) -> Any:
    """``o`` with every non-finite float (numpy's too) replaced by None."""
    if isinstance(o, dict):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_finite(v) for v in o]
    if isinstance(o, float | np.floating):
        return float(o) if np.isfinite(o) else None
    if isinstance(o, np.ndarray):
        return _finite(o.tolist())
    return o


def _json_default(o: Any) -> Any:
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
