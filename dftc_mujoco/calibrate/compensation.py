"""The compensation loop (eqs. 28-31) on a real drive: the smallest G that does not ring and
the fastest acceleration whose jumps do not run the compensation away."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .mismatch import CONTROL_PERIOD, programme, robot_with, step_for


@dataclass(frozen=True)
class Compensation:
    """How the fault estimator's compensation loop (eqs. 28-31) behaves on the robot."""

    G: float  # the gain tried (G = g I)
    phi_p99: float  # healthy ‖φ̂‖ on the robot, 99th percentile [m/s]
    phi_max: float
    ideal: float  # the bound Φ̄ of an ideal plant with the same gains (thresholds.estimator_gain)

    @property
    def rings(self) -> bool:
        """The loop amplifies the robot's lag: healthy ‖φ̂‖ beyond 1.5 Φ̄ of an ideal plant."""
        return self.phi_p99 > 1.5 * self.ideal

    @property
    def runs_away(self) -> bool:
        """On jumping commands (:func:`acceleration`): healthy ‖φ̂‖ beyond 2 Φ̄ of an ideal
        plant at its 99th percentile. Unlimited, the diffdrive's loop runs away (53 Φ̄; 4.5
        Φ̄ at 4 m/s², 1.7 Φ̄ at 2 m/s²), and the disk's and the hexbot's jump transients
        (2.2 Φ̄, 2.1 Φ̄; 1.4 Φ̄ at 8 m/s²) put φ̂ beyond Φ̄ whenever avoidance in a crowd
        flips a command by twice the speed: a healthy hexbot was excluded on that."""
        return self.phi_p99 > 2.0 * self.ideal


G_CANDIDATES = (1.0, 1.5, 2.0, 3.0, 5.0, 10.0)  # multiples of the scenario's G tried


def compensation(
    name: str,
    scenario_name: str = "paper_case",
    seconds: float = 25.0,
    seed: int = 0,
    overrides: dict | None = None,
    lag: float = 0.0,
    measured: dict[str, float] | None = None,
) -> list[Compensation]:
    """Run the paper's fault estimator in closed loop on one robot (smooth commands, η at
    its bound) for the scenario's G (after ``overrides``) and larger ones, until the loop
    no longer rings.

    With a per-period gain h/G = 1 (the paper's G = 0.01 at h = 0.01 s) the loop is
    deadbeat on an integrator and marginal on any robot with lag: healthy ‖φ̂‖ then
    grows far beyond its ideal-plant bound and feeds the robot's commands. With ``lag`` the
    robot models its drive as the team will (``onboard/applied.py``): the estimator is
    driven by the modelled velocity, the drive by the command. ``measured``: what this
    calibration measured before (:func:`.mismatch.robot_with`).
    """
    from ..closed_loop.assembly import PAPER_G
    from ..onboard.thresholds import estimator_gain
    from ..scenario import load_scenario
    from ..sim import scene
    from ..sim.plant import Plant

    s = load_scenario(scenario_name, overrides)
    robot = robot_with(name, measured)
    sc = scene.compose(robot, np.zeros((1, 2)), timestep=step_for(robot))
    K = np.ascontiguousarray(s.gains.K, float)

    # the search starts from the scenario's G, or the paper's where it says "auto"
    g0 = PAPER_G if s.gains.G is None else float(np.asarray(s.gains.G)[0, 0])
    eta_bar = s.noise.eta_bar
    out = []
    for factor in G_CANDIDATES:
        g = g0 * factor
        data = Plant.initial_data(sc)
        drive = robot.adapter(sc, data, CONTROL_PERIOD)
        prog = programme(drive.command_limit)
        steps = min(len(prog.u) - prog.startup, round(seconds / CONTROL_PERIOD))
        u_all = prog.u[prog.startup : prog.startup + steps]
        norms = closed_loop(sc, data, drive, u_all, K, g, eta_bar, lag, seed=seed)
        settled = norms[round(1.0 / CONTROL_PERIOD) :]  # after the first second
        ideal = estimator_gain(K, g * np.eye(2), CONTROL_PERIOD, eta_bar, 0.0, lag=lag)
        result = Compensation(g, float(np.percentile(settled, 99)), float(settled.max()), ideal)
        out.append(result)
        if not result.rings:
            break
    return out


