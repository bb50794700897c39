"""The scenario API: overrides, [onboard], round trips, validation on every path, all errors."""

from __future__ import annotations

import dataclasses
import pickle
import tomllib
from pathlib import Path

import numpy as np
import pytest

from dftc_mujoco import scenario
from dftc_mujoco.campaign import spec as campaign_spec
from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.scenario import Gains, Onboard, Scenario
from tests.conftest import make, scenario_dict

GOOD = (scenario.SCENARIOS / "paper_case.toml").read_text()


def _variant(*pairs: tuple[str, str]) -> str:
    text = GOOD
    for old, new in pairs:
        assert old in text, old
        text = text.replace(old, new, 1)
    return text


def _error(fn, *args, **kwargs) -> str:
    with pytest.raises(ScenarioError) as info:
        fn(*args, **kwargs)
    return str(info.value)


def _arrays(s: Scenario) -> list[np.ndarray]:
    """Every numpy field of a scenario, in a fixed order."""
    out = [s.team.initial_positions, s.gains.K, s.mission.centroid.waypoints]
    out += [] if s.gains.G is None else [s.gains.G]
    out += [o.position for o in s.obstacles] + [f.value for f in s.faults]
    return out


# --------------------------------------------------------------------------- overrides


def test_load_scenario_applies_dotted_overrides():
    s = scenario.load_scenario("paper_case", {"gains.ko": 3, "duration": 40})
    assert s.gains.ko == 3.0 and s.duration == 40.0
    assert [f.kind for f in s.faults] == ["bias"]  # the stop at 41.8 s is after the new end
    s = scenario.load_scenario(
        "paper_case",
        {"onboard.thresholds": "paper", "noise.at_bound": True, "faults.1.t": 12.5},
    )
    assert s.noise.at_bound and s.faults[0].t == 12.5 and s.onboard.thresholds == "paper"
    assert s.source == str(scenario.SCENARIOS / "paper_case.toml")
    assert scenario.load_scenario("paper_case", None).gains.ko == 6.0


def test_apply_overrides_copies_and_creates_tables():
    d = scenario_dict()
    out = scenario.apply_overrides(
        d, {"fdir.detection_window": 0.3, "onboard.params.controller.gain": 2.0}, where="x"
    )
    assert out["fdir"]["detection_window"] == 0.3
    assert out["onboard"] == {"params": {"controller": {"gain": 2.0}}}
    assert "onboard" not in d and d["fdir"]["detection_window"] == 0.2  # input untouched
    out = scenario.apply_overrides(d, {"noise.xi_bar": 0.01, "faults.2.value": (1, 2)}, "x")
    assert out["noise"]["xi_bar"] == 0.01 and out["faults"][1]["value"] == [1, 2]
    assert "xi_bar" not in scenario.apply_overrides(out, {"noise.xi_bar": None}, "x")["noise"]


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        ({"duration.x": 1}, "x.toml (override): duration.x: expected duration to be a table"),
        ({"faults.3.t": 1.0}, "faults.3.t: expected an index 1..2 into the array faults"),
        ({"faults.first.t": 1.0}, "faults.first.t: expected an index 1..2"),
        ({"gains..ko": 1.0}, 'gains..ko: expected a dotted key such as "gains.ko"'),
        # it was "faults[0]: unknown key"
        ({"faults[0].t": 1.0}, 'items numbered from 1 after a dot (e.g. "faults.1.t")'),
    ],
)
def test_bad_override_keys_are_named(overrides, expected):
    assert expected in _error(
        scenario.apply_overrides, scenario_dict(), overrides, "x.toml (override)"
    )


def test_bad_override_values_say_they_come_from_an_override():
    path = scenario.SCENARIOS / "paper_case.toml"
    msg = _error(scenario.load_scenario, "paper_case", {"gains.ko": -1})
    assert msg == f"{path} (override): gains.ko: expected a number > 0, got -1"
    msg = _error(scenario.load_scenario, "paper_case", {"duration.x": 1, "faults.9.t": 1})
    assert msg.splitlines() == [
        f"{path} (override): duration.x: expected duration to be a table, got float 60.0",
        f"{path} (override): faults.9.t: expected an index 1..2 into the array faults, got '9'",
    ]
    msg = _error(scenario.load_scenario, "paper_case", {"gains.ko": 60})
    assert "(override): gains.ko: the observer update is unstable" in msg


