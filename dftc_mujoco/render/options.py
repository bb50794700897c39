"""Video settings (kept apart from the renderer so choosing them does not import mujoco)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class VideoOptions:
    """Frame size, rate and quality of a video."""

    width: int = 640
    height: int = 480
    fps: float = 30.0
    quality: bool = False  # shadows, multisampling and a finer encoding
    trail_seconds: float = np.inf  # how much history each trail shows


def frame_times(duration: float, fps: float) -> np.ndarray:
    """Video frame instants: t = k / fps for k = 0 .. round(duration · fps)."""
    return np.arange(round(duration * fps) + 1) / fps