def closed_loop(
    sc: Any,
    data: Any,
    drive: Any,
    u_all: np.ndarray,
    K: np.ndarray,
    g: float,
    eta_bar: float,
    lag: float = 0.0,
    accel: float = math.inf,
    seed: int = 0,
) -> np.ndarray:
    """One robot driven by the nominal commands ``u_all`` (steps, 2) with the paper's fault
    estimator and compensation (eqs. 28-31) at G = ``g`` I in the loop, η at its bound; the
    drive modelled as the team will (``lag``; ``accel``: the nominal input's change held to
    a_max h per period, ``onboard/applied.py``). Returns ‖φ̂‖ of every period."""
    import mujoco

    from ..onboard.applied import lag_coefficients, lag_input, limit_input
    from ..onboard.fault_estimator import estimate_faults

    steps = len(u_all)
    nsub = round(CONTROL_PERIOD / sc.model.opt.timestep)
    rng = np.random.default_rng(seed)
    ang = rng.uniform(0, 2 * np.pi, steps)
    eta = eta_bar * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    site = int(sc.site[0])
    x_m = data.site_xpos[site][:2][None] + eta[:1]
    z, int_e = x_m.copy(), np.zeros((1, 2))
    phi, applied, u_bar = np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2))
    free = np.zeros(1, bool)  # no contact holds the estimator here
    g_inv = np.eye(2) / g
    ids = drive.controlled()[0]
    norms = np.empty(steps)
    lag_a, lag_b = lag_coefficients(lag, CONTROL_PERIOD)
    v_hat, command = np.zeros((1, 2)), np.zeros((1, 2))
    rows, scratch = np.zeros(1, np.int64), np.zeros((1, 2))
    calm = np.full(1, -1, np.intp)  # avoiding nothing
    step = accel * CONTROL_PERIOD
    for k in range(steps):
        x_m = data.site_xpos[site][:2][None] + eta[k]
        u = u_all[k][None].copy()
        limit_input(u, scratch, scratch.copy(), math.inf, command, rows, step, calm, step)
        if lag_a > 0.0:
            lag_input(u, v_hat, command, lag_a, lag_b)  # u: the modelled velocity
        else:
            command[:] = u
        estimate_faults(
            x_m,
            u,
            z,
            int_e,
            phi,
            applied,
            K,
            g_inv,
            CONTROL_PERIOD,
            drive.command_limit,
            1.0,
            free,
            u_bar,
        )
        norms[k] = np.linalg.norm(phi)
        data.ctrl[ids] = drive.command(command - applied)[0]  # ū (eq. 28)
        mujoco.mj_step(sc.model, data, nstep=nsub)
    return norms


ACCEL_CANDIDATES = (math.inf, 16.0, 8.0, 4.0, 2.0, 1.0, 0.5)  # a_max tried [m/s²], fastest first


def turns(limit: float, dt: float = CONTROL_PERIOD, hold: float = 2.0) -> np.ndarray:
    """Nominal commands that jump between velocities at 0.8 of the range: start, 90°
    switches, reversals, stops (what an avoidance switch or a far start asks of a drive)."""
    v = 0.8 * min(limit, 1e9) / math.sqrt(2)
    targets = [(v, 0), (0, v), (0, -v), (-v, -v), (v, v), (0, 0), (-v, 0), (v, -v), (0, 0)]
    k = round(hold / dt)
    return np.vstack([np.tile(np.asarray(t, float), (k, 1)) for t in targets])


def acceleration(
    name: str,
    G: float,
    lag: float = 0.0,
    eta_bar: float = 0.001,
    seed: int = 0,
    measured: dict[str, float] | None = None,
) -> list[tuple[float, Compensation]]:
    """The compensation loop at G on commands that jump (:func:`turns`), with the nominal
    input's change held to a_max per second for each of ``ACCEL_CANDIDATES`` until the loop
    no longer rings: a drive that cannot follow a jump (a differential drive swinging its
    offset point round) reads the jump as a fault, the compensation adds it to the command
    and the loop runs away (healthy ‖φ̂‖ 4.6 m/s measured on the diffdrive in a crowd)."""
    from ..onboard.thresholds import estimator_gain
    from ..sim import scene
    from ..sim.plant import Plant

    robot = robot_with(name, measured)
    sc = scene.compose(robot, np.zeros((1, 2)), timestep=step_for(robot))
    K = 3.0 * np.eye(2)  # the paper's K
    ideal = estimator_gain(K, G * np.eye(2), CONTROL_PERIOD, eta_bar, 0.0, lag=lag)
    out = []
    for a in ACCEL_CANDIDATES:
        data = Plant.initial_data(sc)
        drive = robot.adapter(sc, data, CONTROL_PERIOD)
        u_all = turns(drive.command_limit)
        norms = closed_loop(sc, data, drive, u_all, K, G, eta_bar, lag, accel=a, seed=seed)
        result = Compensation(G, float(np.percentile(norms, 99)), float(norms.max()), ideal)
        out.append((a, result))
        if not result.runs_away:
            break
    return out


