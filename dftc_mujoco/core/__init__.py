"""What every layer shares: the team's communication graph, its mission, the events a run
records and the run's records themselves (the sampled log, the events, the summary's
files), which the loop writes and the renderers read. Pure Python, numpy and numba;
nothing here knows MuJoCo or the onboard blocks."""
