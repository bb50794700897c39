"""A user's blocks from a module outside the package, through every way of running:
the CLI, a campaign on two local workers, a campaign on Ray; the examples; the viewer."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dftc_mujoco.campaign import runner, spec
from dftc_mujoco.campaign.__main__ import main as campaign_main
from tests.test_campaign import _rows

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
CAMPAIGN = EXAMPLES / "blocks_campaign.toml"


def _run(args, cwd, env=None, timeout=900):
    return subprocess.run(
        [sys.executable, "-m", "dftc_mujoco.run", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **(env or {})},
    )


def _first_flag_delay(summary):
    stop = next(f["t"] for f in summary["faults"] if f["kind"] == "stop")
    return min(d["t"] for d in summary["detections"] if d["robot"] == 1) - stop


def test_cli_runs_blocks_from_a_module_outside_the_package(tmp_path):
    """`mylab` lives in examples/, not in dftc_mujoco: selected with --set, imported in
    the run's process, named in summary.json, and it changes the outcome."""
    common = ["paper_case", "--no-video", "--no-progress", "--duration", "47"]
    paper = _run([*common, "--out", str(tmp_path / "paper")], cwd=EXAMPLES)
    mine = _run(
        [
            *common,
            "--out",
            str(tmp_path / "mine"),
            "--set",
            "onboard.thresholds=mylab.fdi:Scaled",
            "--set",
            "onboard.params.thresholds.factor=0.25",
            "--set",
            'onboard.controller="mylab.control:Lyapunov"',
        ],
        cwd=EXAMPLES,
    )
    assert paper.returncode == 0 and mine.returncode == 0, mine.stderr
    a = json.loads((tmp_path / "paper" / "summary.json").read_text())
    b = json.loads((tmp_path / "mine" / "summary.json").read_text())
    assert b["onboard"]["blocks"]["thresholds"] == "mylab.fdi:Scaled"
    assert b["onboard"]["blocks"]["controller"] == "mylab.control:Lyapunov"
    assert b["onboard"]["path"] == "general" and a["onboard"]["path"] == "compiled"
    assert "blocks:       controller = mylab.control:Lyapunov, thresholds = mylab.fdi:Scaled" in (
        mine.stdout
    )
    assert _first_flag_delay(b) < _first_flag_delay(a) - 1.0  # 1.2 s against 3.3 s
    # the saved scenario names the blocks: re-running it from elsewhere needs mylab on the path
    saved = (tmp_path / "mine" / "scenario.toml").read_text()
    assert 'thresholds = "mylab.fdi:Scaled"' in saved and "factor = 0.25" in saved
    # a module that cannot be found is one line naming the key, exit 2
    bad = _run([*common, "--set", "onboard.thresholds=nolab.fdi:Scaled"], cwd=tmp_path)
    assert bad.returncode == 2
    assert bad.stderr.count("\n") == 1 and "onboard.thresholds: cannot import 'nolab" in bad.stderr


@pytest.fixture(scope="module")
def two_workers(tmp_path_factory):
    out = tmp_path_factory.mktemp("blocks_local")
    assert campaign_main([str(CAMPAIGN), "--workers", "2", "--out", str(out), "--no-progress"]) == 0
    return out


def test_campaign_workers_import_the_users_blocks(two_workers):
    rows = _rows(two_workers)
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows.values())
    by_rule = {}
    for r in rows.values():
        blocks = json.loads(r["blocks"])
        assert blocks["thresholds"] == r["onboard.thresholds"]  # the row names what ran
        assert blocks["controller"] == "mylab.control:Lyapunov" and r["onboard_path"] == "general"
        by_rule.setdefault(r["onboard.thresholds"], []).append(r["delay_first"])
    assert set(by_rule) == {"paper", "mylab.fdi:Scaled"}
    # the scaled rule (factor 0.5) flags the stop earlier than eq. 40 in every run
    assert max(by_rule["mylab.fdi:Scaled"]) < min(by_rule["paper"])


def test_campaign_on_ray_imports_the_users_blocks_too(two_workers, tmp_path, ray_alone):
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install -e '.[cluster]')")
    # a new private instance, whatever else runs here (or a stale ray_current_cluster says)
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        runner.run(spec.load(CAMPAIGN), tmp_path, ray_address=None, progress=False)
    finally:
        ray.shutdown()
    assert _rows(tmp_path) == _rows(two_workers)


@pytest.mark.parametrize(
    ("script", "expect"),
    [
        ("custom_thresholds.py", "thresholds __main__:Tighter"),
        ("custom_controller.py", "locality check: ok"),
        ("step_and_plot.py", "saved"),
    ],
)
def test_examples_run(script, expect, tmp_path):
    args = [str(tmp_path / "residual.png")] if script == "step_and_plot.py" else []
    out = subprocess.run(
        [sys.executable, str(EXAMPLES / script), *args],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, out.stderr
    assert expect in out.stdout
    if script == "step_and_plot.py":
        assert (tmp_path / "residual.png").stat().st_size > 10_000
        assert "detection  robot 1" in out.stdout
    if script == "custom_thresholds.py":
        delays = [line for line in out.stdout.splitlines() if "flags on robot 1" in line]
        assert len(delays) == 2


def test_viewer_without_a_display_says_so_in_one_line(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    out = subprocess.run(
        [
            *(sys.executable, "-m", "dftc_mujoco.run", "paper_case", "--viewer", "--no-video"),
            *("--duration", "1", "--out", str(tmp_path), "--no-progress"),
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=900,
    )
    assert out.returncode == 0
    notes = [line for line in out.stderr.splitlines() if "viewer" in line]
    assert len(notes) == 1 and "needs a display" in notes[0]
    assert (tmp_path / "summary.json").is_file()


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="Xvfb is not installed (apt xvfb)")
def test_viewer_shows_the_run_under_xvfb(tmp_path):
    code = (
        "from dftc_mujoco import Simulation, load_scenario\n"
        "from dftc_mujoco.watch.viewer import watch\n"
        "with Simulation(load_scenario('paper_case', {'duration': 2.0})) as sim:\n"
        "    frames = watch(sim, speed=2.0)\n"
        "    print(frames, sim.done)\n"
    )
    out = subprocess.run(
        ["xvfb-run", "-a", "-s", "-screen 0 800x600x24", sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, out.stderr
    frames, done = out.stdout.split()
    assert int(frames) >= 60 and done == "True"  # 2 s at 30 frames/s, to the end
