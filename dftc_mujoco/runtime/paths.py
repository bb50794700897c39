"""Where the shipped data folders (``models/``, ``scenarios/``) are; runs write to
``./renders/`` in the working directory.

In a repository checkout (and an editable install) the folders are at the repository's
top level, beside the package; a wheel installs them inside the package
(``dftc_mujoco/models``, ``dftc_mujoco/scenarios``, mapped in ``pyproject.toml``). Both
are found from any working directory.
"""

from __future__ import annotations

from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1]  # dftc_mujoco/, above runtime/


def data_folder(name: str) -> Path:
    """The shipped folder ``name``: inside the installed package (a wheel), else beside
    it (a checkout). Returns the checkout path when neither exists, so that errors name
    where it was looked for."""
    installed = PACKAGE / name
    return installed if installed.is_dir() else PACKAGE.parent / name


MODELS = data_folder("models")
SCENARIOS = data_folder("scenarios")
ROOT = MODELS.parent  # kept for older imports: the folder that holds models/
