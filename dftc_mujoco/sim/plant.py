"""The plant: MuJoCo stepping, measurement noise η and disturbance ξ (eqs. 1-4)."""

from __future__ import annotations

import mujoco
import numpy as np
from numba import njit

from ..errors import SimulationError
from ..scenario import Noise
from .scene import Scene

_WARNINGS = [
    (int(w), name.removeprefix("mjWARN_"))
    for name, w in mujoco.mjtWarning.__members__.items()
    if name.startswith("mjWARN_")
]


def _disk_sample(rng: np.random.Generator, n: int, radius: float, at_bound: bool) -> np.ndarray:
    """n planar vectors, uniform in the disk of ``radius`` (or on its rim if ``at_bound``)."""
    return _disk_chunk(rng.random((1, 2, n)), radius, at_bound)[0]


@njit(cache=True)
def _low_pass(w, alpha, state, at_bound, bound, out):  # pragma: no cover - compiled
    """ξ_k = α ξ_{k−1} + (1 − α) w_k for a chunk of periods w (C, N, 2), in place of ``state``."""
    for c in range(w.shape[0]):
        for i in range(w.shape[1]):
            for d in range(2):
                state[i, d] = alpha * state[i, d] + (1.0 - alpha) * w[c, i, d]
            if at_bound:
                norm = max(np.sqrt(state[i, 0] ** 2 + state[i, 1] ** 2), 1e-12)
                out[c, i, 0] = bound * state[i, 0] / norm
                out[c, i, 1] = bound * state[i, 1] / norm
            else:
                out[c, i, 0] = state[i, 0]
                out[c, i, 1] = state[i, 1]


@njit(cache=True)
def _gather_xy(src, idx, out):  # pragma: no cover - compiled
    """out[i] = src[idx[i], :2] (planar part of MuJoCo positions)."""
    for i in range(idx.shape[0]):
        out[i, 0] = src[idx[i], 0]
        out[i, 1] = src[idx[i], 1]


def _disk_chunk(r: np.ndarray, radius: float, at_bound: bool) -> np.ndarray:
    """Planar vectors (C, N, 2) from uniform draws ``r`` (C, 2, N): row 0 gives the angle,
    row 1 the radius (uniform in the disk, or ``radius`` itself if ``at_bound``)."""
    out = np.empty((r.shape[0], r.shape[2], 2))
    _disk_fill(r, radius, at_bound, out)
    return out


@njit(cache=True)
def _disk_fill(r, radius, at_bound, out):  # pragma: no cover - compiled
    """:func:`_disk_chunk` into ``out`` (C, N, 2): the same operations on the same floats as
    numpy's on whole arrays, element by element (twice as fast: numpy called the C library's
    sine and cosine one element at a time all the same, through a slower loop)."""
    for c in range(r.shape[0]):
        for i in range(r.shape[2]):
            ang = (2.0 * np.pi) * r[c, 0, i]
            mag = radius if at_bound else radius * np.sqrt(r[c, 1, i])
            out[c, i, 0] = mag * np.cos(ang)
            out[c, i, 1] = mag * np.sin(ang)


class NoiseStream:
    """η and ξ of every control period, drawn ahead in chunks from the run's generator.

    The draws are the same, in the same order, as one η then one ξ per period
    (the generator fills a chunk in order), so the numbers do not depend on
    the chunk size; drawing ahead only removes per-period work from the loop.
    """

    def __init__(self, plant: Plant, chunk: int = 512) -> None:
        self.plant = plant
        self.chunk = chunk
        self.k = chunk  # next row to hand out
        n = plant.n
        self.eta = np.empty((chunk, n, 2))
        self.xi = np.empty((chunk, n, 2))
        self._r = np.empty((chunk, 2, 2, n))  # the uniform draws of a chunk
        self._w = np.empty((chunk, n, 2))  # ξ's inputs before the low pass
        self._rows: list[tuple[np.ndarray, np.ndarray]] = []  # (η, ξ) views of each period

    def next(self) -> tuple[np.ndarray, np.ndarray]:
        """(η, ξ) of the next control period, each (N, 2): views valid for one period."""
        if self.k == self.chunk:
            self._refill()
        k = self.k
        self.k += 1
        return self._rows[k]

    def peek(self) -> tuple[np.ndarray, np.ndarray]:
        """(η, ξ) that :meth:`next` hands out next, without taking them (copies)."""
        if self.k == self.chunk:
            self._refill()
        return self.eta[self.k].copy(), self.xi[self.k].copy()

    def _refill(self) -> None:
        p = self.plant
        r = p.rng.random(out=self._r)  # per period: η's (2, N), then ξ's (2, N)
        _disk_fill(r[:, 0], p.noise.eta_bar, p.at_bound, self.eta)
        _disk_fill(r[:, 1], p.xi_bar, False, self._w)
        _low_pass(self._w, p._alpha, p._xi_state, p.at_bound, p.xi_bar, self.xi)
        if not self._rows:  # the views of every period, made once (0.1 µs a period each)
            self._rows = list(zip(self.eta, self.xi, strict=True))
        self.k = 0


