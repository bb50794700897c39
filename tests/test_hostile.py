"""Hostile but fair input: every case is one ``error:`` line naming the
file, the key, what was expected and what was found, with the right exit code and nothing
lost, or it runs when it is legitimate. One test per family: scenario files, overrides,
robot files, campaign specs, the command line, the Python API and process faults."""

from __future__ import annotations

import json
import os
import re
import stat
from pathlib import Path

import numpy as np
import pytest

from dftc_mujoco import Simulation, load_scenario, open_run, plot, run, simulate
from dftc_mujoco.blocks import paper
from dftc_mujoco.campaign import __main__ as campaign_cli
from dftc_mujoco.errors import EXIT_INPUT, InputError, OutputError
from dftc_mujoco.render.video import write_video
from dftc_mujoco.runtime import interrupt
from dftc_mujoco.runtime.output import run_folder
from dftc_mujoco.scenario import SCENARIOS

GOOD = (SCENARIOS / "paper_case.toml").read_text()


def _one_error_line(err: str, *needles: str) -> None:
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert lines, err
    assert "Traceback" not in err, err
    for needle in needles:
        assert any(needle in line for line in lines), (needle, err)


def _variant(old: str, new: str) -> str:
    assert old in GOOD, old
    return GOOD.replace(old, new, 1)


@pytest.mark.parametrize(
    ("old", "new", "needles"),
    [
        # a robot that starts off the floor: the mission used to end at t = 0
        ("[-0.40, -0.20]", "[70.0, -0.20]", ("team.initial_positions", "robot 1 at [70")),
        # mm/s typed as m/s: a stop was never detected
        ("eta_bar = 0.001", "eta_bar = 0.001\nxi_bar = 5.0", ("noise.xi_bar", "5 mm/s is 0.005")),
        # G of 1e-4: fault estimates 27-54 m/s wrong; 1e-300: a summary that could not be saved
        ('G = "auto"', "G = 1e-4", ("gains.G", "expected G > 0.00508")),
        ('G = "auto"', "G = 1e-300", ("gains.G", "unstable")),
        # found by fuzzing: K = inf was a LinAlgError traceback, a huge K was blamed on G,
        # and G = 1e300 ran with an overflow warning (compensation off, in silence)
        ("K = 3.0 ", "K = inf ", ("gains.K", "expected a positive number")),
        ("K = 3.0 ", "K = 1e6 ", ("gains.K", "whatever G is", "expected K < 200")),
        ('G = "auto"', "G = 1e300", ("gains.G", "expected numbers within ±1e+09")),
        # every robot was excluded
        ("[fdir]", "[fdir]\nexcluded_safe_distance = 1000.0", ("fdir.excluded_safe_distance",)),
        # numbers that passed the finite check overflowed later
        ("duration = 60.0", "duration = 1e308", ("duration: expected a number within",)),
        # a hang in the path's table, and an overflow of the substeps (found by fuzzing)
        ("ramp_time = 2.0", "ramp_time = 1e-9", ("mission.centroid.ramp_time: expected at least",)),
        ("timestep = 0.002", "timestep = 1e-300", ("physics.timestep: expected at least",)),
        # shorter than a period: no period ran, and the video then failed with exit code 4
        ("duration = 60.0", "duration = 0.004", ("duration: expected at least one control",)),
    ],
)
def test_a_meaningless_scenario_is_refused_before_simulating(tmp_path, capsys, old, new, needles):
    path = tmp_path / "s.toml"
    path.write_text(_variant(old, new))
    out = tmp_path / "out"
    assert run.main([str(path), "--no-video", "--no-progress", "--out", str(out)]) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, str(path), *needles)
    assert not out.exists()


HOSTILE = [-1, 0, 0.5, 1e308, 1e-300, float("nan"), float("inf"), -float("inf"), 10**30, "",
           "x", True, [], [1, 2, 3], {}, [[0, 0]]]  # fmt: skip


def _leaf_keys(table: dict, prefix: str = "") -> list[str]:
    out = []
    for key, value in table.items():
        if isinstance(value, dict):
            out += _leaf_keys(value, f"{prefix}{key}.")
        elif not (isinstance(value, list) and value and isinstance(value[0], dict)):
            out.append(prefix + key)
    return out


def test_every_key_of_paper_case_with_hostile_values_is_refused_or_runs():
    """Each leaf key of paper_case set in turn to each hostile value, then 0.3 s run: the
    package's own one-line error or a run, never another exception (the sweep over the three
    shipped scenarios, 1605 cases, found an infinite gains.K raising numpy's LinAlgError)."""
    import tomllib

    from dftc_mujoco.errors import DftcError

    keys = [k for k in _leaf_keys(tomllib.loads(GOOD)) if k not in ("duration", "name")]
    assert len(keys) >= 20
    other = []
    for key in keys:
        for value in HOSTILE:
            try:
                simulate(load_scenario("paper_case", {key: value, "duration": 0.3}))
            except DftcError:
                pass
            except Exception as exc:  # what a user would see as a traceback
                other.append(f"{key} = {value!r}: {type(exc).__name__}: {exc}")
    assert not other, other[:5]


def test_a_duration_between_two_periods_is_said_to_end_at_the_later(tmp_path, capsys):
    """The run is a whole number of control periods: 0.015 s ended at 0.02 s in silence."""
    runs = {}
    for d in ("0.015", "0.03"):  # 0.03 s is 2.9999999999999996 periods: whole
        out = tmp_path / d
        argv = ["paper_case", "--duration", d, "--no-video", "--no-progress", "--out", str(out)]
        assert run.main(argv) == 0
        runs[d] = (capsys.readouterr().out, open_run(out))
    said, result = runs["0.015"]
    assert result.log["t"][-1] == pytest.approx(0.02)
    assert (
        "WARNING: " + str(SCENARIOS / "paper_case.toml") + ": duration: 0.015 s is not a whole "
        "number of control periods (0.01 s): the run ends at 0.02 s"
    ) in said
    said, result = runs["0.03"]
    assert result.log["t"][-1] == pytest.approx(0.03) and "duration:" not in said


