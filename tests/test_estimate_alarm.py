"""Each robot's own alarm from its fault estimate (onboard/estimate_alarm.py), which confirms
an exclusion: raised after a decision window out of Φ̄ (or with ū out of range), lowered after
as long back in, and what the recovery asks of it. In a run: the healthy robot it keeps is
tests/test_recovery.py's start-up case; paper_case's stopped robot is still excluded at its
t_r of 50.07 s with nothing postponed, on both paths (tests/test_hostile.py); the timers of
both paths agree (tests/test_onboard.py)."""

from __future__ import annotations

import numpy as np

from dftc_mujoco.onboard.estimate_alarm import EstimateAlarm


def _run(alarm: EstimateAlarm, phi: list[float], u_bar: float = 0.0) -> list[bool]:
    """Robot 0's alarm after each period with ‖φ̂‖ = ``phi[j]`` (robot 1 stays at 0)."""
    ups = []
    for p in phi:
        phi_hat = np.array([[p, 0.0], [0.0, 0.0]])
        alarm.step(phi_hat, np.array([[u_bar, 0.0], [0.0, 0.0]]))
        ups.append(bool(alarm.alarm[0]))
    return ups


def test_the_alarm_needs_a_whole_window_out_and_as_long_back_in():
    alarm = EstimateAlarm(2, phi_bar=0.2, limit=0.7, need=3)
    # two periods out, one in, three out: up at the third of the three
    assert _run(alarm, [0.3, 0.3, 0.1, 0.3, 0.3, 0.3]) == [False] * 5 + [True]
    # down after three periods back within Φ̄, not before
    assert _run(alarm, [0.1, 0.1, 0.1]) == [True, True, False]
    assert not alarm.alarm[1] and not alarm.seen[1]  # robot 1 never left its bound


def test_a_command_out_of_range_counts_as_out_even_with_a_small_estimate():
    alarm = EstimateAlarm(2, phi_bar=0.2, limit=0.7, need=2)
    assert _run(alarm, [0.05, 0.05], u_bar=0.75) == [False, True]
    assert _run(alarm, [0.05, 0.05], u_bar=0.69) == [True, False]


def test_a_first_judgement_needs_the_estimate_out_for_the_hold_a_later_one_a_new_alarm():
    """At a robot's first judgement (its t_r) its estimate must have been out for the hold
    (the window and twice its response time) in a row: an alarm that went up after the first
    flag and came down, or went up too lately (a healthy robot's own break of the premises),
    does not confirm. At a later judgement (``again``) an alarm that went up since the last
    one does: an intermittent fault off at its t_r is excluded at the next."""
    alarm = EstimateAlarm(2, phi_bar=0.2, limit=0.7, need=2, hold=4)
    _run(alarm, [0.3, 0.3, 0.3])  # up at the 2nd period, out for 3
    assert alarm.alarm[0] and alarm.timer[0] == 3
    assert not alarm.confirms(0)  # up, but not out for the hold yet
    _run(alarm, [0.3])
    assert alarm.confirms(0)  # out for 4 periods in a row
    _run(alarm, [0.0, 0.0])  # down at the 2nd period back in
    assert not alarm.alarm[0] and not alarm.confirms(0)
    assert not alarm.confirms(0, again=True)  # no alarm went up since the last question
    _run(alarm, [0.3, 0.3, 0.0, 0.0])  # up and down again before the next judgement
    assert alarm.confirms(0, again=True)  # it went up since the last judgement
    assert not alarm.confirms(0, again=True)  # and not since that one
    assert alarm.confirms(0, heard=False)  # unheard (a silent radio) is not healthy
    off = EstimateAlarm(2, phi_bar=np.inf, limit=0.7, need=2)
    assert not off.on and off.confirms(0)  # no bound known: the check is off


def test_the_hold_is_the_window_and_twice_the_robots_response_time():
    """The robots' calibrated response time reaches the alarm: the disk's 0.06 s, the
    diffdrive's 0.52 s (their robot files), twice, past the 0.2 s window."""
    from dftc_mujoco import load_scenario
    from dftc_mujoco.closed_loop.assembly import team_config
    from dftc_mujoco.sim import robots

    s = load_scenario("paper_case")
    for model, response in (("disk", 0.06), ("diffdrive", 0.52)):
        robot = robots.get(model)
        assert robot.response_time == response
        alarm = EstimateAlarm.of(team_config(s, robot), 4)
        assert (alarm.need, alarm.hold) == (20, 20 + round(2 * response / 0.01))
