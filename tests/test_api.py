"""The public Python API: Simulation, stepping, results, saved runs, blocks, reference numbers."""

import dataclasses
import inspect
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import dftc_mujoco
from dftc_mujoco import RunResult, Simulation, check_locality, load_scenario, open_run, simulate
from dftc_mujoco.blocks import paper
from dftc_mujoco.errors import ScenarioError

DATA = Path(__file__).parent / "data"
ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(params=["compiled", "general"])
def path(request, monkeypatch):
    monkeypatch.setenv("DFTC_PERIOD", request.param)
    return request.param


def test_paper_case_records_match_the_stored_reference(path):
    """The records of paper_case equal the numbers stored before the platform rewrite
    (every logged field, 121 samples, within 1e-9) and the events are identical, with the
    drive's acceleration limit and the ramped start off (``fdir.drive_accel = 0``,
    ``fdir.start_ramp = false``: the disk's calibrated 16 m/s², and 1 m/s² during the
    path's ramp, round the start's first commands, by up to a few mm in the records)."""
    result = simulate(
        load_scenario("paper_case", {"fdir.drive_accel": 0, "fdir.start_ramp": False})
    )
    assert result.summary["onboard"]["path"] == path
    with np.load(DATA / "paper_case_reference.npz") as ref:
        every = len(result.log["t"]) // (len(ref["t"]) - 1)
        for name in ref.files:
            got = result.log[name] if name == "obstacles" else result.log[name][::every]
            want = ref[name]
            assert got.shape == want.shape, name
            if want.dtype == bool:
                assert np.array_equal(got, want), name
            else:
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-9, err_msg=name)
    events = json.loads((DATA / "paper_case_events.json").read_text())
    assert result.events.items == events


def test_stepping_then_running_equals_one_run():
    s = load_scenario("paper_case", {"duration": 20.0})
    whole = simulate(s)
    with Simulation(s) as sim:
        assert sim.model.nu == 8 and sim.data.time == 0.0  # MjModel / MjData exposed
        snaps = [sim.step(250) for _ in range(4)]  # 10 s in four pieces
        rest = sim.run(progress=False)
    assert [round(sn.t, 6) for sn in snaps] == [2.49, 4.99, 7.49, 9.99]
    for name, a in whole.log.items():
        assert np.array_equal(a, rest.log[name], equal_nan=a.dtype.kind == "f"), name
    assert rest.events.items == whole.events.items
    # the snapshots carry the events since the previous one, robots from 1
    stepped = [e for sn in snaps for e in sn.events]

    # a premise span is handed out when it ends, the run's list is in time order
    def by_t(es):
        return sorted(es, key=lambda e: e["t"])

    assert by_t(stepped) == [e for e in whole.events.items if e["t"] < 10.0]
    assert {e["robot"] for e in stepped if "robot" in e} <= {1, 2, 3, 4}
    last = snaps[-1]
    assert last.x.shape == (4, 2) and last.x_hat.shape == (4, 4, 2)
    assert last.residual.shape == last.threshold.shape == (4, 4)
    assert (last.residual < last.threshold).all() and last.active.all()
    np.testing.assert_allclose(last.x_hat[2], last.x, atol=0.02)  # robot 3 knows the team


def test_the_set_up_takes_the_kappa_lambda_it_began_beside_the_scene(monkeypatch):
    """The paper's rule needs κ, λ (eq. 41) at set-up: the simulation begins them on a helper
    thread before it builds the scene and its thresholds take them from there (the same
    numbers, nothing left pending); a set-up with another rule begins nothing."""
    import dftc_mujoco.closed_loop.loop as loop_mod
    from dftc_mujoco.onboard.thresholds import decay

    decay._cached_decay_bounds.cache_clear()
    s = load_scenario("paper_case", {"duration": 0.5})
    with Simulation(s) as sim:
        assert not decay._PENDING
        rule = sim.team.thresholds
        here = decay._cached_decay_bounds.__wrapped__(*decay._key(rule.graph, rule.ko, 49))
        assert np.array_equal(rule.kappa, here[0]) and np.array_equal(rule.lam, here[1])
    begun: list[tuple] = []  # what the set-up begins, recorded instead
    monkeypatch.setattr(loop_mod, "prefetch_decay_bounds", lambda *a: begun.append(a))
    with Simulation(s), Simulation(load_scenario("paper_case", {"onboard.thresholds": "l1"})):
        pass
    assert len(begun) == 1 and begun[0][0].edges == s.team.graph.edges