def test_a_toml_file_nested_50000_deep_is_one_line(tmp_path, capsys):
    path = tmp_path / "deep.toml"
    path.write_text("x = " + "[" * 50_000 + "]" * 50_000 + "\n")
    assert run.main([str(path), "--no-video", "--out", str(tmp_path / "o")]) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, str(path), "nested too deep")


@pytest.mark.parametrize(
    ("value", "got"),
    [
        ("os:_exit", "builtin_function_or_method posix._exit"),  # exited 0 with no records
        ("subprocess:call", "function subprocess.call"),  # ran a shell command
        ("collections:OrderedDict", "class collections.OrderedDict"),  # silently replaced
    ],
)
def test_an_override_naming_a_callable_that_is_not_a_block_is_refused(tmp_path, capsys, value, got):
    out = tmp_path / "out"
    code = run.main(
        ["paper_case", "--set", f"onboard.decision={value}", "--no-video", "--out", str(out)]
    )
    assert code == EXIT_INPUT
    _one_error_line(
        capsys.readouterr().err,
        "onboard.decision",
        "expected a class derived from dftc_mujoco.blocks.paper.Decision",
        got,
    )
    assert not out.exists()


def test_overrides_of_sizes_are_checked_before_use(capsys):
    assert run.main(["paper_case", "--set", "team.robots=6000", "--no-video"]) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, "team.robots: expected an integer <= 5000")
    deep = "[" * 50_000 + "]" * 50_000
    assert run.main(["paper_case", "--set", f"team.graph={deep}", "--no-video"]) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, "--set team.graph", "nested too deep")


def test_a_robot_file_with_a_huge_number_or_too_deep_is_one_line(tmp_path, capsys):
    data = Path(__file__).parent / "data" / "robots"
    text = (data / "slowbase.robot.toml").read_text()
    for name, body, needle in [
        ("deep", text + "\nx = " + "[" * 50_000 + "]" * 50_000 + "\n", "nested too deep"),
        ("huge", text.replace("lag = 2.503", "lag = 1e300", 1), "calibration.lag"),
    ]:
        path = tmp_path / f"{name}.robot.toml"
        path.write_text(body)
        for item in (data / "slowbase").iterdir():  # the robot file's own folder of models
            (tmp_path / "slowbase").mkdir(exist_ok=True)
            (tmp_path / "slowbase" / item.name).write_bytes(item.read_bytes())
        code = run.main(["paper_case", "--robot", str(path), "--no-video"])
        assert code == EXIT_INPUT
        _one_error_line(capsys.readouterr().err, str(path), needle)


def test_campaign_specs_that_mean_nothing_are_refused(tmp_path, capsys):
    spec = tmp_path / "c.toml"
    spec.write_text(
        'name = "c"\nscenario = "paper_case"\nruns = 3\n[vary]\ngraph_family = ["ring_chords"]\n'
        '[vary.graph]\nchords = "x"\n'
    )
    assert campaign_cli.main([str(spec), "--out", str(tmp_path / "c")]) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, "vary.graph.chords: expected a list of chord")
    spec.write_text('name = "c"\nscenario = "paper_case"\nruns = 2\n[vary]\nseed = false\n')
    assert campaign_cli.main([str(spec), "--out", str(tmp_path / "c")]) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, "every one of the 2 runs would be the same scenario")
    spec.write_text(
        'name = "c"\nscenario = "paper_case"\nruns = 2\n[vary]\nfault_time = [5.0, 1.0]\n'
    )
    assert campaign_cli.main([str(spec), "--out", str(tmp_path / "c")]) == EXIT_INPUT
    # the range as written, not numpy's repr ([np.float64(5.0), np.float64(1.0)])
    _one_error_line(
        capsys.readouterr().err, "vary.fault_time: expected 0 <= low <= high, got [5.0, 1.0]"
    )
    # every run a bias of 0 (no fault, counted as one): such a campaign ran without a word
    spec.write_text(
        'name = "c"\nscenario = "paper_case"\nruns = 2\n[vary]\nfault_kind = ["bias"]\n'
        "bias_magnitude = [0.0, 0.0]\n"
    )
    assert campaign_cli.main([str(spec), "--out", str(tmp_path / "c")]) == EXIT_INPUT
    _one_error_line(
        capsys.readouterr().err,
        "vary.bias_magnitude: expected high > 0 (a bias of 0 is no fault), got [0.0, 0.0]",
    )


def test_a_ray_timeout_must_be_a_time_and_needs_ray(tmp_path, capsys):
    spec = Path(__file__).resolve().parent.parent / "campaigns" / "tiny.toml"
    for extra, needle in (
        (["--ray-timeout", "nan", "--ray"], "--ray-timeout: expected seconds in (0, 3600]"),
        (["--ray-timeout", "-1", "--ray"], "--ray-timeout: expected seconds in (0, 3600]"),
        (["--ray-timeout", "30"], "--ray-timeout: only with --ray"),
    ):
        assert campaign_cli.main([str(spec), "--out", str(tmp_path / "t"), *extra]) == EXIT_INPUT
        _one_error_line(capsys.readouterr().err, needle)
    assert not (tmp_path / "t").exists()


def test_a_campaign_whose_every_run_is_refused_does_not_exit_0(tmp_path, capsys):
    spec = tmp_path / "e.toml"
    spec.write_text(
        'name = "e"\nscenario = "paper_case"\nruns = 2\n[set]\nfaults = []\nduration = 8.0\n'
        "mission.centroid.speed = 5.0\n"
    )
    code = campaign_cli.main([str(spec), "--out", str(tmp_path / "e"), "--workers", "1"])
    assert code == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, "every run was refused (2 of 2)", "command range")


