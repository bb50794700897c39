"""What every command line shares: its program name in help and ``--version``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import __version__


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