def test_step_past_the_end_and_reset_with_another_seed():
    s = load_scenario("paper_case", {"duration": 1.0})
    with Simulation(s) as sim:
        sim.run(progress=False)
        assert sim.done
        with pytest.raises(RuntimeError, match="reset"):
            sim.step()
        sim.reset(seed=5)
        again = sim.run(progress=False)
    fresh = simulate(s.with_overrides(seed=5))
    assert np.array_equal(again.log["x"], fresh.log["x"])
    assert again.summary["seed"] == 5


def test_save_and_open_run_round_trip(tmp_path):
    """A run made from code (with overrides) is saved as the CLI saves it and read back."""
    s = load_scenario("paper_case", {"gains.ko": 3.0, "duration": 8.0})
    result = simulate(s)
    result.save(tmp_path, video=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "figures",
        "log.npz",
        "scenario.toml",
        "summary.json",
        "video.mp4",
    ]
    assert len(list((tmp_path / "figures").glob("*.png"))) == 5
    assert (tmp_path / "video.mp4").stat().st_size > 10_000
    back = open_run(tmp_path)
    assert isinstance(back, RunResult)
    assert back.scenario.gains.ko == 3.0 and back.scenario.duration == 8.0
    assert back.scenario.to_dict() == result.scenario.to_dict()  # the scenario that ran:
    assert s.onboard.thresholds == "auto" and back.scenario.onboard.thresholds == "paper"
    assert back.summary == json.loads(json.dumps(result.summary))
    assert back.events.items == result.events.items
    for name, a in result.log.items():
        assert np.array_equal(a, back.log[name], equal_nan=a.dtype.kind == "f"), name
    # the saved scenario reproduces the run exactly
    again = simulate(back.scenario)
    assert np.array_equal(again.log["x"], result.log["x"])


def test_open_run_names_what_is_missing(tmp_path):
    with pytest.raises(ScenarioError, match=r"summary\.json: missing"):
        open_run(tmp_path)


class Halved(paper.Thresholds):
    def mu(self, t):
        return 0.5 * super().mu(t)


class Gentle(paper.Controller):
    """Eq. 15 with a quarter of the feedback gain: k_c = 1 instead of 4."""

    def collective_input(self, x_hat, x_d, xd_dot):
        return 0.25 * super().collective_input(x_hat, x_d, xd_dot) + 0.75 * xd_dot[None]


def test_user_blocks_change_the_outcome_and_the_summary_names_them():
    s = load_scenario("paper_case", {"duration": 50.0})
    base = simulate(s)
    th = simulate(s, blocks={"thresholds": Halved()})
    ctrl = simulate(s, blocks={"controller": Gentle()})
    assert base.summary["onboard"] == {
        "path": "compiled",
        "blocks": dict.fromkeys(dftc_mujoco.blocks.BLOCKS, "paper"),
    }
    # a thresholds rule enters the compiled period as an array: still compiled
    assert th.summary["onboard"]["path"] == "compiled"
    assert th.summary["onboard"]["blocks"]["thresholds"].endswith("test_api:Halved")
    first = min(d["t"] for d in base.summary["detections"])
    assert min(d["t"] for d in th.summary["detections"]) < first - 0.5  # earlier
    # a controller subclass runs the general path
    assert ctrl.summary["onboard"]["path"] == "general"
    assert ctrl.summary["onboard"]["blocks"]["controller"].endswith("test_api:Gentle")
    at_2s = np.searchsorted(base.log["t"], 2.0)  # the team converges slower: 0.064 -> 0.142 m
    slow, fast = (np.linalg.norm(r.log["sigma_err"][at_2s]) for r in (ctrl, base))
    assert slow > 1.8 * fast
    assert check_locality({"controller": Gentle(), "thresholds": Halved()}) == []


class OneRow(paper.Thresholds):
    def mu(self, t):
        return super().mu(t)[0]


class Ragged(paper.Thresholds):
    def mu(self, t):
        return [[1.0], [1.0, 2.0]]