def test_out_with_dot_dot_lands_where_the_shell_would_put_it(tmp_path, capsys):
    """--out p/new/.. simulated, printed "records: ...", then exited 5 and kept nothing."""
    p = tmp_path / "p"
    p.mkdir()
    (p / "keep.txt").write_text("")
    target = tmp_path / "q"
    code = run.main(
        [
            "paper_case",
            "--duration",
            "1",
            "--no-video",
            "--no-progress",
            "--out",
            f"{target}/new/..",
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert open_run(target).summary["simulated_time"] >= 1.0
    assert not (target / "new").exists()


def test_plot_answers_hand_edited_records_in_one_line(tmp_path, capsys, fault_free_run):
    out = fault_free_run.save(tmp_path / "run", figures=False)
    summary = json.loads((out / "summary.json").read_text())
    summary["status"] = "failed"
    summary.pop("error", None)  # a failed summary without its error: KeyError before
    (out / "summary.json").write_text(json.dumps(summary))
    assert open_run(out).error is not None
    log = dict(np.load(out / "log.npz"))
    log["t"] = log["t"].astype(str)  # a time column of text: TypeError in the figures before
    np.savez(out / "log.npz", **log)
    assert plot.main([str(out)]) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, "log.npz", "field 't' holds str")


class _Falsy(paper.Thresholds):
    """A user's thresholds block that is falsy (a container that is empty, say)."""

    def __len__(self) -> int:
        return 0


def test_the_api_refuses_what_it_cannot_do_in_one_line(tmp_path):
    s = load_scenario("paper_case", {"duration": 1.0, "faults": []})
    sim = Simulation(s)
    for bad in (0, -5, 1.5, True):  # step(0) and step(-5) returned snapshots at t < 0
        with pytest.raises(ValueError, match="step\\(periods\\): expected a whole number"):
            sim.step(bad)
    with pytest.raises(ValueError, match="reset\\(seed\\)"):  # ran seed 1
        sim.reset(seed=1.5)
    with pytest.raises(ValueError, match=r"reset\(seed\): expected a whole number in 0\.\.2\*\*63"):
        sim.reset(seed=2**70)  # an InputError about the "command line" before
    with pytest.raises(ValueError, match=r"drive\(robot\): expected a robot in 0\.\.3, got 1\.5"):
        sim.drive(1.5, [0.0, 0.0])  # numpy's IndexError before
    for bad in ([1.0], "ab", [[1.0, 2.0, 3.0]]):  # numpy's reshape and conversion errors before
        with pytest.raises(ValueError, match=r"drive\(velocity\): expected a planar velocity"):
            sim.drive(0, bad)
    sim.close()
    with pytest.raises(RuntimeError, match="was closed"):  # AttributeError before
        sim.step()
    with pytest.raises(InputError, match="unknown block 'observr'"):  # KeyError before
        from dftc_mujoco import blocks

        blocks.create("observr", "paper")
    falsy = _Falsy()
    with Simulation(s, blocks={"thresholds": falsy}) as sim2:  # replaced by the paper's before
        assert sim2.team.thresholds is falsy
    with pytest.raises(InputError, match="not a thresholds block"):
        Simulation(s, blocks={"thresholds": paper.Decision()})
    with pytest.raises(InputError, match="unknown block 'ctrl'; expected one of observer"):
        simulate(s, blocks={"ctrl": paper.Controller()})  # KeyError: 'ctrl' before
    with pytest.raises(TypeError, match=r"overrides: expected a mapping of dotted keys"):
        load_scenario("paper_case", [("gains.ko", 2)])  # AttributeError: 'list' ... 'items'
    with pytest.raises(TypeError, match=r"Simulation\(scenario\): expected a Scenario"):
        simulate(None)  # AttributeError from deep inside before
    with pytest.raises(TypeError, match=r"Simulation\(hook\): expected hook\(t, plant\) or None"):
        Simulation(s, hook=3)  # TypeError in the first period before


def test_save_never_mixes_two_runs(tmp_path):
    """RunResult.save over a saved run left the old figures beside the new records."""
    short = simulate(load_scenario("paper_case", {"duration": 1.0, "faults": []}))
    longer = simulate(load_scenario("paper_case", {"duration": 2.0, "faults": []}))
    out = short.save(tmp_path / "run")
    assert (out / "figures").is_dir()
    with pytest.raises(OutputError, match="holds another run"):
        longer.save(out, figures=False)
    assert open_run(out).summary["simulated_time"] == pytest.approx(1.0, abs=0.02)
    longer.save(out, figures=False, overwrite=True)
    assert open_run(out).summary["simulated_time"] == pytest.approx(2.0, abs=0.02)
    assert not (out / "figures").exists()  # replaced as a whole


def test_run_folders_get_the_users_umask(tmp_path):
    old = os.umask(0o022)
    try:
        out = simulate(load_scenario("paper_case", {"duration": 1.0, "faults": []})).save(
            tmp_path / "run", figures=False
        )
    finally:
        os.umask(old)
    assert stat.S_IMODE(out.stat().st_mode) == 0o755  # mkdtemp's 0700 before


@pytest.mark.parametrize(("after", "at"), [(100, "1.00"), (0, "0.00")])
def test_a_block_that_raises_stops_the_run_in_one_line_and_keeps_its_records(
    tmp_path, capsys, after, at
):
    """A plug-in controller raising at 1 s gave exit 1, a long traceback and no records.
    Raising in the first period left a log of no rows: drawing its paths raised IndexError
    after the report had named the records, and the traceback took the records with it."""
    mod = f"boom{after}"  # a module of its own per case: Python keeps the first imported
    (tmp_path / f"{mod}.py").write_text(
        "from dftc_mujoco.blocks.paper import Controller\n\n"
        "class Boom(Controller):\n"
        "    calls = 0\n\n"
        "    def own_input(self, u_hat_g):\n"
        "        Boom.calls += 1\n"
        f"        if Boom.calls > {after}:\n"
        "            raise ZeroDivisionError('the gain went to zero')\n"
        "        return super().own_input(u_hat_g)\n"
    )
    scen = tmp_path / "s.toml"
    text = (Path(__file__).resolve().parent.parent / "scenarios" / "paper_case.toml").read_text()
    scen.write_text(text.replace("[fdir]", f'[onboard]\ncontroller = "{mod}:Boom"\n\n[fdir]'))
    out = tmp_path / "out"
    code = run.main([str(scen), "--out", str(out), "--no-video", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 3
    assert (
        f"onboard block controller ({mod}:Boom) raised ZeroDivisionError: the gain went to "
        f"zero at t = {at} s" in err
    )
    assert "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed"
    t = np.load(out / "log.npz")["t"]
    assert len(t) == 0 if after == 0 else t[-1] >= 0.98
    assert len(list((out / "figures").glob("*.png"))) == 5
    if after == 0:  # the saved run is read and redrawn; a frame of it is refused in one line
        assert write_video(tmp_path / "v.mp4", *_records(open_run(out))) == 0
        assert not (tmp_path / "v.mp4").exists()
        assert plot.main([str(out)]) == 0
        assert plot.main([str(out), "--still", "0"]) == EXIT_INPUT
        err = capsys.readouterr().err
        assert err == "error: --still: the run logged no period: there is no frame\n"


def _records(result):
    return result.scenario, result.log, result.summary


class _NoRow(paper.Thresholds):
    def mu(self, t):
        raise RuntimeError("my table has no row for t")


@pytest.mark.parametrize(
    ("rule", "said"),
    [
        (
            'mine:BadParams"\n[onboard.params.thresholds]\nfactor = -1\n',
            "s.toml: onboard.thresholds: creating 'mine:BadParams' with "
            "onboard.params.thresholds raised ValueError: factor must be positive, got -1",
        ),
        (
            'mine:NoRow"\n',
            "s.toml: onboard block thresholds (mine:NoRow) raised RuntimeError: my table has "
            "no row for t while the team was being set up; nothing ran",
        ),
    ],
    ids=["its-params", "its-thresholds-at-0"],
)
def test_a_block_that_raises_before_the_run_is_one_line_of_bad_input(tmp_path, capsys, rule, said):
    """A plug-in block raising in its constructor (its own check of onboard.params) or in
    its thresholds at t = 0 gave a traceback; now one line naming the block, exit 2, and
    nothing is written."""
    (tmp_path / "mine.py").write_text(
        "from dftc_mujoco.blocks import paper\n\n"
        "class BadParams(paper.Thresholds):\n"
        "    def __init__(self, factor=1.0):\n"
        "        if factor <= 0:\n"
        "            raise ValueError(f'factor must be positive, got {factor}')\n\n"
        "class NoRow(paper.Thresholds):\n"
        "    def mu(self, t):\n"
        "        raise RuntimeError('my table has no row for t')\n"
    )
    scen = tmp_path / "s.toml"
    text = (Path(__file__).resolve().parent.parent / "scenarios" / "paper_case.toml").read_text()
    scen.write_text(f'{text}\n[onboard]\nthresholds = "{rule}')
    out = tmp_path / "out"
    code = run.main([str(scen), "--out", str(out), "--no-video", "--no-progress"])
    err = capsys.readouterr().err
    assert code == EXIT_INPUT
    assert err.splitlines()[-1] == f"error: {tmp_path / said}"
    assert "Traceback" not in err and not out.exists()


def test_a_given_block_that_raises_before_the_run_names_itself():
    """The Python API: a thresholds instance given that raises at set-up is named in one
    line; its own exception stays chained for the user's debugger."""
    s = load_scenario("paper_case", {"duration": 1.0})
    with pytest.raises(
        InputError, match=r"onboard block thresholds \(.*_NoRow\) raised RuntimeError"
    ) as info:
        Simulation(s, blocks={"thresholds": _NoRow()})
    assert isinstance(info.value.__cause__, RuntimeError)


class _SaysRobotCapitalised(paper.Thresholds):
    initial_error = "Robot"


class _CannotSay(paper.Thresholds):
    @property
    def initial_error(self):
        return self.meaning  # an attribute the rule never set: AttributeError


class _SaysNothing(paper.Thresholds):
    initial_error = None


@pytest.mark.parametrize(
    ("rule", "said"),
    [
        (_SaysRobotCapitalised, r"declares initial_error = 'Robot'; expected \"stacked\" "),
        (
            _CannotSay,
            r"raised AttributeError: .*'meaning' when its initial_error was read; nothing ran",
        ),
        (_SaysNothing, r"declares initial_error = None; expected \"stacked\" "),
    ],
    ids=["misspelt", "raises", "none"],
)
def test_a_rule_whose_initial_error_cannot_be_read_is_refused(rule, said):
    """What ε̄ (fdir.initial_error_bound) bounds is the rule's own declaration: the stack of
    every observer's error (eq. 40) or each robot's offset, √(N − 1) apart. A misspelt or
    unreadable declaration was read as "stacked" in silence, and a rule meaning "robot" got
    an ε̄ about √3 times too large on paper_case."""
    s = load_scenario("paper_case", {"duration": 1.0})
    with pytest.raises(InputError, match=rf"onboard block thresholds \(.*{rule.__name__}\) {said}"):
        Simulation(s, blocks={"thresholds": rule()})


class _OneAxis(paper.Controller):
    def collective_input(self, x_hat, x_d, xd_dot):
        return super().collective_input(x_hat, x_d, xd_dot)[:, :1]


class _LosesItself(paper.Controller):
    def own_input(self, u_hat_g):
        u = np.array(super().own_input(u_hat_g))
        if self.t >= 1.0:
            u[1, 0] = np.nan
        return u


class _Transposed(paper.Supervisor):
    def step(self, x, u_g, *args, **kwargs):
        u, delta = super().step(x, u_g, *args, **kwargs)
        return u, delta.T


class _OneRowOfFlags(paper.Decision):
    def update(self, r_norm, mu):
        return super().update(r_norm, mu)[0]


@pytest.mark.parametrize(
    ("kind", "block", "said"),
    [
        (
            "controller",
            _OneAxis,
            r"collective_input\(\) shape \(4, 1, 2\), expected \(4, 4, 2\), at t = 0\.00",
        ),
        (
            "controller",
            _LosesItself,
            r"own_input\(\) nan at index \(1, 0\), expected a finite number, at t = 1\.00",
        ),
        (
            "supervisor",
            _Transposed,
            r"step\(\)\[1\] shape \(2, 4\), expected \(4, 2\), at t = 0\.00",
        ),
        ("decision", _OneRowOfFlags, r"update\(\) shape \(4,\), expected \(4, 4\), at t = 0\.\d\d"),
    ],
)
def test_a_block_output_that_cannot_be_used_stops_the_run_in_one_line(kind, block, said):
    """numpy broadcast a controller's (4, 1, 2) into the team's inputs: the run went on to
    'status: ok' with a formation error of 41 m and one overflow warning. A NaN input ran
    until MuJoCo's BADCTRL, which names no block. Each output of the general path is now
    checked: the run stops at that period, naming the block, its method and what was wrong."""
    result = simulate(load_scenario("paper_case", {"duration": 2.0}), blocks={kind: block()})
    assert not result.ok
    assert re.fullmatch(
        rf"onboard block {kind} \(.*{block.__name__}\) returned from {said} s; the run "
        "stopped there and its records are kept",
        str(result.error),
    ), result.error
    if block is _LosesItself:  # the log keeps every period before
        assert result.log["t"][-1] == pytest.approx(0.98)


class _ForgetsExclusions(paper.Thresholds):
    """The paper's thresholds, always on the 4 robots the team started with."""

    def mu(self, t):
        a = super().mu(t)
        out = np.full((4, 4), np.inf)
        out[: len(a), : len(a)] = a
        return out


class _GeneralToo(paper.Controller):
    """The paper's controller, as a subclass: the team runs the general path."""


class _NaNAfterAnExclusion(paper.Thresholds):
    """The paper's thresholds, scaled by each robot's share of a team of 4: 0/0 once a robot
    has left (a rule's own bug after its restart)."""

    def mu(self, t):
        a = super().mu(t)
        lost = 4 - len(a)
        return a * (1 - lost) / (1 - lost) if lost else a


@pytest.mark.parametrize("path", ["compiled", "general"])
@pytest.mark.parametrize(
    ("rule", "said"),
    [
        (_ForgetsExclusions, r"shape \(4, 4\), expected \(3, 3\)"),
        (
            _NaNAfterAnExclusion,
            r"nan as robot 2's threshold on robot 2, expected a number ≥ 0 or \+inf",
        ),
    ],
    ids=["forgets-it", "nan-after-it"],
)
@pytest.mark.parametrize("dt_d_max", [5.0, "auto"])
def test_a_rule_that_mishandles_an_exclusion_stops_the_run_in_one_line(path, rule, said, dt_d_max):
    """From robot 1's exclusion (t_r = 50.07 s) the team has 3 members. A rule still
    returning 4 x 4 thresholds was read by the compiled period by its own count, silently
    (with a smaller array it would have read past its end), and blamed on the detector by
    the general path; a rule turning NaN flagged nobody and the team went on blind, in
    silence. Now the run stops at the first round of the new team, naming the rule, and its
    records keep the exclusion that began that period (they used to lose it). With
    Δt_d,max "auto" the reduced graph's horizon read the rule before the exclusion's event,
    and a wrong shape was a numpy broadcasting error."""
    blocks = {"thresholds": rule()}
    if path == "general":
        blocks["controller"] = _GeneralToo()
    over = {"duration": 55.0, "fdir.dt_d_max": dt_d_max}  # eq. 40's "auto" falls back to 5 s
    result = simulate(load_scenario("paper_case", over), blocks=blocks)
    assert result.summary["onboard"]["path"] == path
    assert re.fullmatch(
        rf"onboard block thresholds \(.*{rule.__name__}\) returned from mu\(t\) {said}, at "
        r"t = 50\.07 s; the run stopped there and its records are kept",
        str(result.error),
    ), result.error
    kinds = [(e["kind"], e.get("robot")) for e in result.events.items if e["t"] > 50.0]
    assert kinds == [("exclusion", 1), ("simulation_error", None)]
    assert result.summary["exclusions"] == [{"robot": 1, "t": pytest.approx(50.07)}]


class _NaNForAWhile(paper.Thresholds):
    """NaN as robot 4's threshold on robot 2 from 20 to 25 s: set-up reads t = 0 and the
    steady array, both fine."""

    def mu(self, t):
        out = super().mu(t).copy()
        if 20.0 <= t < 25.0:
            out[3, 1] = np.nan
        return out


def test_a_rule_that_turns_nan_for_a_while_stops_the_run_in_one_line():
    """Robot 2's bias from 19 s could not be flagged by robot 4 while its threshold was NaN,
    and nothing said so. A rule's array has its least entry read every round."""
    result = simulate(
        load_scenario("paper_case", {"duration": 30.0}), blocks={"thresholds": _NaNForAWhile()}
    )
    assert re.fullmatch(
        r"onboard block thresholds \(.*_NaNForAWhile\) returned from mu\(t\) nan as robot 4's "
        r"threshold on robot 2, expected a number ≥ 0 or \+inf, at t = 20\.00 s; the run "
        "stopped there and its records are kept",
        str(result.error),
    ), result.error


def test_a_bug_while_drawing_keeps_the_records(tmp_path, capsys):
    """Records a figure cannot draw (obstacles of three columns, as a drawing bug would meet
    them): the run's records are kept and the exit code is 1, with the traceback."""
    result = simulate(load_scenario("paper_case", {"duration": 0.5}))
    result.log["obstacles"] = result.log["obstacles"][:, :3]
    out = tmp_path / "out"
    with run_folder(out) as work:
        code = run._finish(result, work, out, interrupt.Signals(), None, False)
    err = capsys.readouterr().err
    assert code == 1
    assert "Traceback" in err and err.rstrip().endswith(
        f"please report the traceback above); the records (no figures) are in {out}"
    )
    assert sorted(p.name for p in out.iterdir()) == ["log.npz", "scenario.toml", "summary.json"]


# ------------------------------------------------------------- bad and risky inputs, answered
# Each bad input is one error line (file, key, expected, found); a legitimate but risky one
# runs with a warning naming the guarantee it loses.

ROBOTS = Path(__file__).resolve().parent.parent / "models" / "robots"


def _campaign(tmp_path: Path, extra: str = "", name: str = "c") -> Path:
    spec = tmp_path / f"{name}.toml"
    spec.write_text(
        f'name = "{name}"\nscenario = "paper_case"\nruns = 2\nseed = 1\n'
        f"[set]\nduration = 1.0\nfaults = []\nmission.transient = 0.5\n"
        f'team.robot_model = "{tmp_path / "bot.robot.toml"}"\n'
        f"{extra}"
    )
    return spec


def test_a_campaign_is_not_resumed_after_its_robot_file_changed(tmp_path, capsys):
    """The robot file (its calibration, its MJCF) was not part of a campaign's identity: a
    resume mixed rows of two robot definitions, exit 0."""
    robot = (ROBOTS / "disk.robot.toml").read_text().replace('"disk.xml"', '"bot.xml"')
    (tmp_path / "bot.robot.toml").write_text(robot)
    mjcf = (ROBOTS / "disk.xml").read_text()
    (tmp_path / "bot.xml").write_text(mjcf)
    spec = _campaign(tmp_path)
    args = [str(spec), "--out", str(tmp_path / "out"), "--workers", "1", "--no-progress"]
    assert campaign_cli.main([*args, "--runs", "1"]) == 0
    rows = (tmp_path / "out" / "results.jsonl").read_text()
    (tmp_path / "bot.robot.toml").write_text(robot.replace("xi_bar = 0.005", "xi_bar = 0.008"))
    capsys.readouterr()
    assert campaign_cli.main(args) == 5
    _one_error_line(
        capsys.readouterr().err, f"robot {tmp_path / 'bot.robot.toml'} changed", "--overwrite"
    )
    assert (tmp_path / "out" / "results.jsonl").read_text() == rows  # nothing mixed in
    (tmp_path / "bot.robot.toml").write_text(robot)  # put back: it resumes
    (tmp_path / "bot.xml").write_text(mjcf.replace('kv="200"', 'kv="150"'))
    assert campaign_cli.main(args) == 5
    _one_error_line(
        capsys.readouterr().err, f"robot {tmp_path / 'bot.robot.toml'}: bot.xml changed"
    )
    (tmp_path / "bot.xml").write_text(mjcf)
    assert campaign_cli.main(args) == 0
    assert len((tmp_path / "out" / "results.jsonl").read_text().splitlines()) == 2


def test_a_campaign_plug_in_that_changed_is_named(tmp_path, capsys):
    from dftc_mujoco.campaign import folder
    from dftc_mujoco.campaign import spec as spec_mod

    (tmp_path / "bot.robot.toml").write_text(
        (ROBOTS / "disk.robot.toml").read_text().replace('"disk.xml"', f'"{ROBOTS / "disk.xml"}"')
    )
    (tmp_path / "mylab_rule.py").write_text(
        "from dftc_mujoco.blocks import paper\nclass Rule(paper.Thresholds):\n    pass\n"
    )
    spec = _campaign(tmp_path, '[set.onboard]\nthresholds = "mylab_rule:Rule"\n')
    before = folder.identity(spec_mod.load(spec))["inputs"]
    assert "plug-in mylab_rule" in before
    (tmp_path / "mylab_rule.py").write_text((tmp_path / "mylab_rule.py").read_text() + "# v2\n")
    after = folder.identity(spec_mod.load(spec))["inputs"]
    assert after["plug-in mylab_rule"] != before["plug-in mylab_rule"]


def test_vary_and_methods_setting_the_same_key_are_refused(tmp_path, capsys):
    """[vary] "onboard.thresholds" overrode every [methods.NAME]: the report compared eq. 40
    with itself."""
    spec = tmp_path / "m.toml"
    spec.write_text(
        'name = "m"\nscenario = "paper_case"\nruns = 4\n[vary]\n'
        '"onboard.thresholds" = ["paper", "l1"]\n[methods.paper]\n[methods.tight]\n'
        'thresholds = "l1"\n'
    )
    assert campaign_cli.main([str(spec), "--out", str(tmp_path / "m")]) == EXIT_INPUT
    _one_error_line(
        capsys.readouterr().err,
        f'{spec}: vary."onboard.thresholds": [methods.tight] sets onboard.thresholds too',
    )
    assert not (tmp_path / "m").exists()


class _NaNScores(paper.Detector):
    """The hostile tester's detector: NaN scores from 1 s (robot 1's stop was then flagged by
    nobody, "status: ok")."""

    def judge(self, r_norm, mu, observer, x_m):
        score, bound = super().judge(r_norm, mu, observer, x_m)
        if self.t >= 1.0:
            score = np.full_like(score, np.nan)
        return score, bound


class _NaNBounds(paper.Detector):
    def judge(self, r_norm, mu, observer, x_m):
        return r_norm, np.where(np.eye(len(mu), dtype=bool), mu, np.nan)


class _Words(paper.Detector):
    def judge(self, r_norm, mu, observer, x_m):
        return r_norm, np.full(mu.shape, "high")


class _OneThing(paper.Detector):
    def judge(self, r_norm, mu, observer, x_m):
        return r_norm


@pytest.mark.parametrize(
    ("block", "said"),
    [
        (_NaNScores, r"judge\(\)\[0\] nan as robot 1's score on robot 1 .*at t = 1\.00"),
        (_NaNBounds, r"judge\(\)\[1\] nan as robot 1's bound on robot 2 .*at t = 0\.\d\d"),
        (_Words, r"judge\(\)\[1\] an array of <U4, expected numbers, at t = 0\.\d\d"),
        (_OneThing, r"judge\(\) a ndarray, expected \(scores, bounds\), at t = 0\.\d\d"),
    ],
)
def test_a_detector_returning_nan_or_the_wrong_type_stops_the_run_in_one_line(block, said):
    result = simulate(load_scenario("paper_case", {"duration": 2.0}), blocks={"detector": block()})
    assert not result.ok
    assert re.fullmatch(
        rf"onboard block detector \(.*{block.__name__}\) returned from {said} s; the run "
        "stopped there and its records are kept",
        str(result.error),
    ), result.error


@pytest.mark.parametrize(
    ("sets", "needles"),
    [
        # a latency on a link the graph does not have set the team's round: R = 31, not 1
        (
            ['onboard.thresholds="l1"', "network.links=[{link=[1,3],latency=0.3}]"],
            ("network.links[1].link: [1, 3] is not a link of team.graph", "from 1 to 4"),
        ),
        (
            ['onboard.thresholds="l1"', "network.links=[{link=[9,0],latency=0.3}]"],
            ("network.links[1].link: [9, 0] names robot 9, which is not in the team",),
        ),
        # a 37 GB MemoryError traceback: the channel's ring holds a slot per period of latency
        (
            ['onboard.thresholds="l1"', "network.latency=1e7", "gains.ko=1e-13"],
            ("network.latency: this run needs about", "GB (network", "20 ms is 0.02"),
        ),
        # 1e6 m/s² flung a disk 315 m in 0.04 s, "premises: all held"
        (
            ['faults=[{robot=1,kind="drift",t=0.5,value=[1e6,0]}]'],
            ("faults[1].value: a drift of 1e+06 m/s² on robot 1 grows to a bias of",),
        ),
        # k and in_degree beyond N - 1 were clamped without a word
        (['team.graph={family="knn",k=9}'], ("team.graph.k: expected at most N - 1 = 3",)),
        (
            ['team.graph={family="random",in_degree=9}'],
            ("team.graph.in_degree: expected at most N - 1 = 3",),
        ),
        (['team.graph_family="line"'], ("team.graph_family: 'line' does not describe the edges",)),
        # kc·h = 1e4: the controller chattered against the command range, status ok
        (["gains.kc=1e6"], ("gains.kc: kc = 1e+06 moves each robot 1e+04 times",)),
        # a line break in a --set value set a second key in silence
        (["gains.ko=3\nduration=1"], ("--set gains.ko: '3\\nduration=1' holds more than one",)),
        (["team.robot_model=disk\nx"], ("a bare word (a string) has no line breaks",)),
    ],
)
def test_silent_nonsense_is_refused_in_one_line(tmp_path, capsys, sets, needles):
    out = tmp_path / "out"
    argv = ["paper_case", "--duration", "2", "--no-video", "--no-progress", "--out", str(out)]
    for item in sets:
        argv += ["--set", item]
    assert run.main(argv) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, *needles)
    assert not out.exists()


@pytest.mark.parametrize(
    ("key", "said"),
    [
        ("sighting_tolerance", "network.sighting_tolerance: 0 switches the sighting rule off"),
        ("sighting_range", "network.sighting_range: 0 switches the sighting rule off"),
    ],
)
def test_a_sighting_rule_switched_off_runs_with_a_warning(tmp_path, key, said):
    """network.sighting_tolerance = 0 switched the sighting rule off without a word: a
    silent robot that stops was never excluded."""
    result = simulate(load_scenario("paper_case", {"duration": 0.5, f"network.{key}": 0}))
    warned = [e["message"] for e in result.events.items if e["kind"] == "warning"]
    assert any(said in w and "never excluded" in w for w in warned), warned
    result.save(tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert any(said in w for w in summary["warnings"]), summary["warnings"]


@pytest.mark.parametrize(
    ("key", "value", "needles"),
    [
        ("drift_bound", "100.0", ("calibration.drift_bound: 100 m is beyond", "2.7 mm is 0.0027")),
        ("lag", "1000.0", ("calibration.lag: 1000 s is beyond", "80 ms is 0.08")),
        ("response_time", "1e6", ("calibration.response_time: 1e+06 s is beyond",)),
        ("xi_bar", "5.0", ("calibration.xi_bar: 5 m/s is beyond", "5 mm/s is 0.005")),
        ("saturation", "5.0", ("calibration.saturation: 5 is beyond", "a share of the commands")),
        ("accel", "0.001", ("calibration.accel: 0.001 m/s² would take the robot 1000 s",)),
    ],
)
def test_a_unit_slip_in_a_robot_files_calibration_is_refused(tmp_path, capsys, key, value, needles):
    """A drift bound of 100 m, a lag of 1000 s, a response time of 1e6 s ran without a word
    and switched detection or exclusion off."""
    text = (
        (ROBOTS / "disk.robot.toml").read_text().replace('"disk.xml"', f'"{ROBOTS / "disk.xml"}"')
    )
    text = re.sub(rf"(?m)^{key} = .*$", "", text) + f"{key} = {value}\n"
    robot = tmp_path / "slip.robot.toml"
    robot.write_text(text)
    out = tmp_path / "out"
    argv = ["paper_case", "--robot", str(robot), "--duration", "1", "--no-video", "--out", str(out)]
    assert run.main(argv) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, str(robot), *needles)
    assert not out.exists()


def test_a_fifo_in_a_campaign_folder_is_refused_never_opened(tmp_path):
    """A FIFO named results.jsonl hung the resume (open() waits for a writer), and SIGTERM
    did not stop it."""
    import subprocess
    import sys

    spec = _campaign(tmp_path)
    (tmp_path / "bot.robot.toml").write_text(
        (ROBOTS / "disk.robot.toml").read_text().replace('"disk.xml"', f'"{ROBOTS / "disk.xml"}"')
    )
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / "results.jsonl")
    proc = subprocess.run(
        [sys.executable, "-m", "dftc_mujoco.campaign", str(spec), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 5, proc.stderr
    _one_error_line(proc.stderr, f"{out}: results.jsonl is a FIFO (named pipe)", "--out")
    assert stat.S_ISFIFO((out / "results.jsonl").lstat().st_mode)  # left as it was


def test_a_robot_files_mjcf_that_is_a_symlink_loop_is_one_line(tmp_path, capsys):
    """RuntimeError: Symlink loop, a traceback."""
    (tmp_path / "a.xml").symlink_to(tmp_path / "b.xml")
    (tmp_path / "b.xml").symlink_to(tmp_path / "a.xml")
    robot = tmp_path / "bot.robot.toml"
    robot.write_text('mjcf = "a.xml"\nbase = "base"\ndrive = "holonomic"\n[holonomic]\nx = "vx"\n'
                     'y = "vy"\n')  # fmt: skip
    for given, key in ((robot, f"{robot}: mjcf"), (tmp_path / "a.xml", "--robot")):
        argv = ["paper_case", "--robot", str(given), "--duration", "1", "--no-video"]
        assert run.main([*argv, "--out", str(tmp_path / "out")]) == EXIT_INPUT
        _one_error_line(capsys.readouterr().err, f"{key}: {tmp_path / 'a.xml'} is a symbolic link")


def test_open_run_on_a_summary_whose_events_are_not_events_is_one_line(tmp_path, capsys):
    """open_run on events [1, 2, 3]: TypeError: 'int' object is not iterable."""
    folder = tmp_path / "run"
    simulate(load_scenario("paper_case", {"duration": 0.2})).save(folder)
    summary = json.loads((folder / "summary.json").read_text())
    summary["events"] = [1, 2, 3]
    (folder / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(InputError, match=r"summary\.json: events\[1\]: expected an event"):
        open_run(folder)
    assert plot.main([str(folder), "--no-video"]) == EXIT_INPUT
    _one_error_line(capsys.readouterr().err, "events[1]: expected an event", "got 1")


def _interrupt_after_first_line(argv: list[str]) -> tuple[int, str, str]:
    """Start a command, send SIGINT as soon as it prints its first line; (code, out, err)."""
    import signal
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None
    first = proc.stdout.readline()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=600)
    return proc.returncode, first + out, err


def test_sigint_before_the_first_period_writes_no_run_folder(tmp_path):
    """SIGINT at t = 0 left a run folder of 0.00 s and said "the records up to t = 0.00 s"."""
    out = tmp_path / "out"
    code, _said, err = _interrupt_after_first_line(
        ["dftc_mujoco.run", "paper_case", "--duration", "2", "--no-video", "--out", str(out)]
    )
    assert code == 130, err
    assert "interrupted by SIGINT before the run started: nothing was written" in err, err
    assert "Traceback" not in err and not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]  # no lock, no tmp


def test_sigint_during_calibrate_is_one_line(tmp_path):
    """SIGINT during calibrate: a KeyboardInterrupt traceback (exit 130)."""
    robot = tmp_path / "bot.robot.toml"
    robot.write_text(HAND_WRITTEN_DISK)
    before = robot.read_bytes()
    code, _said, err = _interrupt_after_first_line(
        ["dftc_mujoco.calibrate", str(robot), "--write", "--runs", "1"]
    )
    assert code == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines()[-1] == "interrupted by SIGINT; nothing written", err
    assert robot.read_bytes() == before


HAND_WRITTEN_DISK = (
    (ROBOTS / "disk.robot.toml").read_text().replace('"disk.xml"', f'"{ROBOTS / "disk.xml"}"')
)


def test_a_ball_jointed_base_is_told_what_its_joint_is(tmp_path, capsys):
    """A ball-jointed base was told it "has no joint"."""
    (tmp_path / "ball.xml").write_text(
        '<mujoco model="ballbot"><worldbody><body name="base" pos="0 0 0.1">'
        '<joint name="swivel" type="ball"/><geom type="sphere" size="0.08" mass="2"/></body>'
        '</worldbody><actuator><motor name="vx" joint="swivel" gear="1 0 0 0 0 0"/>'
        '<motor name="vy" joint="swivel" gear="0 1 0 0 0 0"/></actuator></mujoco>'
    )
    robot = tmp_path / "ball.robot.toml"
    robot.write_text(
        'mjcf = "ball.xml"\nbase = "base"\ndrive = "holonomic"\n[holonomic]\nx = "vx"\ny = "vy"\n'
    )
    argv = ["paper_case", "--robot", str(robot), "--duration", "1", "--no-video"]
    assert run.main([*argv, "--out", str(tmp_path / "out")]) == EXIT_INPUT
    err = capsys.readouterr().err
    _one_error_line(err, f"{robot}: base: body 'base' moves on swivel (ball)", "free joint")
    assert "has no joint" not in err
