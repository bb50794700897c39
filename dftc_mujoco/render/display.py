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


#: a link of the network, by the age of the message it holds (the video's links)
LINK_LIVE = (0.15, 0.65, 0.25, 0.8)  # within the latency: no message lost
LINK_DELAYED = (0.95, 0.65, 0.1, 0.85)  # within a round: lost ones, within the bound
LINK_DROPPED = (0.85, 0.1, 0.1, 0.9)  # beyond a round: the premise 'network' is broken
LINKS = (("live", LINK_LIVE), ("delayed", LINK_DELAYED), ("dropped", LINK_DROPPED))


def link_state(age: float, fresh: float, whole: float) -> str:
    """A link's state from the age [s] of its message: live, delayed or dropped, against
    the latency ``fresh`` and the round ``whole`` [s] (a period's slack on each)."""
    if not age <= whole + 1e-9:
        return "dropped"
    return "live" if age <= fresh + 1e-9 else "delayed"