@pytest.mark.parametrize(("rule", "what"), [(OneRow, r"shape \(4,\)"), (Ragged, "list")])
def test_a_thresholds_rule_of_the_wrong_shape_is_refused_before_the_run(rule, what):
    """A rule's ⁱμ_k must be (M, M): one row of them or a ragged list is refused before the
    run, in one line naming the key, the rule and what it returned (one row used to stop the
    run at t = 0 with numba's typing error, and a ragged list broke the set-up's numpy)."""
    s = load_scenario("paper_case", {"duration": 2.0})
    with pytest.raises(
        ScenarioError,
        match=rf"^onboard\.thresholds: .*{rule.__name__}\.mu\(t\) "
        rf"returned {what}; expected an array of numbers of shape \(4, 4\)",
    ):
        Simulation(s, blocks={"thresholds": rule()})


class Negative(paper.Thresholds):
    def mu(self, t):
        return -super().mu(t)


class NaNLate(paper.Thresholds):
    """NaN on robot 3's row from 30 s on: the steady array shows it."""

    def mu(self, t):
        out = super().mu(t).copy()
        if t >= 30.0:
            out[2, 1] = np.nan
        return out


@pytest.mark.parametrize(
    ("rule", "said"),
    [
        (Negative, r"Negative\.mu\(0\) returned -[0-9.]+ as robot 1's threshold on robot 1"),
        (NaNLate, r"NaNLate\.mu\(1e\+09\) returned nan as robot 3's threshold on robot 2"),
    ],
    ids=["negative", "nan-when-steady"],
)
def test_a_negative_or_nan_threshold_is_refused_before_the_run(rule, said):
    """A threshold bounds a residual's norm: a negative one flagged every robot at 0.19 s
    (the systemic-anomaly guard kept them, blaming the mismatch premise), a NaN one flagged
    nobody, all in silence. Both are refused in one line naming the entry."""
    s = load_scenario("paper_case", {"duration": 2.0})
    with pytest.raises(
        ScenarioError, match=rf"^onboard\.thresholds: .*{said}; expected a number ≥ 0"
    ):
        Simulation(s, blocks={"thresholds": rule()})


class Blind(paper.Thresholds):
    def mu(self, t):
        return np.full_like(super().mu(t), np.inf)


def test_a_rule_that_can_flag_nobody_is_warned_about():
    """+inf everywhere is a valid rule (no pair can be judged), and a fault then goes
    undetected: the run says so at t = 0 (it used to say only that the faults came before
    the thresholds settled)."""
    result = simulate(
        load_scenario("paper_case", {"duration": 45.0}), blocks={"thresholds": Blind()}
    )
    warned = [e["message"] for e in result.events.items if e.get("kind") == "warning"]
    assert any("gives +inf for every pair at t = 0 and when steady" in m for m in warned), warned
    assert result.summary["detections"] == []  # robot 2's bias from 19 s: never flagged
    plain = simulate(load_scenario("paper_case", {"duration": 2.0}))
    assert not any("+inf for every pair" in e.get("message", "") for e in plain.events.items)


def test_blocks_from_the_scenario_and_their_params(tmp_path):
    mod = tmp_path / "labblocks.py"
    mod.write_text(
        "from dftc_mujoco.blocks import paper\n"
        "class Scaled(paper.Thresholds):\n"
        "    def __init__(self, factor):\n"
        "        self.factor = factor\n"
        "    def mu(self, t):\n"
        "        return self.factor * super().mu(t)\n"
    )
    text = (ROOT / "scenarios" / "paper_case.toml").read_text()
    text += (
        '\n[onboard]\nthresholds = "labblocks:Scaled"\n[onboard.params.thresholds]\nfactor = 0.3\n'
    )
    (tmp_path / "mine.toml").write_text(text)
    s = load_scenario(tmp_path / "mine.toml", {"duration": 46.0})  # found beside the file
    result = simulate(s)
    assert result.summary["onboard"]["blocks"]["thresholds"] == "labblocks:Scaled"
    assert np.nanmax(result.log["threshold"][-1]) < 0.31 * 0.2  # scaled paper thresholds
    bad = dataclasses.replace(
        s, onboard=dataclasses.replace(s.onboard, params={"thresholds": {"fator": 1}})
    )
    with pytest.raises(ScenarioError, match=r"onboard.thresholds: cannot create .*fator"):
        Simulation(bad)
    missing = dataclasses.replace(s, onboard=dataclasses.replace(s.onboard, controller="nope:X"))
    with pytest.raises(ScenarioError, match=r"onboard.controller: cannot import 'nope'"):
        Simulation(missing)


