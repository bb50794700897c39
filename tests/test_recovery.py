"""The exclusion protocol (eqs. 42-43, ``onboard/recovery.py``): one exclusion instant per
robot from its first flag, cancelled when nobody flags it at that instant."""

from __future__ import annotations

from dftc_mujoco.onboard.recovery import Recovery


def test_the_first_flag_fixes_the_common_instant_and_later_flags_do_not_move_it():
    rec = Recovery(dt_d_max=5.0)
    first = rec.flagged(10.0, [(2, 1)])
    assert [e["kind"] for e in first] == ["detection", "exclusion_scheduled"]
    assert first[1]["t_r"] == 15.0 and first[1]["robot"] == 2
    later = rec.flagged(12.0, [(3, 1), (2, 1)])  # a new flagger; a pair already reported
    assert [(e["kind"], e["by"]) for e in later] == [("detection", 4)]
    assert rec.pending == {1: 15.0}
    assert rec.due(14.99) == []
    assert rec.due(15.0) == [1] and rec.pending == {}


def test_due_robots_come_earliest_first_and_a_cancelled_one_can_be_scheduled_again():
    rec = Recovery(dt_d_max=2.0)
    rec.flagged(3.0, [(0, 2)])
    rec.flagged(1.0, [(0, 3)])
    assert rec.due(10.0) == [3, 2]
    cancelled = rec.cancel(10.0, 2)
    assert cancelled["kind"] == "exclusion_cancelled" and cancelled["detected_by"] == [1]
    again = rec.flagged(11.0, [(0, 2)])  # forgotten: a new flag is a new detection
    assert [e["kind"] for e in again] == ["detection", "exclusion_scheduled"]
    assert again[1]["t_r"] == 13.0


def test_an_exclusion_names_who_flags_at_t_r_and_who_ever_detected():
    rec = Recovery(dt_d_max=1.0)
    rec.flagged(0.5, [(0, 1), (2, 1), (3, 1)])
    assert rec.due(1.5) == [1]
    e = rec.exclusion(1.5, 1, flaggers=[3, 4])
    assert e == {"t": 1.5, "kind": "exclusion", "robot": 2, "flagged_by": [3, 4],
                 "detected_by": [1, 3, 4]}  # fmt: skip
