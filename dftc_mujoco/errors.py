"""One exception type per layer; the CLI turns each into a single line and a non-zero exit."""

from __future__ import annotations


class DftcError(Exception):
    """Base class of every error dftc-mujoco reports to a user."""


class ScenarioError(DftcError):
    """A scenario file (or a CLI override of it) is not valid.

    The message always names the file, the key and what was expected.
    """


class SimulationError(DftcError):
    """The physics went wrong (MuJoCo warning, NaN, instability) during a run."""