# --------------------------------------------------------------------------- all errors at once


def test_several_errors_are_reported_together_in_file_order(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(
        _variant(
            ("kc = 4.0", 'kc = "fast"'),
            ("log_rate = 50.0", "log_rate = 50.0\nspeed = 3"),
            ("robot = 1\nkind", "robot = 9\nkind"),
        )
    )
    assert _error(scenario.load, path).splitlines() == [
        f"{path}: physics.speed: unknown key (known keys here: control_period, log_rate, "
        "matrix_log_rate, robot_contacts, timestep)",
        f"{path}: gains.kc: expected a number, got str 'fast'",
        f"{path}: faults[2].robot: robot 9 out of range: robots are numbered 1..4",
    ]


def test_errors_in_every_section_and_no_follow_on_errors():
    d = scenario_dict()
    d["seed"] = -1
    d["physics"]["timestep"] = "small"  # control_period's multiple check is skipped
    d["physics"]["zz"] = d["physics"]["aa"] = 1  # every unknown key
    d["team"]["robots"] = "four"  # checks that need N are skipped
    d["team"]["graph"][1] = [2, 2]
    d["mission"]["centroid"]["speed"] = 0
    d["obstacles"][1]["radius"] = -1  # safe_distance > radius is skipped
    d["fdir"]["enabled"] = "yes"
    lines = _error(scenario.from_dict, d, "x.toml").splitlines()
    assert lines == [
        "x.toml: seed: expected an integer >= 0, got -1",
        "x.toml: physics.timestep: expected a number, got str 'small'",
        "x.toml: physics.zz: unknown key (known keys here: control_period, log_rate, "
        "matrix_log_rate, robot_contacts, timestep)",
        "x.toml: physics.aa: unknown key (known keys here: control_period, log_rate, "
        "matrix_log_rate, robot_contacts, timestep)",
        "x.toml: team.robots: expected an integer, got str 'four'",
        "x.toml: team.graph[2]: edge [2, 2] goes from a robot to itself",
        "x.toml: mission.centroid.speed: expected a number > 0, got 0",
        "x.toml: obstacles[2].radius: expected a number > 0, got -1",
        "x.toml: fdir.enabled: expected true or false, got str 'yes'",
    ]


def test_a_broken_section_does_not_hide_the_others():
    d = scenario_dict()
    d["team"] = 5
    d["mission"]["formation"] = "square"
    d["faults"] = {"robot": 1}
    d["gains"]["ko"] = 600.0  # the observer check needs the team: skipped
    assert _error(scenario.from_dict, d, "x.toml").splitlines() == [
        "x.toml: team: expected a table, got int 5",
        "x.toml: mission.formation: expected a table, got str 'square'",
        "x.toml: faults: expected an array of tables ([[faults]]), got a table",
    ]
    d = scenario_dict()
    del d["mission"]  # a generated layout then cannot be made: no error of its own
    d["team"]["initial_positions"] = {"layout": "formation", "jitter": 0.1}
    d["team"]["graph"] = {"family": "knn", "k": 2}
    assert _error(scenario.from_dict, d, "x.toml") == "x.toml: mission: missing key"


def test_a_single_error_keeps_its_one_line_message():
    d = scenario_dict()
    del d["gains"]["kc"]
    assert _error(make, d, "x.toml") == "x.toml: gains.kc: missing key"
    assert (
        _error(scenario.from_dict, [1], "x.toml")
        == "x.toml: (top level): expected a table, got [1]"
    )


# --------------------------------------------------------------------------- [onboard]

ONBOARD = """
[onboard]
thresholds = "paper"
controller = "mylab.control:Lyapunov"
[onboard.params.controller]
gain = 2.0
limits = [1, 2]
"""


def test_onboard_table():
    s = scenario.from_dict(tomllib.loads(GOOD + ONBOARD), "x.toml")
    ob = s.onboard
    assert (ob.controller, ob.thresholds, ob.observer) == (
        "mylab.control:Lyapunov",
        "paper",
        "paper",
    )
    assert ob.params == {"controller": {"gain": 2.0, "limits": [1, 2]}}
    with pytest.raises(TypeError):
        ob.params["observer"] = {}  # type: ignore[index]
    with pytest.raises(TypeError):
        ob.params["controller"]["gain"] = 3.0  # type: ignore[index]
    assert pickle.loads(pickle.dumps(s)).onboard == ob
    assert scenario.load("paper_case").onboard == Onboard()


def test_onboard_errors():
    d = tomllib.loads(GOOD + ONBOARD)
    d["onboard"]["observer"] = "not a path"
    d["onboard"]["decision"] = 3
    d["onboard"]["colour"] = "red"
    d["onboard"]["params"]["estimator"] = {"gain": 1}
    d["onboard"]["params"]["controller"]["not-a-name"] = 1
    d["onboard"]["params"]["supervisor"] = 4
    lines = _error(scenario.from_dict, d, "x.toml").splitlines()
    assert lines == [  # in file order: the keys added above come after [onboard.params]
        "x.toml: onboard.params.controller.not-a-name: expected a keyword argument name, "
        "got 'not-a-name'",
        "x.toml: onboard.params.estimator: unknown block (blocks: observer, controller, "
        "supervisor, fault_estimator, thresholds, detector, decision)",
        "x.toml: onboard.params.supervisor: expected a table, got int 4",
        "x.toml: onboard.observer: expected a built-in name ('paper') or an import path "
        "\"module:Class\", got 'not a path'",
        "x.toml: onboard.decision: expected a string, got int 3",
        "x.toml: onboard.colour: unknown key (known keys here: controller, decision, "
        "detector, fault_estimator, observer, params, supervisor, thresholds)",
    ]


def test_directory_is_the_scenario_files_folder(tmp_path):
    assert scenario.load("paper_case").directory == scenario.SCENARIOS.absolute()
    path = tmp_path / "mine.toml"
    path.write_text(GOOD)
    assert scenario.load(path).directory == tmp_path.absolute()
    assert make(scenario_dict()).directory is None  # source "<test>"


# --------------------------------------------------------------------------- round trip


def _custom() -> Scenario:
    """Generated layout and graph, faults, obstacles, onboard params, ξ̄ and a 2x2 gain."""
    d = tomllib.loads(GOOD + ONBOARD)
    d["description"] = 'quotes " and \\ backslash,\ttab, newline\n and ≈ unicode'
    d["team"]["initial_positions"] = {"layout": "formation", "jitter": 0.07}
    d["team"]["graph"] = {"family": "knn", "k": 2}
    d["noise"]["xi_bar"] = 0.0071
    d["gains"]["K"] = [[3.0, 0.1], [0.1, 2.0]]
    d["onboard"]["params"]["decision"] = {"mode": "strict", "nested": {"a": [1.5, 2]}}
    d["obstacles"][0]["height"] = 1 / 3
    return scenario.from_dict(d, "custom.toml")


@pytest.mark.parametrize("which", ["paper_case", "grid16", "custom"])
def test_round_trip_through_toml(which):
    s = _custom() if which == "custom" else scenario.load(which)
    text = s.to_toml()
    back = Scenario.from_dict(tomllib.loads(text))
    assert back.to_dict() == s.to_dict()
    for a, b in zip(_arrays(back), _arrays(s), strict=True):
        assert np.array_equal(a, b)
    assert back.team.graph == s.team.graph and back.team.graph_family == s.team.graph_family
    assert back.onboard == s.onboard and back.description == s.description
    assert back.to_toml() == text


def test_to_dict_is_plain_and_complete():
    s = _custom()
    d = s.to_dict()

    def plain(v):
        if isinstance(v, dict):
            return all(isinstance(k, str) and plain(x) for k, x in v.items())
        if isinstance(v, list):
            return all(plain(x) for x in v)
        return type(v) in (str, int, float, bool)

    assert plain(d)
    assert d["team"]["graph_family"] == "knn"
    assert d["team"]["graph"] == [[j + 1, i + 1] for j, i in s.team.graph.edges]
    assert len(d["team"]["initial_positions"]) == 4
    assert d["noise"]["xi_bar"] == 0.0071
    assert "xi_bar" not in scenario.load("paper_case").to_dict()["noise"]
    assert d["faults"][1] == {"robot": 1, "kind": "stop", "t": 41.8, "value": [0.0, 0.0],
                              "time_constant": 0.0}  # fmt: skip
    assert set(d["fdir"]) == {f.name for f in dataclasses.fields(scenario.Fdir)}
    assert d["onboard"]["params"]["decision"] == {"mode": "strict", "nested": {"a": [1.5, 2]}}


def test_graph_family_must_match_a_generated_graph():
    d = scenario_dict("grid16")
    d["team"]["graph_family"] = "knn"
    msg = _error(scenario.from_dict, d, "x.toml")
    assert msg.startswith("x.toml: team.graph_family: expected 'random' (the family of team.graph)")


def test_stop_faults_take_only_zero_bias_values():
    d = scenario_dict()
    d["faults"][1]["value"] = [0.0, 0.0]
    d["faults"][1]["time_constant"] = 0
    assert make(d).faults[1].kind == "stop"
    d["faults"][1]["value"] = [0.1, 0.0]
    assert "faults[2].value: expected [0.0, 0.0] or no value for a stop fault" in _error(make, d)


# --------------------------------------------------------------------------- built scenarios


def test_dataclass_built_scenarios_are_validated():
    s = scenario.load("paper_case")
    unstable = Gains(kc=4.0, ko=600.0, K=s.gains.K, G=s.gains.G, theta=3.0)
    msg = _error(dataclasses.replace, s, gains=unstable)
    assert msg.startswith(f"{s.source}: gains.ko: the observer update is unstable")
    fields = {f.name: getattr(s, f.name) for f in dataclasses.fields(Scenario)}
    fields.pop("source")
    assert Scenario(**fields).source == "<memory>"  # valid: builds
    fields["gains"] = unstable
    fields["duration"] = 30.0  # the stop fault at 41.8 s is now after the end
    assert _error(Scenario, **fields).splitlines() == [  # gains come before faults in a document
        "<memory>: gains.ko: the observer update is unstable at this control period: "
        "ko * control_period * (2 * max in-degree + 1) = 30, expected < 2; "
        "lower ko or physics.control_period",
        "<memory>: faults[2].t: fault at 41.8 s is after the end of the run (duration = 30 s)",
    ]
    msg = _error(dataclasses.replace, s, onboard=Onboard(controller="no good"))
    assert "paper_case.toml: onboard.controller: expected a built-in name" in msg
    msg = _error(dataclasses.replace, s, team=dataclasses.replace(s.team, robots=5))
    assert (
        msg == f"{s.source}: team.graph: expected a graph on team.robots = 5 robots, got one on 4"
    )
    assert "physics: expected a Physics, got NoneType" in _error(
        dataclasses.replace, s, physics=None
    )


def test_with_overrides_still_checks_and_shortens():
    s = scenario.load("paper_case")
    assert s.with_overrides(seed=5).seed == 5
    short = s.with_overrides(duration=2.0)
    assert short.duration == 2.0 and short.faults == () and short.mission.transient == 1.0
    assert scenario.dropped_faults(s, short) == list(s.faults)
    assert s.with_overrides(robot_model="diffdrive").team.robot_model == "diffdrive"


# --------------------------------------------------------------------------- campaign [vary] keys

CAMPAIGN = """
name = "dotted"
scenario = "paper_case"
runs = 6
seed = 3
[set]
duration = 30.0
[vary]
fault_kind = ["stop", "bias"]
fault_time = [6.0, 10.0]
"""
DOTTED = """
"gains.ko" = [3, 6]
"onboard.thresholds" = ["paper", "mylab.fdi:Mine"]
"fdir.detection_window" = [0.1, 0.2]
"""


def _spec(tmp_path: Path, extra: str = "", name: str = "c.toml") -> campaign_spec.Spec:
    path = tmp_path / name
    path.write_text(CAMPAIGN + extra)
    return campaign_spec.load(path)


def test_vary_dotted_keys_are_drawn_after_the_others(tmp_path):
    plain = _spec(tmp_path, name="plain.toml")
    dotted = _spec(tmp_path, DOTTED)
    seen = set()
    for i in range(plain.runs):
        a, b = campaign_spec.draw(plain, i), campaign_spec.draw(dotted, i)
        assert {k: v for k, v in b.items() if "." not in k} == a  # today's draws unchanged
        assert b["gains.ko"] in (3, 6) and b["fdir.detection_window"] in (0.1, 0.2)
        assert b["onboard.thresholds"] in ("paper", "mylab.fdi:Mine")
        assert campaign_spec.draw(dotted, i) == b  # from (seed, index) only
        seen.add(b["gains.ko"])
    assert seen == {3, 6}


def test_vary_dotted_keys_reach_the_scenario(tmp_path):
    s = _spec(tmp_path, DOTTED)
    for i in range(s.runs):
        p = campaign_spec.draw(s, i)
        sc = campaign_spec.scenario_for(s, p)
        assert (
            sc.gains.ko == p["gains.ko"] and sc.fdir.detection_window == p["fdir.detection_window"]
        )
        assert sc.onboard.thresholds == p["onboard.thresholds"]
        assert sc.faults[0].kind == p["fault_kind"] and sc.duration == 30.0


def test_vary_dotted_key_errors(tmp_path):
    msg = _error(_spec, tmp_path, '"gains.ko" = 3\n')
    expected = 'vary."gains.ko": expected a non-empty list of choices, got int 3'
    assert msg == f"{tmp_path / 'c.toml'}: {expected}"
    assert 'vary."gains.ko": expected a non-empty list' in _error(
        _spec, tmp_path, '"gains.ko" = []\n'
    )
    assert "vary.gainsko: unknown key" in _error(_spec, tmp_path, "gainsko = [3]\n")
    msg = _error(_spec, tmp_path, '"gains.ko" = [3, -1]\n')
    assert '(vary."gains.ko" = -1): gains.ko: expected a number > 0, got -1' in msg
    msg = _error(_spec, tmp_path, '"duration.x" = [1]\n')
    assert "duration.x: expected duration to be a table" in msg


def test_vary_draws_the_top_level_obstacles_and_duration(tmp_path):
    """A campaign draws obstacle sets and durations among choices, as it draws dotted keys
    (before, ``vary.obstacles`` was an unknown key: no campaign could put a cylinder in its
    runs' way); a set that is not valid is refused at load, naming its key."""
    cylinder = "{ position = [1.2, 0.6], radius = 0.2, safe_distance = 0.45 }"
    s = _spec(tmp_path, f"obstacles = [[], [{cylinder}]]\nduration = [20.0, 30.0]\n")
    drawn = [campaign_spec.scenario_for(s, campaign_spec.draw(s, i)) for i in range(s.runs)]
    assert {len(sc.obstacles) for sc in drawn} == {0, 1}
    assert {sc.duration for sc in drawn} == {20.0, 30.0}
    (one,) = next(sc.obstacles for sc in drawn if sc.obstacles)
    assert tuple(one.position) == (1.2, 0.6) and one.radius == 0.2
    msg = _error(_spec, tmp_path, "obstacles = [[{ position = [1, 0], radius = 0.3 }]]\n")
    assert msg.endswith("c.toml (run 0): obstacles[1].safe_distance: missing key")
    assert "vary.obstacle: unknown key" in _error(_spec, tmp_path, "obstacle = [[]]\n")


def test_a_document_built_with_numpy_values_and_tuples_reads_as_the_plain_one():
    """A scenario built in Python may hold numpy integers, floats, arrays and tuples (an
    edge list from ``np.argwhere``, positions from an array): it reads as the same
    document written with plain numbers and lists."""
    plain = scenario_dict()
    d = scenario_dict()
    d["team"]["graph"] = [tuple(np.int64(v) for v in e) for e in plain["team"]["graph"]]
    d["team"]["initial_positions"] = np.array(plain["team"]["initial_positions"])
    d["duration"] = np.float64(plain["duration"])
    d["seed"] = np.int32(plain.get("seed", 0))
    plain["seed"] = plain.get("seed", 0)
    assert make(d).to_dict() == make(plain).to_dict()
