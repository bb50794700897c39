"""One period's physics step, and what the loop reads of MuJoCo before it.

The loop (:mod:`.loop`) turns the team's compensated inputs into actuator commands
(:meth:`PhysicsStep.commands`) and advances MuJoCo by a control period. A team that shares
its pass over the N × N state between threads (:attr:`.onboard.team.Team.shares`) runs
this step *beside* that pass (:meth:`PhysicsStep.__call__`, given to
:meth:`.onboard.team.Team.step`): it needs the period's commands and nothing the pass
writes. What the loop reads of MuJoCo's state for the period after the team's step (the
premises monitor's poses and contacts, the log row's poses) is then copied before the
step (:class:`Before`), and a physics error is kept and raised by the loop where its own
physics step would have raised it, so both ways give the same records. On the ideal
network the premises monitor runs here too, on that copy and before the step
(:meth:`PhysicsStep.watch`), and so does the next period's noise, after it
(:attr:`PhysicsStep.ahead`): work the helper threads would otherwise wait through.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from . import checks
from .onboard.team import Team
from .premises import Monitor
from .sim.plant import Plant


class Before(NamedTuple):
    """MuJoCo's state as the loop reads it at a period, before the physics advances."""

    xpos: np.ndarray  # (nbody, 3)
    xmat: np.ndarray  # (nbody, 9)
    geom: np.ndarray | None  # (ncon, 2) contacts' geoms, None without contacts
    dist: np.ndarray | None  # (ncon,)
    ncon: int
    pose: np.ndarray  # (N, 3) the robots' planar poses (written when the period is logged)


