"""Rendering and plotting: videos and the paper's figures, drawn from a run's records.

Nothing here reaches into a running simulation or into the controllers: the
video re-poses a copy of the scene from ``log.npz``, and the figures are drawn
from ``log.npz`` and ``summary.json``.
"""
