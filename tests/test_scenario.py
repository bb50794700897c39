"""Bad input gets one clear line (file, key, what was expected) and a non-zero exit."""

import subprocess
import sys

import numpy as np
import pytest

from dftc_mujoco import load_scenario, run, scenario
from dftc_mujoco.errors import ScenarioError
from tests.conftest import scenario_dict

GOOD = (scenario.SCENARIOS / "paper_case.toml").read_text()


def _variant(old: str, new: str) -> str:
    assert old in GOOD, old
    return GOOD.replace(old, new, 1)


BAD = {
    "unknown key": (_variant("seed = 1", "seed = 1\nsede = 2"), "sede: unknown key"),
    "missing key": (_variant("kc = 4.0      # eq. 15", ""), "gains.kc: missing key"),
    "wrong type": (_variant("robots = 4", 'robots = "four"'), "team.robots: expected an integer"),
    "wrong shape": (
        _variant("[-0.10, 0.40]]", "[-0.10]]"),
        "team.initial_positions: expected a list of 4 [x, y] pairs",
    ),
    "robot out of range": (_variant("[4, 2]]", "[4, 5]]"), "robot 5 out of range"),
    "edge to itself": (_variant("[4, 2]]", "[4, 4]]"), "goes from a robot to itself"),
    "not strongly connected": (
        _variant("[[1, 2], [2, 3], [3, 4], [4, 1], [4, 2]]", "[[1, 2], [2, 3], [3, 4]]"),
        "expected a strongly connected graph",
    ),
    "control period": (
        _variant("control_period = 0.01 ", "control_period = 0.007 "),
        "expected a whole multiple of timestep",
    ),
    "fault after end": (_variant("t = 41.8", "t = 61.0"), "after the end of the run"),
    "fault robot": (_variant("robot = 1\nkind", "robot = 9\nkind"), "faults[2].robot"),
    "fault kind": (_variant('kind = "stop"', 'kind = "explode"'), "expected one of 'bias'"),
    "not toml": ("name = ", "not valid TOML"),
    "unstable observer": (_variant("ko = 6.0", "ko = 60.0"), "observer update is unstable"),
    "safe distance": (
        _variant("safe_distance = 0.37", "safe_distance = 0.1"),
        "obstacles[1].safe_distance",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_scenario_one_line_and_exit_2(case, tmp_path, capsys):
    text, expected = BAD[case]
    path = tmp_path / "bad.toml"
    path.write_text(text)
    code = run.main([str(path), "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert expected in err
    assert str(path) in err  # names the file
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_cli_errors_in_a_real_process(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(BAD["edge to itself"][0])
    for args in (
        [str(path)],
        ["no_such_scenario"],
        ["paper_case", "--robot", "tank"],
        ["paper_case", "--duration", "-3"],
    ):
        p = subprocess.run(
            [sys.executable, "-m", "dftc_mujoco.run", *args],
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert p.returncode == 2, p.stderr
        assert "Traceback" not in p.stderr
        assert p.stderr.startswith("error: ")


def test_load_by_name_and_by_path():
    a = scenario.load("paper_case")
    b = scenario.load(scenario.SCENARIOS / "paper_case.toml")
    assert a.name == b.name == "paper_case"
    assert a.team.robots == 4 and a.faults[0].robot == 1  # robot 2, 0-based inside


def test_paper_case_matches_the_paper():
    s = scenario.load("paper_case")
    assert (s.gains.kc, s.gains.ko) == (4.0, 6.0)
    assert (s.gains.K == 3 * np.eye(2)).all() and s.gains.G is None  # "auto": the robot's
    from dftc_mujoco.closed_loop.assembly import effective_G
    from dftc_mujoco.sim import robots

    assert (effective_G(s, robots.get("disk")) == 0.01 * np.eye(2)).all()  # the paper's G
    assert (effective_G(s, robots.get("diffdrive")) == 0.02 * np.eye(2)).all()  # calibrated
    assert (s.noise.eta_bar, s.noise.xi_bar) == (0.001, None)  # ξ̄ from the robot model
    from dftc_mujoco.closed_loop.loop import effective_xi_bar
    from dftc_mujoco.sim import robots

    assert effective_xi_bar(s, robots.get("disk")) == 0.005  # the paper's value
    assert set(s.team.graph.edges) == {(0, 1), (1, 2), (2, 3), (3, 0), (3, 1)}
    assert not any(0 in (j, i) and i in (2, 3) for j, i in s.team.graph.edges)
    assert s.team.graph.without(0).is_strongly_connected()
    bias, stop = s.faults
    assert (bias.robot, bias.kind, bias.t, bias.time_constant) == (1, "bias", 19.0, 0.45)
    assert list(bias.value) == [0.3, -0.35]
    assert (stop.robot, stop.kind, stop.t) == (0, "stop", 41.8)


def test_duration_override_drops_later_faults():
    s = scenario.load("paper_case")
    short = s.with_overrides(duration=30.0)
    assert [f.kind for f in short.faults] == ["bias"]
    assert [f.kind for f in scenario.dropped_faults(s, short)] == ["stop"]
    with pytest.raises(ScenarioError, match="--seed"):
        s.with_overrides(seed=-1)


def test_dict_validation_names_nested_keys():
    d = scenario_dict()
    d["mission"]["centroid"]["speed"] = -1
    with pytest.raises(ScenarioError, match=r"mission\.centroid\.speed: expected a number > 0"):
        scenario.from_dict(d, source="x.toml")


def test_generated_start_layouts_for_untuned_batteries():
    """random: uniform around the path's start, points at least ``spacing`` apart; circle: on
    a circle in a shuffled order; an impossible random layout is one line naming the key."""
    base = {
        "team.robots": 40,
        "team.graph": {"family": "ring_chords", "chords": [2]},
        "fdir.initial_error_bound": "auto",
        "obstacles": [],
    }
    rand = load_scenario(
        "paper_case",
        {**base, "team.initial_positions": {"layout": "random", "spread": 4.0, "spacing": 0.6}},
    )
    x = np.asarray(rand.team.initial_positions)
    gaps = np.linalg.norm(x[:, None] - x[None], axis=-1) + np.eye(40) * 9
    assert gaps.min() >= 0.6 and np.abs(x).max() <= 4.0
    circle = load_scenario(
        "paper_case", {**base, "team.initial_positions": {"layout": "circle", "radius": 7.0}}
    )
    r = np.linalg.norm(np.asarray(circle.team.initial_positions), axis=1)
    np.testing.assert_allclose(r, 7.0)
    again = load_scenario(
        "paper_case", {**base, "team.initial_positions": {"layout": "circle", "radius": 7.0}}
    )
    assert np.array_equal(again.team.initial_positions, circle.team.initial_positions)
    with pytest.raises(ScenarioError) as err:
        load_scenario(
            "paper_case",
            {**base, "team.initial_positions": {"layout": "random", "spread": 1.0}},
        )
    assert "team.initial_positions.spread: 40 robots 0.5 m apart do not fit within ±1 m" in str(
        err.value
    )