class PhysicsStep:
    """The period's commands and physics step: ``plant`` driven through ``adapter`` and the
    actuator ``faults`` by the ``team``'s compensated inputs; ``x`` (N, 2) is the array the
    loop keeps the true positions of the period in; ``steps`` the run's last period, a log
    row every ``log_every`` periods, ``nsub`` MuJoCo steps a period."""

    def __init__(
        self,
        plant: Plant,
        team: Team,
        adapter: Any,
        faults: Any,
        x: np.ndarray,
        steps: int,
        log_every: int,
        nsub: int,
    ) -> None:
        self.plant, self.team, self.adapter, self.faults = plant, team, adapter, faults
        self.x, self.steps, self.log_every, self.nsub = x, steps, log_every, nsub
        n = plant.n
        self.cmd = np.empty((n, 2))  # the planar velocities asked of the drives (log: v_cmd)
        self.override = np.zeros((n, 2))  # Simulation.drive(): commands from outside the team
        self.driven = np.zeros(n, bool)
        self.any_driven = False  # driven.any(), kept by Simulation.drive()
        data = plant.data
        self.xpos = np.empty_like(data.xpos)
        self.xmat = np.empty_like(data.xmat)
        self._live = (data.xpos, data.xmat)  # views into MjData's memory, taken once
        self.pose = np.empty((n, 3))
        self._still = Before(*self._live, None, None, 0, self.pose)  # live() without contacts
        self.k = 0
        self.xi = np.zeros((0, 2))
        self.ctrl: np.ndarray | None = None
        self.stepped = False
        self.error: BaseException | None = None
        self.before: Before | None = None
        #: work for the next period, run after the physics step (the loop's noise stream's
        #: :meth:`~.sim.plant.NoiseStream.ahead`), so that it too runs beside the pass
        self.ahead: Callable[[], None] | None = None
        #: the premises' monitor, run on :class:`Before` beside the pass where the loop sets
        #: it (:meth:`watch`); then :attr:`watched` and, if it raised, :attr:`watch_error`
        self.monitor: Monitor | None = None
        self.t, self.eta = 0.0, np.zeros((0, 2))
        self.watched = False
        self.watch_error: BaseException | None = None

    def drive(self, robot: int, velocity: np.ndarray | Sequence[float] | None) -> None:
        """Robot ``robot`` (0-based) told ``velocity`` (planar, m/s) from outside the team
        from the next period on; None gives it back (:meth:`.loop.Simulation.drive`)."""
        n = len(self.driven)
        if isinstance(robot, bool) or not isinstance(robot, int | np.integer) or not 0 <= robot < n:
            raise ValueError(f"drive(robot): expected a robot in 0..{n - 1}, got {robot!r}")
        if velocity is None:
            self.driven[robot] = False
        else:
            try:
                v = np.asarray(velocity, dtype=float).reshape(2)
            except (TypeError, ValueError):  # numpy's own words named neither argument
                raise ValueError(
                    f"drive(velocity): expected a planar velocity of 2 numbers (m/s), got "
                    f"{velocity!r}"
                ) from None
            if not np.all(np.isfinite(v)):
                raise ValueError(f"drive(velocity): expected finite numbers, got {v.tolist()}")
            self.override[robot] = v
            self.driven[robot] = True
        self.any_driven = bool(self.driven.any())

    def commands(self, xi: np.ndarray) -> np.ndarray:
        """The actuator commands for the team's ū plus the drives' errors ``xi`` (eq. 2)
        (robots driven from outside: their given velocity plus ``xi``), into :attr:`cmd`."""
        cmd, driven = self.cmd, self.driven
        np.add(self.team.u_bar, xi, out=cmd)
        if self.any_driven:  # robots an outside policy drives (Simulation.drive())
            cmd[driven] = self.override[driven] + xi[driven]
        ctrl = self.adapter.command(cmd)
        if self.faults.any_stuck:  # stuck actuators keep their command of onset
            ctrl = self.faults.hold(ctrl)
        return ctrl

    def live(self) -> Before:
        """MuJoCo's state now, without copies (the physics advances after the loop read it)."""
        data = self.plant.data
        ncon = data.ncon
        if not ncon:
            return self._still
        contact = data.contact
        return Before(*self._live, contact.geom, contact.dist, ncon, self.pose)

    def set(self, k: int, xi: np.ndarray, t: float, eta: np.ndarray) -> PhysicsStep:
        """Period ``k`` (at ``t``, with the noise ``eta`` the monitor reads) with the drives'
        errors ``xi``: ready to be run beside the pass."""
        self.k, self.xi, self.t, self.eta = k, xi, t, eta
        self.ctrl, self.stepped, self.error, self.before = None, False, None, None
        self.watched, self.watch_error = False, None
        return self

    def __call__(self) -> None:
        """The commands, the copy of what the loop reads, the premises' monitor where the loop
        gave it (:meth:`watch`), then (unless the run ends at this period, as the loop decides,
        or the monitor stopped it) MuJoCo's step; an error is kept in :attr:`error`."""
        k, plant, team = self.k, self.plant, self.team
        try:
            self.ctrl = self.commands(self.xi)
            data = plant.data
            np.copyto(self.xpos, data.xpos)
            np.copyto(self.xmat, data.xmat)
            ncon = data.ncon
            logged = k % self.log_every == 0 or team.ended or k == self.steps
            if logged:
                plant.poses(out=self.pose)
            self.before = Before(
                self.xpos,
                self.xmat,
                data.contact.geom.copy() if ncon else None,
                data.contact.dist.copy() if ncon else None,
                ncon,
                self.pose,
            )
            if self.monitor is not None and not self.watch():
                return  # the run stops here, before the physics advances, as in one thread
            # the loop's own test for the last period (its log row marks a robot off the floor)
            leaves = logged and np.abs(self.x).max() > checks.ARENA_HALF
            if k == self.steps or team.ended or leaves:
                return
            self.stepped = True
            plant.step(self.ctrl, self.nsub)
            if self.ahead is not None:
                self.ahead()
        except BaseException as exc:  # raised by the loop where its physics step stood
            self.error = exc

    def watch(self) -> bool:
        """The premises' monitor on this period (:meth:`.premises.Monitor.period`), as the loop
        calls it after the team's step: the team's commands are out and :attr:`before` is
        what MuJoCo held before it advanced. An error is kept in :attr:`watch_error` (and
        False returned), which the loop raises where it would have called the monitor."""
        team, monitor, before = self.team, self.monitor, self.before
        assert monitor is not None and before is not None
        self.watched = True
        try:
            monitor.period(self.t, self.x, self.eta, team.u, team.u_bar, team.phi_hat, *before[:5])
        except BaseException as exc:
            self.watch_error = exc
            return False
        return True
