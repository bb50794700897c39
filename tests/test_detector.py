"""The detector plug-in point (``[onboard] detector``): separate from the observer, given the
residual's ingredients and the observer's messages, local, and compared with the paper's
in one campaign (examples/detectors_campaign.toml)."""

import sys
from pathlib import Path

import numpy as np
import pytest

from dftc_mujoco import check_locality, load_scenario, simulate
from dftc_mujoco.blocks import paper
from dftc_mujoco.campaign import spec as campaign_spec

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture(autouse=True)
def _examples_on_path(monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))


def _events(r, *kinds):
    return [e for e in r.events.items if e["kind"] in kinds]


def test_the_paper_detector_is_the_default_and_changes_nothing():
    s = load_scenario("paper_case")
    assert s.onboard.detector == "paper"
    r = simulate(s, progress=False)
    assert r.summary["onboard"]["path"] == "compiled"
    assert [e["robot"] for e in _events(r, "exclusion")] == [1]


def test_a_neighbour_only_detector_flags_the_stop_sooner_and_only_its_listener_does():
    """examples/mylab/neighbours.py on paper_case: robot 2 (robot 1's only listener) flags
    its stop within a second (the paper's detector: 3.27 s), robot 1 its own, nobody else
    is flagged and robot 1 is excluded."""
    s = load_scenario(
        "paper_case", overrides={"onboard.detector": "mylab.neighbours:NeighbourMonitor"}
    )
    r = simulate(s, progress=False)
    assert r.summary["onboard"]["path"] == "general"
    found = [(e["by"], e["robot"], e["t"]) for e in _events(r, "detection")]
    assert {(b, k) for b, k, _ in found} == {(2, 1), (1, 1)}
    first = min(t for b, k, t in found if b == 2)
    assert 41.8 < first < 41.8 + 1.0
    assert [e["robot"] for e in _events(r, "exclusion")] == [1]


class _Peeking(paper.Detector):
    """Judges robot k by the estimate of robot k held by robot k + 1, which nobody but
    robot k + 1's listeners may read: check_locality must catch it."""

    def judge(self, r_norm, mu, observer, x_m):
        m = len(r_norm)
        y = observer.y_hat
        score = np.array([[np.abs(y[(k + 1) % m, k]).sum() for k in range(m)] for _ in range(m)])
        return score, np.full((m, m), 1e9)


def test_a_detector_is_checked_for_locality():
    sys.modules.pop("mylab.neighbours", None)
    from mylab.neighbours import NeighbourMonitor

    assert check_locality({"detector": NeighbourMonitor(after=0.0)}) == []
    assert check_locality({"detector": NeighbourMonitor(after=0.0)}, networked=True) == []
    assert check_locality({"detector": _Peeking()})


def test_the_two_detectors_compare_in_one_campaign():
    """The first draw of examples/detectors_campaign.toml with each method: the same
    scenario but for the detector."""
    s = campaign_spec.load(EXAMPLES / "detectors_campaign.toml")
    a, b = campaign_spec.draw(s, 0), campaign_spec.draw(s, 1)
    assert (a["method"], b["method"]) == ("paper", "neighbours")
    sa, sb = campaign_spec.scenario_for(s, a), campaign_spec.scenario_for(s, b)
    assert sb.onboard.detector == "mylab.neighbours:NeighbourMonitor"
    da, db = sa.to_dict(), sb.to_dict()
    assert da["onboard"]["detector"] == "paper"
    for d in (da, db):
        del d["onboard"], d["name"]
    assert da == db
