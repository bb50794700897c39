"""A Gymnasium environment: a policy drives one robot of the team (:mod:`.seat`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from ..watch.viewer import has_display
from .seat import BIG, Seats

RENDER_MODES = ["rgb_array", "human"] if has_display() else ["rgb_array"]


class DFTCEnv(gymnasium.Env):
    """One robot of a DFTC team, driven by the policy; the rest of the team runs the
    scenario's blocks. Observation: the robot's own view (:data:`.seat.FIELDS`, float32,
    scaled to the order of 1); action: its planar velocity command in m/s, or with
    ``action="correction"`` a velocity added to the team's own command for it; reward: minus
    its distance from its slot, in slots' spacings. The episode terminates when the robot
    is excluded (or the team falls apart, or the physics fails) and is truncated at the
    scenario's duration. ``vary`` draws each episode's faults, starts or scenario keys (a
    campaign's ``[vary]`` table); ``reset(seed=...)`` fixes them, an unseeded reset draws
    the next episode of the stream. ``render_mode="rgb_array"``: :meth:`render` returns the
    team from above; ``"human"`` shows it in MuJoCo's viewer (a display is needed)."""

    #: "human" where a display is (MuJoCo's viewer needs one)
    metadata: dict[str, Any] = {"render_modes": RENDER_MODES, "render_fps": 30}  # noqa: RUF012 - gymnasium's own type

    def __init__(
        self,
        scenario: Any = "paper_case",
        robot: int = 1,
        vary: Mapping[str, Any] | None = None,
        action: str = "velocity",
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode: expected one of {self.metadata['render_modes']} or None, "
                f"got {render_mode!r}"
            )
        self.seats = Seats(scenario, [int(robot) - 1], vary, action)
        self.robot = int(robot) - 1
        self.render_mode = render_mode
        size = self.seats.size(self.robot)
        self.observation_space = spaces.Box(-BIG, BIG, (size,), np.float32)
        lim = self.seats.limit
        self.action_space = spaces.Box(-lim, lim, (2,), np.float32)
        self._frames: Any = None
        self._viewer: Any = None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: the one ``seed`` fixes, or without one the next of the stream."""
        super().reset(seed=seed)
        self._close_render()
        self.seats.reset(int(self.np_random.integers(2**31 - 1)))
        if self.render_mode == "human":
            self.render()
        return self.seats.observe(self.robot).copy(), self.seats.info(self.robot)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One control period with the robot commanded ``action``."""
        s, i = self.seats, self.robot
        s.step({i: action})
        terminated = s.terminated(i)
        truncated = s.truncated and not terminated
        if self.render_mode == "human":
            self.render()
        return s.observe(i).copy(), s.reward(i), terminated, truncated, s.info(i)

    def render(self) -> np.ndarray | None:
        """The team from above (``"rgb_array"``: a (360, 480, 3) uint8 frame), or one more
        frame in MuJoCo's viewer (``"human"``)."""
        if self.render_mode == "rgb_array":
            if self._frames is None:
                from .frames import Frames

                self._frames = Frames(self.seats.sim)
            return self._frames.frame()
        if self.render_mode == "human":
            if self._viewer is None:
                import mujoco.viewer

                sim = self.seats.sim
                self._viewer = mujoco.viewer.launch_passive(sim.model, sim.data)
            self._viewer.sync()
        return None

    def _close_render(self) -> None:
        if self._frames is not None:
            self._frames.close()
            self._frames = None
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

    def close(self) -> None:
        """Release the simulation (and the renderer)."""
        self._close_render()
        self.seats.close()
