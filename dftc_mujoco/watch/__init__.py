"""Watching a run: live in MuJoCo's passive viewer, or in a web browser, live or replayed
from its records."""
