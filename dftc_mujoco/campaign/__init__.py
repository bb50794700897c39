"""Monte-Carlo fault campaigns: many runs of a base scenario with what varies drawn per run.

``spec`` reads a campaign TOML and draws each run's parameters from the
campaign seed and the run's index (so any engine runs the same runs);
``runner`` executes them on a local process pool or a Ray cluster, appending
each finished run to the results at once; ``report`` summarises them.
"""
