"""What every command line shares: its program name in help and ``--version``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import __version__
from .errors import DftcError


def prog(module: str, script: str) -> str:
    """``script`` (e.g. ``dftc-run``) when run as the installed command, else
    ``python -m module``, so that help and errors name what the user typed."""
    return script if Path(sys.argv[0]).name == script else f"python -m {module}"


def parser(module: str, script: str, description: str) -> argparse.ArgumentParser:
    """An ArgumentParser with the right program name and ``--version``."""
    p = argparse.ArgumentParser(prog=prog(module, script), description=description)
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


def print_error(exc: BaseException) -> None:
    """One ``error:`` line on stderr per problem the exception reports."""
    for line in str(exc).splitlines() or [type(exc).__name__]:
        print(f"error: {line}", file=sys.stderr)


def fail(exc: DftcError) -> int:
    """Print ``exc`` as :func:`print_error` does; return its exit code (``errors.py``)."""
    print_error(exc)
    return exc.exit_code


def add_set_option(p: argparse.ArgumentParser, what: str) -> None:
    """``--set KEY=VALUE`` (repeatable, into ``args.overrides``): a scenario key by dotted
    path, the value in TOML syntax; ``what`` completes the help."""
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"override a key of {what} by dotted path, value in TOML syntax "
        "(e.g. --set gains.ko=3 --set mission.formation.side=1.0); repeatable",
    )
