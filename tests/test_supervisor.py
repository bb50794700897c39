"""Teammate avoidance by the supervisor (issue 20): teammates are obstacles of the null-space
behaviour of eqs. 17-18, so crossing robots keep apart and their residuals stay unaffected."""

from __future__ import annotations

import numpy as np
import pytest

from dftc_mujoco import load_scenario, simulate
from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.onboard.supervisor import supervise
from tests.test_premises import shuffled


def test_two_robots_heading_at_each_other_are_held_at_the_safe_distance():
    """Eq. 18 with the teammate as obstacle: the radial part of the input is replaced by
    θ(d − ‖xᵢ − x_j‖), the tangential part is kept."""
    x = np.array([[0.0, 0.0], [0.25, 0.0]])
    u_g = np.array([[1.0, 0.2], [-1.0, 0.0]])
    active = np.full(2, -1, dtype=np.intp)
    u, du = np.empty((2, 2)), np.empty((2, 2))
    none = np.zeros((0, 2))
    theta, safe = 3.0, 0.22
    supervise(x, u_g, none, np.zeros(0), np.zeros(0), theta, 0.01, active, u, du, x, safe, 0.32)
    assert list(active) == [1, 0]  # each avoids the other (obstacle index O + j, O = 0)
    away = theta * (safe - 0.25)  # radial speed allowed: −0.09 m/s towards the teammate
    assert u[0] == pytest.approx([-away, 0.2])
    assert u[1] == pytest.approx([away, 0.0])
    np.testing.assert_allclose(du, u - u_g)
    supervise(x, u_g, none, np.zeros(0), np.zeros(0), theta, 0.01, active, u, du, x, 0.0, 0.0)
    assert list(active) == [-1, -1] and np.array_equal(u, u_g)  # off: the paper's behaviour


def test_robots_crossing_the_circle_to_their_slots_do_not_collide_or_flag():
    """12 robots start on their formation circle in a shuffled order, with contacts on: their
    paths cross. Without teammate avoidance they collide and healthy robots are flagged;
    with it (the default) no contact happens and nobody is flagged or excluded."""
    over = shuffled(12, 30.0, **{"physics.robot_contacts": True})
    off = simulate(load_scenario("paper_case", {**over, "supervisor.avoid_teammates": False}))
    contacts = [e for e in off.events.of_kind("premise_violated") if e["premise"] == "contact"]
    assert contacts and off.summary["healthy_flags"] > 0
    on = simulate(load_scenario("paper_case", over))
    contacts = [e for e in on.events.of_kind("premise_violated") if e["premise"] == "contact"]
    assert contacts == []
    assert on.summary["healthy_flags"] == 0 and on.events.of_kind("exclusion") == []
    avoided = {e["obstacle"] for e in on.events.of_kind("reactive_on")}
    assert any(a.startswith("robot") for a in avoided)
    assert on.summary["errors"]["final_formation"] < 0.01


def test_a_bad_teammate_distance_is_one_line_naming_the_key():
    with pytest.raises(ScenarioError, match=r"supervisor\.teammate_distance") as err:
        load_scenario("paper_case", {"supervisor.teammate_distance": "far"})
    assert 'expected a distance in m or "auto"' in str(err.value)


@pytest.mark.parametrize("model", ["disk", "diffdrive"])
def test_no_contact_between_teammates_in_paper_case(model):
    """paper_case (robot contacts on) with teammate avoidance: no hull ever touches another
    robot or a cylinder, before or after robot 1 is excluded; its outcome is the paper's."""
    r = simulate(load_scenario("paper_case", {"team.robot_model": model}))
    out = r.summary
    assert out["premises"]["contact"]["held"], out["premises"]["contact"]
    assert not [e for e in r.events.of_kind("premise_violated") if e["premise"] == "contact"]
    assert [e["robot"] for e in out["exclusions"]] == [1]
    assert not [e for e in out["events"] if e["kind"] == "exclusion_postponed"]