class Plant:
    """MuJoCo model + data of one run, with the robots' sensors and the disturbance.

    ``rng`` is the run's only source of randomness (passed in, never global).
    ξ is a low-pass filtered random planar velocity, bounded by ξ̄ by
    construction (a convex combination of points in the disk); the loop adds it
    to the velocity each robot's adapter is asked for, so it reaches any robot
    model through its actuators (a braked robot ignores it). With
    ``noise.at_bound`` both η and ξ have norms exactly at their bounds.
    """

    def __init__(
        self,
        scene: Scene,
        noise: Noise,
        control_period: float,
        rng: np.random.Generator,
        xi_bar: float | None = None,
    ) -> None:
        self.scene = scene
        self.model = scene.model
        self.data = self.initial_data(scene)
        self.noise = noise
        self.rng = rng
        self.at_bound = noise.at_bound
        self.n = len(scene.body)
        # bound of the injected disturbance; the loop passes ξ̄ minus the model's mismatch
        self.xi_bar = xi_bar if xi_bar is not None else (noise.xi_bar or 0.0)
        self._alpha = float(np.exp(-control_period / noise.xi_time_constant))
        self._xi_state = _disk_sample(rng, self.n, self.xi_bar, False)
        # the drive writes the driven and the held actuators, in this order (drives.Drive;
        # a mixed team: each model's robots in turn, fleet.MixedDrive)
        self._ctrl_index: np.ndarray | slice = (
            scene.ctrl_index
            if len(scene.ctrl_index)
            else np.hstack([scene.actuator, scene.held]).ravel()
        )
        if np.array_equal(self._ctrl_index, np.arange(self.data.ctrl.size)):  # every one, in order
            self._ctrl_index = slice(None)  # a copy instead of a gather each period
        # views into MjData's own memory, taken once (the hot loop reads and writes them)
        self._site_xpos = self.data.site_xpos
        self._ctrl = self.data.ctrl
        self._warnings = self.data.warning.number
        self._site = np.ascontiguousarray(scene.site, dtype=np.intp)

    @staticmethod
    def initial_data(scene: Scene) -> mujoco.MjData:
        """MjData at the scene's initial state: each robot at its keyframe pose, the
        actuators nobody drives holding their keyframe ctrl."""
        data = mujoco.MjData(scene.model)
        data.qpos[:] = scene.qpos_init
        data.ctrl[:] = scene.ctrl_init
        mujoco.mj_forward(scene.model, data)
        return data

    @property
    def time(self) -> float:
        return float(self.data.time)

    def positions(self, out: np.ndarray | None = None) -> np.ndarray:
        """True planar positions (N, 2) from the robots' sites (world frame, docs/notes.md, 13)."""
        if out is None:
            out = np.empty((self.n, 2))
        _gather_xy(self._site_xpos, self._site, out)
        return out

    def velocities(self) -> np.ndarray:
        """True planar velocities (N, 2) of the robots' bases."""
        v = np.empty((self.n, 6))
        for k, b in enumerate(self.scene.body):
            mujoco.mj_objectVelocity(
                self.model, self.data, mujoco.mjtObj.mjOBJ_BODY, int(b), v[k], 0
            )
        return v[:, 3:5].copy()

    def measure(self, x: np.ndarray | None = None) -> np.ndarray:
        """Each robot's own noisy position x_m,i = x_i + η_i, ‖η_i‖ ≤ η̄ (eqs. 3-4).

        ``x`` are the true positions if the caller already has them.
        """
        eta = _disk_sample(self.rng, self.n, self.noise.eta_bar, self.at_bound)
        return (self.positions() if x is None else x) + eta

    def step(self, ctrl: np.ndarray, nsub: int) -> None:
        """Hold actuator commands ``ctrl`` (N, A + H: driven, then held) for ``nsub`` steps."""
        self._ctrl[self._ctrl_index] = ctrl.ravel()
        mujoco.mj_step(self.model, self.data, nstep=nsub)
        if np.count_nonzero(self._warnings):
            self.check()

    def check(self) -> None:
        """Raise :class:`SimulationError` on any MuJoCo warning (non-finite states included)."""
        counts = self._warnings
        if counts.any():
            idx, name = next((i, nm) for i, nm in _WARNINGS if counts[i])
            info = self.data.warning[idx].lastinfo
            raise SimulationError(
                f"MuJoCo warning {name} at t = {self.time:.3f} s (info {info}); the run was stopped"
            )
        # a non-finite qpos, qvel or qacc raises MuJoCo's BADQPOS/BADQVEL/BADQACC above
