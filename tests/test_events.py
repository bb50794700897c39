"""Events: every kind a run emits is listed in ``events.KINDS`` with its fields, and
``events.describe`` puts each into one line of words (the console, the summary's warnings
and the video captions use it)."""

from __future__ import annotations

import json
from pathlib import Path

from dftc_mujoco import load_scenario, simulate
from dftc_mujoco.core import events

DATA = Path(__file__).parent / "data"


def _check(items):
    for e in items:
        kind = e["kind"]
        assert kind in events.KINDS, kind
        assert set(e) - {"t", "kind"} <= set(events.KINDS[kind]), (kind, sorted(e))
        line = events.describe(e)
        assert "\n" not in line and not line.startswith(f"{kind} {{"), line


def test_every_event_of_paper_case_is_a_known_kind_in_one_line():
    _check(json.loads((DATA / "paper_case_events.json").read_text()))


def test_the_recovery_events_are_known_kinds_in_one_line():
    """A line whose middle robot stops and is excluded with neither a relay nor a re-wiring
    (``fdir.rewire = "none"``): exclusion, split, horizon and scheduling events all have
    their words."""
    line = [[1, 2], [2, 1], [2, 3], [3, 2], [3, 4], [4, 3]]
    s = load_scenario(
        "paper_case",
        {
            "team.graph": line,
            "faults": [{"robot": 2, "kind": "stop", "t": 30.0}],
            "fdir.dt_d_max": "auto",
            "fdir.rewire": "none",
            "onboard.thresholds": "l1",
            "duration": 40.0,
        },
    )
    items = simulate(s).events.items
    kinds = {e["kind"] for e in items}
    assert {"exclusion", "graph_not_strongly_connected", "detection_horizon"} <= kinds
    _check(items)


def test_an_event_is_made_only_with_the_fields_its_kind_declares():
    """events.make is the one constructor: a kind or a field KINDS does not list is refused
    (the summary's readers and describe() rely on the fields)."""
    import pytest

    e = events.make(1.5, "exclusion", robot=2, flagged_by=[1], detected_by=[1, 3])
    assert e == {
        "t": 1.5,
        "kind": "exclusion",
        "robot": 2,
        "flagged_by": [1],
        "detected_by": [1, 3],
    }
    with pytest.raises(ValueError, match="unknown event kind 'exclusoin'"):
        events.make(1.5, "exclusoin", robot=2)
    with pytest.raises(ValueError, match="has no field"):
        events.make(1.5, "reactive_off", robot=2, obstacle="cylinder 1")


def test_the_event_record_types_every_field_a_kind_declares():
    """``events.Event`` (the type checker's view) lists exactly ``t``, ``kind`` and the
    fields of :data:`events.KINDS`: a field declared for a kind is typed, and none is typed
    that no kind carries."""
    declared = {f for fields in events.KINDS.values() for f in fields}
    assert set(events.Event.__annotations__) == {"t", "kind"} | declared
    assert set(events.KINDS) == set(events.Kind)
