"""The errors dftc-mujoco reports, and the one table of exit codes its commands return.

Every error a user can meet is a :class:`DftcError`; its ``exit_code`` says which row of the
table it belongs to, and the command line prints it as one ``error:`` line per problem.

=====  ==================  =========================================================
code   name                meaning
=====  ==================  =========================================================
0      EXIT_OK             done
1      EXIT_BUG            a bug in dftc_mujoco: its traceback is printed (the records of a
                           run are kept when the bug was in drawing its figures or video)
2      EXIT_INPUT          a scenario, robot file, campaign spec, log or flag is not valid
3      EXIT_PHYSICS        the physics went wrong during the run (the records are kept)
4      EXIT_RENDER         no OpenGL context, or rendering failed
5      EXIT_OUTPUT         the output folder, the disk or the OS; a cluster that cannot be
                           used (EXIT_CLUSTER); a browser view that cannot be served
                           (EXIT_SERVE: no MuJoCo Studio web viewer, the port taken)
130    SIGINT              interrupted (128 + the signal's number; 143 for SIGTERM)
=====  ==================  =========================================================
"""

from __future__ import annotations

EXIT_OK = 0
EXIT_BUG = 1  # what Python returns for an exception nothing caught
EXIT_INPUT = 2
EXIT_PHYSICS = 3
EXIT_RENDER = 4
EXIT_OUTPUT = 5
EXIT_CLUSTER = EXIT_OUTPUT  # an environment problem, like a full disk
EXIT_SERVE = EXIT_OUTPUT  # --web: the same kind of problem


def exit_interrupted(signum: int) -> int:
    """The exit code of a command stopped by signal ``signum``: 130 for SIGINT, 143 for
    SIGTERM, as a shell reports it."""
    return 128 + int(signum)


def raised_line(exc: BaseException) -> str:
    """``Kind: the first line of its message`` (``Kind`` alone when it has none): how a
    user's own exception is quoted in a one-line error."""
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0]}" if text else type(exc).__name__


class DftcError(Exception):
    """Base class of every error dftc-mujoco reports to a user."""

    exit_code = 1


class InputError(DftcError):
    """An input is not valid: a scenario file (or a CLI override of it), a robot file, a
    campaign spec, a log, a flag.

    The message always names the file, the key and what was expected.
    """

    exit_code = EXIT_INPUT


#: the name every part of the package has raised for invalid input since the first release
ScenarioError = InputError


class SimulationError(DftcError):
    """The physics went wrong (MuJoCo warning, NaN, instability) during a run."""

    exit_code = EXIT_PHYSICS


#: dm_control's name for the same thing
PhysicsError = SimulationError


class BlockError(SimulationError):
    """An onboard block raised during a run: the run stops there and keeps its records
    (exit code 3, like physics trouble: the run itself went wrong, not its input)."""


class RenderError(DftcError):
    """No offscreen OpenGL context can be created (or rendering failed)."""

    exit_code = EXIT_RENDER


class OutputError(DftcError):
    """The output folder cannot be used (exists, locked, not writable, no space)."""

    exit_code = EXIT_OUTPUT


class ClusterError(DftcError):
    """Ray is missing, or the cluster cannot be reached or joined."""

    exit_code = EXIT_CLUSTER


class ServeError(DftcError):
    """``--web``: MuJoCo Studio's web viewer cannot serve the run (it is not installed, the
    port is taken, it stopped); the message says what to do."""

    exit_code = EXIT_SERVE