def acceleration_report(results: list[tuple[float, Compensation]]) -> tuple[str, bool]:
    """The line to print about jumping commands, and whether it is a warning."""
    first, (a, last) = results[0][1], results[-1]
    if not first.runs_away:
        return (
            f"jumping commands: healthy |phi_hat| p99 {first.phi_p99:.3g} m/s against "
            f"Phi_bar = {first.ideal:.3g} m/s with no acceleration limit (it does not run away)",
            False,
        )
    if last.runs_away:
        return (
            f"jumping commands run the compensation loop away (|phi_hat| p99 "
            f"{first.phi_p99:.3g} m/s) even at {a:g} m/s², the least acceleration tried: this "
            "drive cannot follow the team's commands (no acceleration limit stored)",
            True,
        )
    return (
        f"jumping commands run the compensation loop away unlimited (|phi_hat| p99 "
        f"{first.phi_p99:.3g} m/s against Phi_bar = {first.ideal:.3g}); held to accel = {a:g} "
        f"m/s² it stays at {last.phi_p99:.3g} m/s: the robot limits its nominal input's "
        "change to that (onboard/applied.py)",
        False,
    )


def range_fit(
    g: float,
    limit: float,
    scenario_name: str,
    overrides: dict,
    xi_bar: float,
    lags: tuple[float, ...],
) -> tuple[float, float, float]:
    """(G, its Φ̄, Φ̄ at ``g``): the smallest of ``g`` and its multiples
    (``assembly.wider_G``) whose bound Φ̄ on a healthy robot's ‖φ̂‖ in a run (η̄ and
    ``xi_bar``, the largest of the ``lags`` the run may model) leaves a drive of per-axis
    range ``limit`` room beside the compensation's headroom (``assembly.input_limit``);
    ``g`` itself where none does."""
    from ..closed_loop.assembly import compensation_headroom, wider_G
    from ..onboard.thresholds import estimator_gain
    from ..scenario import load_scenario

    s = load_scenario(scenario_name, overrides)
    K = np.asarray(s.gains.K, float)

    def bound(x: float) -> float:
        return estimator_gain(
            K, x * np.eye(2), CONTROL_PERIOD, s.noise.eta_bar, xi_bar, lag=np.array(lags)
        )

    first = bound(g)
    if not math.isfinite(limit) or compensation_headroom(first) < limit:
        return g, first, first
    fits = wider_G(lambda m: bound(m * g), limit)
    return (fits[0] * g, fits[1], first) if fits else (g, first, first)


def range_fit_report(g: float, G: float, phi: float, first: float, limit: float) -> str | None:
    """The line to print when :func:`range_fit` raised G (``g`` → ``G``), or None."""
    if G == g:
        return None
    return (
        f"at G = {g:g} I a healthy robot's |phi_hat| bound in a run, Phi_bar = {first:.3g} "
        f"m/s (with xi_bar and the drive's lag), and the anti-windup's band take the whole "
        f"command range ±{limit:.3g} m/s; G = {G:g} I leaves it room (Phi_bar = {phi:.3g} "
        "m/s; the fault estimate settles more slowly): stored as compensation_G"
    )


def compensation_report(results: list[Compensation]) -> tuple[str, bool]:
    """The line to print about the compensation loop, and whether it is a warning."""
    first, last = results[0], results[-1]
    if not first.rings:
        return (
            f"compensation loop (G = {first.G:g} I): healthy |phi_hat| p99 "
            f"{first.phi_p99:.3g} m/s against its bound Phi_bar = {first.ideal:.3g} m/s "
            "(estimator_gain: ideal plant with the drive model; it does not ring)",
            False,
        )
    fix = (
        f"--set gains.G={last.G:g} keeps it at {last.phi_p99:.3g} m/s (ideal plant "
        f"{last.ideal:.3g})"
        if not last.rings
        else f"even G = {last.G:g} I, the top of the gains tried, does not calm it (stored "
        "all the same: the calmest tried)"
    )
    return (
        f"the compensation loop rings on this robot at G = {first.G:g} I: healthy |phi_hat| "
        f"reaches {first.phi_p99:.3g} m/s (p99; max {first.phi_max:.3g}) against "
        f"{first.ideal:.3g} m/s on an ideal plant, and the robot's commands carry it; {fix}",
        True,
    )
