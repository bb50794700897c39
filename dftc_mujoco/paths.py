"""Where the repository's data folders live (``models/``, ``scenarios/``); runs write to
``./renders/`` in the working directory."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
SCENARIOS = ROOT / "scenarios"