def test_figures_are_returned_as_matplotlib_objects_and_no_backend_is_forced():
    from matplotlib.figure import Figure

    result = simulate(load_scenario("paper_case", {"duration": 3.0}))
    figs = result.figures()
    assert set(figs) == {
        "fig3_paths",
        "fig4_fault_estimate",
        "fig5_8_residuals",
        "fig9_errors",
        "fig10_inputs",
    }
    assert all(isinstance(f, Figure) for f in figs.values())
    code = (
        "import sys; import dftc_mujoco.render.figures, dftc_mujoco.campaign.report, "
        "dftc_mujoco.closed_loop.loop; print('matplotlib.pyplot' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"  # importing never picks a backend for the user


def test_every_public_name_is_documented():
    """Like python-control: each public function and class has a docstring, with its
    parameters named in the signature that the docs describe."""
    for name in dftc_mujoco.__all__:
        if name.startswith("__"):
            continue
        obj = getattr(dftc_mujoco, name)
        assert inspect.getdoc(obj), name
    for cls in (Simulation, RunResult):
        for meth_name, meth in inspect.getmembers(cls, inspect.isfunction):
            if not meth_name.startswith("_"):
                assert inspect.getdoc(meth), f"{cls.__name__}.{meth_name}"
    for name in paper.__all__:
        cls = getattr(paper, name)
        for meth_name, meth in inspect.getmembers(cls, inspect.isfunction):
            if not meth_name.startswith("_"):
                assert inspect.getdoc(meth), f"paper.{name}.{meth_name}"
    params = inspect.signature(paper.Controller.collective_input).parameters
    assert list(params) == ["self", "x_hat", "x_d", "xd_dot"]
    assert list(inspect.signature(paper.Thresholds.mu).parameters) == ["self", "t"]


def test_given_builtin_blocks_keep_their_names_and_the_compiled_path():
    from dftc_mujoco.onboard.thresholds import Drive

    r = simulate(
        load_scenario("paper_case", {"duration": 1.0}),
        blocks={"controller": paper.Controller(), "thresholds": Drive()},
    )
    assert r.summary["onboard"]["path"] == "compiled"
    assert r.summary["onboard"]["blocks"]["controller"] == "paper"
    assert r.summary["onboard"]["blocks"]["thresholds"] == "drive"


def test_the_last_period_is_logged_whatever_the_log_rate():
    s = load_scenario("paper_case", {"duration": 3.0, "physics.log_rate": 0.3, "faults": []})
    r = simulate(s)
    assert r.log["t"][-1] == pytest.approx(3.0)  # the final errors are the final state's
    assert r.summary["simulated_time"] == pytest.approx(3.0)


def test_the_summary_says_how_far_the_estimates_are_from_the_world():
    """estimation_error: per robot, the RMS of its teammates' estimate errors after the
    transient; the stopped robot 1 (estimated as moving until it is excluded) stands out."""
    r = simulate(load_scenario("paper_case"), progress=False)
    e = r.summary["estimation_error"]
    rms = e["per_robot_rms"]
    assert len(rms) == 4 and rms[1] < 0.005 and rms[0] > 5 * max(rms[1:])
    assert e["max"] >= max(rms)


def test_every_block_has_its_own_random_stream_and_plug_ins_know_the_time():
    """Blocks receive self.rng (from the scenario's seed and the block's place: the same on
    every run of that seed, different between blocks) and, for plug-ins, self.t."""
    from dftc_mujoco.blocks.paper import Controller

    class Noisy(Controller):
        def own_input(self, u_hat_g):
            self.seen = getattr(self, "seen", [])
            self.seen.append((self.t, float(self.rng.random())))
            return super().own_input(u_hat_g)

    def run(seed: int) -> list:
        c = Noisy()
        s = load_scenario("paper_case", {"duration": 0.05, "seed": seed})
        with Simulation(s, blocks={"controller": c}) as sim:
            sim.run(progress=False)
            return c.seen

    a, b, c = run(1), run(1), run(2)
    assert a == b and [x for _, x in a] != [x for _, x in c]
    assert [round(t, 6) for t, _ in a][:3] == [0.0, 0.01, 0.02]
