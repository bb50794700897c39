"""Writing a calibration into a robot file's ``[calibration]`` table (or an older MJCF's
``<custom>`` numerics), atomically."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

from ..atomic import write_text
from ..errors import ScenarioError
from .mismatch import Calibration

# --------------------------------------------------------------------------- writing


def write(path: Path, cal: Calibration) -> None:
    """Store the calibration: the ``[calibration]`` table of a robot file, or the
    ``<custom>`` numerics of an MJCF of the older contract (through MjSpec)."""
    if path.name.endswith(".toml"):
        _write_robot_file(path, cal.table())
    else:
        _write_mjcf(path, {"mismatch": cal.smooth_max, "xi_bar": cal.recommended_xi_bar})


def _calibration_header(path: Path, lines: list[str]) -> int | None:
    """The line of the robot file's ``[calibration]`` header (None: no calibration yet);
    a calibration written otherwise (inline or dotted keys) cannot be replaced line-wise."""
    start = next((i for i, ln in enumerate(lines) if ln.strip().startswith("[calibration]")), None)
    if start is None and "calibration" in tomllib.loads("\n".join(lines)):
        raise ScenarioError(
            f"{path}: calibration: written as an inline or dotted table; --write replaces a "
            "[calibration] table: move those keys into one (or delete them) and run again"
        )
    return start


def check_writable(path: Path) -> None:
    """Refuse ``--write`` before measuring when the robot file's calibration cannot be
    replaced (:func:`_calibration_header`); an MJCF is saved through MjSpec."""
    if path.name.endswith(".toml"):
        _calibration_header(path, path.read_text().splitlines())
    if not os.access(path, os.W_OK) or not os.access(path.parent, os.W_OK):
        raise ScenarioError(f"{path}: cannot write the calibration there (permission denied)")


def _write_robot_file(path: Path, values: dict[str, float]) -> None:
    """Replace (or add) the ``[calibration]`` table; every other line stays as it was."""
    lines = path.read_text().splitlines()
    start = _calibration_header(path, lines)
    body = [f"{k} = {v:.6g}" for k, v in values.items()]
    table = ["[calibration]  # python -m dftc_mujoco.calibrate --write", *body]
    if start is None:
        new = [*lines, "", *table]
    else:
        end = next(
            (i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")),
            len(lines),
        )
        new = lines[:start] + table + ([""] if end < len(lines) else []) + lines[end:]
    text = "\n".join(new) + "\n"
    tomllib.loads(text)  # never write a file that does not read back
    write_text(path, text)


def _write_mjcf(path: Path, values: dict[str, float]) -> None:
    import mujoco

    spec = mujoco.MjSpec.from_file(str(path))
    for key, value in values.items():
        name = f"dftc_{key}"
        found = [n for n in spec.numerics if n.name == name]
        for extra in found[1:]:  # an earlier tool may have left duplicates
            spec.delete(extra)
        if found:
            found[0].data = [float(value)]
        else:
            spec.add_numeric(name=name, data=[float(value)])
    text = spec.to_xml()
    write_text(path, text)
