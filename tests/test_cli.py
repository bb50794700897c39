"""Command lines: version, program names, names that would write outside renders/, limits."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

import dftc_mujoco
from dftc_mujoco import load_scenario
from dftc_mujoco.campaign.__main__ import main as campaign_main
from dftc_mujoco.errors import ScenarioError

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("command", ["run", "plot", "calibrate", "campaign"])
def test_every_command_says_its_version(command):
    out = subprocess.run(
        [sys.executable, "-m", f"dftc_mujoco.{command}", "--version"],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0
    assert out.stdout.strip() == f"python -m dftc_mujoco.{command} {dftc_mujoco.__version__}"


def test_installed_commands_call_themselves_by_their_name():
    script = Path(sys.executable).parent / "dftc-run"
    if not script.exists():
        pytest.skip("the dftc-run console script is not installed beside this Python")
    out = subprocess.run([str(script), "--help"], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0 and out.stdout.startswith("usage: dftc-run ")


@pytest.mark.parametrize("name", ["/tmp/x", "../../../x", "a/b", "..", ".hidden", ""])
def test_a_scenario_name_cannot_point_outside_renders(name):
    with pytest.raises(ScenarioError, match=r"name: expected a plain name"):
        load_scenario("paper_case", {"name": name})


def test_a_campaign_name_cannot_point_outside_renders(tmp_path, capsys):
    text = (ROOT / "campaigns" / "tiny.toml").read_text().replace('name = "tiny"', 'name = "../x"')
    text = text.replace(
        'scenario = "paper_case"', f'scenario = "{ROOT / "scenarios" / "paper_case.toml"}"'
    )
    spec = tmp_path / "bad.toml"
    spec.write_text(text)
    assert campaign_main([str(spec), "--out", str(tmp_path / "out")]) == 2
    assert "name: expected a plain name" in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and not (tmp_path.parent / "x").exists()


def test_a_negative_limit_is_refused(tmp_path, capsys):
    code = campaign_main(
        [str(ROOT / "campaigns" / "tiny.toml"), "--limit", "-3", "--out", str(tmp_path)]
    )
    assert code == 2
    assert "--limit: expected at least 1, got -3" in capsys.readouterr().err
    assert not (tmp_path / "results.jsonl").exists()


def test_a_slow_log_rate_reports_the_time_simulated(tmp_path, capsys):
    """physics.log_rate = 0.001 logs only t = 0: the run used to say "0.00 s simulated"."""
    from dftc_mujoco import run

    out = tmp_path / "run"
    args = ["--duration", "3", "--no-video", "--out", str(out), "--set", "physics.log_rate=0.001"]
    code = run.main(["paper_case", *args])
    assert code == 0
    assert "paper_case: 3.00 s simulated" in capsys.readouterr().out
    assert json.loads((out / "summary.json").read_text())["simulated_time"] == 3.0


@pytest.mark.parametrize("second", [7.0, 15.0])
def test_two_biases_on_one_robot_give_one_fault_estimate_line(tmp_path, capsys, second):
    from dftc_mujoco import run

    faults = (
        '[{robot = 2, kind = "bias", t = 7.0, value = [0.1, 0.0], time_constant = 0.45}, '
        f'{{robot = 2, kind = "bias", t = {second}, value = [0.0, 0.1], time_constant = 0.45}}]'
    )
    out = tmp_path / "run"
    code = run.main(
        [
            "paper_case",
            "--duration",
            "25",
            "--no-video",
            "--out",
            str(out),
            "--set",
            f"faults={faults}",
            "--verbose",
        ]
    )
    assert code == 0
    lines = [x for x in capsys.readouterr().out.splitlines() if x.startswith("fault estimate")]
    assert len(lines) == 1 and lines[0].startswith("fault estimate on robot 2 ("), lines
    (estimate,) = json.loads((out / "summary.json").read_text())["fault_estimates"]
    assert estimate["faults"] == [7.0, second]
    assert len(estimate["windows"]) == (1 if second == 7.0 else 2)


def test_a_scenario_that_is_not_utf8_is_one_line(tmp_path, capsys):
    from dftc_mujoco import run

    bad = tmp_path / "latin1.toml"
    bad.write_bytes((ROOT / "scenarios" / "paper_case.toml").read_bytes() + b"\n# caf\xe9\n")
    assert run.main([str(bad), "--no-video", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {bad}: not UTF-8 text (byte 0xe9"), err
    assert not (tmp_path / "out").exists()


def test_a_signal_that_surfaces_inside_a_ctypes_call_is_still_an_interruption(tmp_path):
    """SIGTERM while an EGL call converts its arguments arrived as ctypes.ArgumentError and
    `plot --video` died with a traceback and exit 1 (seen in CI); it is exit 143 now."""
    script = tmp_path / "victim.py"
    script.write_text(
        "import ctypes, os, signal, sys\n"
        "from dftc_mujoco.runtime import interrupt\n"
        "class Arg:\n"
        "    @property\n"
        "    def _as_parameter_(self):\n"
        "        os.kill(os.getpid(), signal.SIGTERM)\n"
        "        return 1\n"
        "def body(signals):\n"
        "    with signals.active():\n"
        "        ctypes.CDLL(None).abs(Arg())\n"
        "    return 0\n"
        "sys.exit(interrupt.guarded(body, ''))\n"
    )
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True)
    assert done.returncode == 143, done.stderr
    assert "Traceback" not in done.stderr and "interrupted by SIGTERM" in done.stderr
