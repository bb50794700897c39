"""How a robot's state is shown: its name and its colour, the same in the video, the figures
and the live viewer.

A robot is ``excluded`` once the team dropped it, else ``flagged`` while a teammate flags
it, else ``compensating`` while it compensates a fault estimate, else ``healthy``.
"""

from __future__ import annotations

HEALTHY = (0.20, 0.45, 0.85, 1.0)
COMPENSATING = (0.95, 0.60, 0.10, 1.0)
FLAGGED = (0.85, 0.15, 0.15, 1.0)
EXCLUDED = (0.45, 0.45, 0.45, 1.0)

#: (state, RGBA), in the order a legend lists them
STATES: tuple[tuple[str, tuple[float, float, float, float]], ...] = (
    ("healthy", HEALTHY),
    ("compensating", COMPENSATING),
    ("flagged", FLAGGED),
    ("excluded", EXCLUDED),
)
COLOURS = dict(STATES)


def robot_state(active: bool, flagged: bool, compensating: bool) -> str:
    """The state shown for a robot: excluded, flagged, compensating or healthy."""
    if not active:
        return "excluded"
    if flagged:
        return "flagged"
    return "compensating" if compensating else "healthy"
