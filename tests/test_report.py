"""What ``python -m dftc_mujoco.run`` prints, read as a newcomer reads it: a first line that
says what runs, one verdict per question (mission, faults, false alarms, obstacles,
premises), the developer's figures only behind ``--verbose``. Every run here is a real run
of paper_case on MuJoCo."""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from dftc_mujoco import run

#: words of the onboard code's developers that the default output must not use
INTERNAL = ("eq.", "Δt_d", "compiled path", "general path", "set-up", "task errors")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """paper_case to 60 s and cut at 47 s (before its stop's exclusion is due), printed plainly
    and with --verbose."""
    out = {}
    for name, extra in (("full", []), ("cut", ["--duration", "47"]), ("verbose", ["--verbose"])):
        folder = tmp_path_factory.mktemp(name)
        args = ["paper_case", "--no-video", "--no-progress", "--out", str(folder / "run")]
        text = io.StringIO()
        with contextlib.redirect_stdout(text):
            assert run.main([*args, *extra]) == 0
        out[name] = (text.getvalue(), json.loads((folder / "run" / "summary.json").read_text()))
    return out


def _line(text: str, head: str) -> str:
    (line,) = [x for x in text.splitlines() if x.startswith(head)]
    return line


def test_each_question_gets_one_verdict(runs):
    text, summary = runs["full"]
    assert text.splitlines()[0] == "paper_case: 4 robots (disk), 60 s of mission, seed 1"
    assert _line(text, "mission:").startswith("mission:      completed: the 3 robots left ended")
    faults = text[text.index("faults:") : text.index("false alarms:")].splitlines()
    assert faults[0].startswith("faults:       bias on robot 2 at 19.00 s: compensated on board")
    excluded = [f for f in summary["fault_outcomes"] if f["outcome"] == "excluded"]
    assert [f["robot"] for f in excluded] == [1]
    assert faults[1].strip().startswith("stop on robot 1 at 41.80 s: flagged")
    assert f"excluded at {excluded[0]['excluded_at']:.2f} s" in faults[1]
    assert _line(text, "false alarms:").startswith("false alarms: none (")
    assert _line(text, "obstacles:").startswith("obstacles:    no contact")
    held = "premises:     all held (what the detection thresholds assume)"
    assert _line(text, "premises:") == held
    assert not [w for w in INTERNAL if w in text], text


def test_a_stop_whose_exclusion_falls_after_the_end_says_so(runs):
    """Cut at 47 s, robot 1 was flagged but its exclusion was due later: the line says why it
    was not excluded, instead of a bare "NOT excluded"."""
    text, summary = runs["cut"]
    (stop,) = [f for f in summary["fault_outcomes"] if f["kind"] == "stop"]
    assert stop["outcome"] == "detected" and stop["excluded_at"] is None
    (due,) = [e["t_r"] for e in summary["events"] if e["kind"] == "exclusion_scheduled"]
    assert due > 47.0
    assert f"NOT excluded before the run ended (its exclusion was due at {due:.2f} s)" in text
    assert _line(text, "mission:").startswith("mission:      NOT completed")


def test_verbose_adds_the_developers_figures(runs):
    plain, _ = runs["full"]
    text, summary = runs["verbose"]
    assert _line(text, "onboard:").startswith(f"onboard: {summary['onboard']['path']} path")
    assert _line(text, "task errors (eqs. 9-12)")
    assert _line(text, "set-up ")
    assert len(text.splitlines()) > len(plain.splitlines())
