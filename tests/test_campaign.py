"""Monte-Carlo campaigns: local pool, Ray, resuming, failures, the report."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from dftc_mujoco.campaign import report, runner, spec
from dftc_mujoco.campaign.__main__ import main as campaign_main
from dftc_mujoco.errors import ScenarioError

ROOT = Path(__file__).resolve().parent.parent
TINY = ROOT / "campaigns" / "tiny.toml"


def _rows(folder: Path) -> dict[int, dict]:
    rows = [json.loads(line) for line in (folder / "results.jsonl").read_text().splitlines()]
    return {r["run"]: {k: v for k, v in r.items() if k not in runner.TIMING_COLUMNS} for r in rows}


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("tiny_local")
    assert campaign_main([str(TINY), "--workers", "2", "--out", str(out), "--no-progress"]) == 0
    return out


def test_small_campaign_on_two_local_workers(local_run):
    rows = _rows(local_run)
    assert sorted(rows) == [0, 1, 2, 3]
    assert all(r["status"] == "ok" for r in rows.values())
    assert all(r["fault_kind"] == "stop" and 6 <= r["fault_t"] <= 10 for r in rows.values())
    table = pq.read_table(local_run / "results.parquet")
    assert table.num_rows == 4 and {"detected", "delay_first", "false_alarms"} <= set(
        table.column_names
    )
    # every stop is detected within Δt_d,max-ish, no false alarm in paper_case
    assert all(r["detected"] for r in rows.values())
    assert all(r["false_alarms"] == 0 for r in rows.values())
    text = (local_run / "report.md").read_text()
    assert "detection rate" in text and "100.0 % of 4" in text
    assert (local_run / "figures" / "delays.png").stat().st_size > 5000


def test_same_campaign_on_a_local_ray_instance_gives_identical_rows(local_run, tmp_path):
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install -e '.[cluster]')")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        s = spec.load(TINY)
        runner.run(s, tmp_path, ray_address=None, progress=False)
    finally:
        ray.shutdown()
    assert _rows(tmp_path) == _rows(local_run)


def test_draws_depend_only_on_campaign_seed_and_index():
    s = spec.load(ROOT / "campaigns" / "scale_sweep.toml")
    assert [spec.draw(s, i) for i in range(5)] == [spec.draw(s, i) for i in range(5)]
    assert spec.draw(s, 1) != spec.draw(s, 2)


def test_interrupted_campaign_resumes_without_duplicates(local_run, tmp_path):
    """A torn last line (a crash mid-write) and missing runs: only those are run again."""
    lines = (local_run / "results.jsonl").read_text().splitlines()
    (tmp_path / "results.jsonl").write_text(lines[0] + "\n" + lines[1] + "\n" + lines[2][:40])
    executed = []
    runner.run(
        spec.load(TINY),
        tmp_path,
        workers=1,
        progress=False,
        on_row=lambda r: executed.append(r["run"]),
    )
    first_two = {json.loads(lines[0])["run"], json.loads(lines[1])["run"]}
    assert sorted(executed) == sorted({0, 1, 2, 3} - first_two)
    assert _rows(tmp_path) == _rows(local_run)
    text = (tmp_path / "results.jsonl").read_text().splitlines()
    assert len(text) == 4 and len({json.loads(t)["run"] for t in text}) == 4


def test_a_killed_campaign_loses_no_finished_run(tmp_path):
    """SIGKILL a real campaign process after its first rows, then run it again."""
    cmd = [
        sys.executable,
        "-m",
        "dftc_mujoco.campaign",
        str(TINY),
        "--workers",
        "1",
        "--out",
        str(tmp_path),
        "--no-progress",
    ]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    jsonl = tmp_path / "results.jsonl"
    deadline = time.time() + 120
    while time.time() < deadline and (not jsonl.exists() or not jsonl.read_text().count("\n")):
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    kept = _rows(tmp_path)
    assert 1 <= len(kept) < 4
    assert subprocess.run(cmd, capture_output=True, timeout=300).returncode == 0
    after = _rows(tmp_path)
    assert sorted(after) == [0, 1, 2, 3]
    assert all(after[k] == v for k, v in kept.items())  # finished runs untouched


def test_a_run_that_raises_is_recorded_and_the_campaign_goes_on(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.read_text().replace("[set]", '[set.team]\nrobot_model = "tank"\n\n[set]'))
    out = tmp_path / "out"
    assert campaign_main([str(bad), "--workers", "1", "--out", str(out), "--no-progress"]) == 0
    rows = _rows(out)
    assert len(rows) == 4 and all(r["status"] == "failed" for r in rows.values())
    assert all("unknown robot model 'tank'" in r["error"] for r in rows.values())
    assert "4 failed" in (out / "report.md").read_text()


def test_bad_specs_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.read_text().replace('fault_kind = ["stop"]', 'fault_kind = ["melt"]'))
    assert campaign_main([str(bad), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "vary.fault_kind: expected a list of stop, bias, none" in err and str(bad) in err
    with pytest.raises(ScenarioError, match="no such campaign spec"):
        spec.load(tmp_path / "missing.toml")


def test_report_rates_from_rows():
    base = {
        "status": "ok",
        "robots": 4,
        "duration": 3600.0,
        "dt_d_max": 5.0,
        "delay_last": None,
        "excluded_faulty": False,
        "success": True,
        "wrong_isolation": False,
    }
    rows = [
        {
            **base,
            "run": 0,
            "fault_kind": "stop",
            "detected": True,
            "detected_by": 4,
            "delay_first": 2.0,
            "false_alarms": 0,
            "false_alarm_robots": 0,
        },
        {
            **base,
            "run": 1,
            "fault_kind": "stop",
            "detected": False,
            "detected_by": 0,
            "delay_first": None,
            "false_alarms": 0,
            "false_alarm_robots": 0,
        },
        {
            **base,
            "run": 2,
            "fault_kind": "none",
            "detected": False,
            "detected_by": 0,
            "delay_first": None,
            "false_alarms": 2,
            "false_alarm_robots": 1,
        },
    ]
    s = report.summarise(rows)
    assert s["detection_rate"] == 0.5 and s["missed"] == 1
    assert s["false_alarm_rate_fault_free"] == 1.0
    assert s["false_alarms_per_robot_hour"] == pytest.approx(1 / 12)  # 1 robot in 12 robot-hours
    assert s["delay_median"] == 2.0
