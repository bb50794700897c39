"""What every layer shares: the team's communication graph, its mission, and the events a
run records. Pure Python and numpy; nothing here knows MuJoCo or the onboard blocks."""
