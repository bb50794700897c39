"""Monte-Carlo campaigns: local pool, Ray, resuming, failures, the report."""

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from dftc_mujoco.campaign import cluster, report, runner, spec
from dftc_mujoco.campaign.__main__ import main as campaign_main
from dftc_mujoco.campaign.pool import Pool
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


def test_same_campaign_on_a_local_ray_instance_gives_identical_rows(local_run, tmp_path, ray_alone):
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install -e '.[cluster]')")
    # a new private instance, whatever else runs here (or a stale ray_current_cluster says)
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        s = spec.load(TINY)
        runner.run(s, tmp_path, ray_address=None, progress=False)
    finally:
        ray.shutdown()
    assert _rows(tmp_path) == _rows(local_run)


def test_workers_share_a_pass_between_threads_only_on_cores_of_their_own(monkeypatch):
    """A pool's workers run a large team's pass in as many threads as leave each worker
    cores of its own (the cores, capped by ``NUMBA_NUM_THREADS``): two workers on two cores,
    one thread each."""
    cores = len(os.sched_getaffinity(0))
    loaded = spec.load(TINY)
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    assert Pool(loaded, workers=1).execution().threads == cores
    assert Pool(loaded, workers=cores).execution().threads == 1
    assert Pool(loaded, workers=cores + 1).execution().threads == 1
    monkeypatch.setenv("NUMBA_NUM_THREADS", "1")
    assert Pool(loaded, workers=1).execution().threads == 1


@pytest.mark.parametrize("path", sorted((ROOT / "campaigns").glob("*.toml")), ids=lambda p: p.stem)
def test_every_shipped_campaign_spec_loads(path):
    """The guide's campaigns page (docs/guide/campaigns.md) names every shipped spec and
    tells the reader to run it: each one is valid as shipped, and named there."""
    s = spec.load(path)
    assert s.runs > 0 and spec.draw(s, 0) == spec.draw(s, 0)
    page = (ROOT / "docs" / "guide" / "campaigns.md").read_text(encoding="utf-8")
    assert f"`{path.stem}`" in page, f"{path.name} is not named in docs/guide/campaigns.md"


@pytest.mark.parametrize(
    "plain_name, walled_name",
    [
        ("no_false_exclusion", "no_false_exclusion_obstacles"),
        ("network_no_false_exclusion", "network_no_false_exclusion_obstacles"),
        ("no_false_exclusion_tidybot", "no_false_exclusion_tidybot_obstacles"),
    ],
)
def test_the_obstacle_batteries_draw_their_plain_battery_and_a_cylinder_set(
    plain_name: str, walled_name: str
) -> None:
    """An obstacle battery adds one drawn key, last: its runs meet the very draws of its plain
    battery, each with one of the twelve cylinder sets (the same in every obstacle battery),
    and every set is a valid scenario on a start in formation."""
    plain = spec.load(ROOT / "campaigns" / f"{plain_name}.toml")
    walled = spec.load(ROOT / "campaigns" / f"{walled_name}.toml")
    sets = walled.vary["scenario_keys"]["obstacles"]
    assert len(sets) == 12 and sets[0] == [] and max(len(c) for c in sets) == 8
    first = spec.load(ROOT / "campaigns" / "no_false_exclusion_obstacles.toml")
    assert sets == first.vary["scenario_keys"]["obstacles"]
    seen = set()
    for i in range(60):
        drawn = spec.draw(walled, i)
        assert {k: v for k, v in drawn.items() if k != "obstacles"} == spec.draw(plain, i)
        seen.add(sets.index(drawn["obstacles"]))
    assert len(seen) >= 10
    for cylinders in sets:
        drawn = {**spec.draw(walled, 1), "obstacles": cylinders}
        drawn["team.initial_positions"] = {"layout": "formation", "jitter": 0.05}
        drawn["team.robot_model"] = "disk"  # the TidyBot's files are the user's own
        assert len(spec.scenario_for(walled, drawn).obstacles) == len(cylinders)


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


def test_bytes_that_are_not_utf8_in_the_results_cost_their_line_only(local_run, tmp_path):
    lines = (local_run / "results.jsonl").read_bytes().splitlines()
    torn = lines[0] + b"\n" + lines[1][:30] + b"\xff\xfe\n" + b"[1, 2]\n"
    (tmp_path / "results.jsonl").write_bytes(torn)
    results = runner.Results(tmp_path)
    assert [r["run"] for r in results.rows] == [json.loads(lines[0])["run"]]
    assert (tmp_path / "results.jsonl").read_bytes() == lines[0] + b"\n"


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
    deadline = time.time() + 900
    while time.time() < deadline and (not jsonl.exists() or not jsonl.read_text().count("\n")):
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    kept = _rows(tmp_path)
    assert 1 <= len(kept) < 4
    assert subprocess.run(cmd, capture_output=True, timeout=900).returncode == 0
    after = _rows(tmp_path)
    assert sorted(after) == [0, 1, 2, 3]
    assert all(after[k] == v for k, v in kept.items())  # finished runs untouched


def test_a_run_that_raises_is_recorded_and_the_campaign_goes_on(tmp_path, capsys):
    """Every run refused: each is recorded with its error, the report is written, and the
    campaign says so and exits 2 (it exited 0 with nothing learnt)."""
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.read_text().replace("[set]", '[set.team]\nrobot_model = "tank"\n\n[set]'))
    out = tmp_path / "out"
    assert campaign_main([str(bad), "--workers", "1", "--out", str(out), "--no-progress"]) == 2
    assert "every run was refused (4 of 4)" in capsys.readouterr().err
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
            "detected_by": 3,  # every teammate
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
    assert s["detected_by_all_rate"] == 0.5  # teammates: the robot itself never counts


# --------------------------------------------------------------------------- interruption

LONG = ["--runs", "40", "--workers", "2", "--no-progress"]


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc: no psutil)."""
    kids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                kids.append(int(entry.name))
    return kids


def _running(pid: int) -> bool:
    """Alive and not a zombie waiting to be reaped."""
    try:
        os.kill(pid, 0)
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (ProcessLookupError, FileNotFoundError):
        return False
    return state not in ("Z", "X")


def _start_long_campaign(out: Path) -> tuple[subprocess.Popen, list[int]]:
    """40 runs on two workers, started in a session of its own (like a terminal's job);
    returns once two rows are on disk, with the campaign's child processes."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "dftc_mujoco.campaign", str(TINY), "--out", str(out), *LONG],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    jsonl = out / "results.jsonl"
    deadline = time.time() + 900
    while time.time() < deadline and proc.poll() is None:
        if jsonl.exists() and jsonl.read_text().count("\n") >= 2:
            break
        time.sleep(0.05)
    kids = _children(proc.pid)
    assert proc.poll() is None and len(kids) >= 2, "the campaign did not get going"
    return proc, kids


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_stops_a_campaign_at_once_and_keeps_every_finished_row(tmp_path, sig, code):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) or SIGTERM (to
    the campaign alone): it used to run ~30 more queued runs, throw them away with a
    traceback and leave the pool's workers behind."""
    proc, kids = _start_long_campaign(tmp_path)
    seen = len(_rows(tmp_path))
    if sig == signal.SIGINT:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    _, err = proc.communicate(timeout=900)  # a safety net; the queued runs are cancelled:
    assert proc.returncode == code, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"interrupted by {sig.name}:"), err
    assert "run the same command to resume" in lines[0]
    rows = _rows(tmp_path)
    assert seen <= len(rows) < 40  # the queued runs were cancelled
    table = pq.read_table(tmp_path / "results.parquet")
    assert sorted(table.column("run").to_pylist()) == sorted(rows)  # same rows as the JSON lines
    assert f"{len(rows)} runs: {len(rows)} finished" in (tmp_path / "report.md").read_text()
    assert f"{len(rows)}/40 runs recorded" in lines[0]
    deadline = time.time() + 900  # a safety net: they end as soon as they can
    while time.time() < deadline and any(_running(k) for k in kids):
        time.sleep(0.1)
    assert not [k for k in kids if _running(k)]  # workers and resource tracker are gone


def test_workers_do_not_outlive_a_killed_campaign(tmp_path):
    """kill -9 of the campaign alone: its workers (and multiprocessing's resource
    tracker) used to stay alive for 10+ minutes, ~230 MB each."""
    proc, kids = _start_long_campaign(tmp_path)
    proc.kill()
    proc.communicate(timeout=900)
    deadline = time.time() + 900  # a safety net: they end as soon as they notice
    while time.time() < deadline and any(_running(k) for k in kids):
        time.sleep(0.1)
    assert not [k for k in kids if _running(k)]


# --------------------------------------------------------------------------- one folder, one spec


def _tiny_variant(tmp_path: Path, name: str, old: str, new: str) -> Path:
    text = TINY.read_text().replace('scenario = "paper_case"', 'scenario = "paper_case"')
    assert old in text
    path = tmp_path / f"{name}.toml"
    path.write_text(text.replace(old, new))
    return path


def test_more_workers_than_cpus_are_said_before_running(tmp_path, capsys):
    """--workers beyond the machine's CPUs used to start that many processes in silence
    (200 of a 200-run spec on 2 cores, each with its own MuJoCo and team): it is said
    first, before anything else is looked at (here an --out that is a file, exit 5)."""
    many = (os.cpu_count() or 1) + 1
    taken = tmp_path / "a_file"
    taken.write_text("")
    args = [str(TINY), "--workers", str(many), "--out", str(taken), "--no-progress"]
    assert campaign_main(args) == 5
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"note: --workers {many} is more than the {many - 1} CPUs here")
    assert len(err) == 2 and "names a file, not a folder" in err[1]
    assert campaign_main([*args[:1], "--workers", str(many - 1), *args[3:]]) == 5
    assert "note:" not in capsys.readouterr().err


def test_a_campaign_folder_belongs_to_one_spec(tmp_path, capsys):
    """Two specs used to merge silently into one --out ("6/6 runs recorded (2 new)",
    30 s rows beside 60 s rows, spec.toml overwritten)."""
    out = tmp_path / "out"
    common = ["--workers", "1", "--no-progress", "--out", str(out)]
    assert campaign_main([str(TINY), "--runs", "2", *common]) == 0
    before = (out / "results.jsonl").read_text()
    spec_copy = (out / "spec.toml").read_text()
    longer = _tiny_variant(tmp_path, "longer", "duration = 30.0", "duration = 12.0")
    capsys.readouterr()
    assert campaign_main([str(longer), "--runs", "2", *common]) == 5
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds the campaign 'tiny' of another spec" in err[0]
    assert "differs in: set.duration" in err[0] and "--overwrite" in err[0]
    assert (out / "results.jsonl").read_text() == before
    assert (out / "spec.toml").read_text() == spec_copy
    # the same spec resumes, also with more runs (run i does not depend on --runs)
    assert campaign_main([str(TINY), "--runs", "3", *common]) == 0
    assert sorted(_rows(out)) == [0, 1, 2]
    # an edited base scenario is another campaign too
    base = tmp_path / "base.toml"
    base.write_text(
        (ROOT / "scenarios" / "paper_case.toml").read_text().replace("seed = 1", "seed = 2")
    )
    edited = _tiny_variant(tmp_path, "edited", 'scenario = "paper_case"', f'scenario = "{base}"')
    capsys.readouterr()
    assert campaign_main([str(edited), "--runs", "2", *common]) == 5
    assert "differs in: base scenario: seed" in capsys.readouterr().err
    # --overwrite replaces the folder as a whole
    assert campaign_main([str(longer), "--runs", "2", "--overwrite", *common]) == 0
    rows = _rows(out)
    assert sorted(rows) == [0, 1] and all(r["duration"] == 12.0 for r in rows.values())
    assert "duration = 12.0" in (out / "spec.toml").read_text()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out.")]
    # ... also when it holds the same campaign: --overwrite starts over
    (out / "results.jsonl").write_text(
        "\n".join(json.dumps({**r, "duration": -1.0}) for r in rows.values()) + "\n"
    )
    assert campaign_main([str(longer), "--runs", "2", "--overwrite", *common]) == 0
    assert all(r["duration"] == 12.0 for r in _rows(out).values())  # run again, not kept
    # another seed is another draw of the battery, so another campaign for the folder
    capsys.readouterr()
    assert campaign_main([str(longer), "--runs", "2", "--seed", "4", *common]) == 5
    assert "differs in: seed" in capsys.readouterr().err


def test_seed_draws_the_same_battery_again(tmp_path, capsys, monkeypatch):
    """--seed overrides the spec's campaign seed (a new draw of an untuned battery, as the
    seed-89 edge draws of docs/thresholds.md), into its own default folder; a bad one is
    exit 2."""
    sp = spec.load(TINY)
    again = dataclasses.replace(sp, seed=4)
    assert [spec.draw(sp, i)["seed"] for i in range(4)] != [
        spec.draw(again, i)["seed"] for i in range(4)
    ]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "renders" / "campaigns").mkdir(parents=True)
    (tmp_path / "renders" / "campaigns" / "tiny_seed4").write_text("x")  # no run starts
    assert campaign_main([str(TINY), "--seed", "4", "--no-progress"]) == 5
    err = capsys.readouterr().err
    assert "tiny_seed4" in err and "names a file" in err
    for bad in ("-1", str(2**63)):
        assert campaign_main([str(TINY), "--seed", bad, "--no-progress"]) == 2
        assert "--seed: expected an integer from 0 to 2**63 - 1" in capsys.readouterr().err


def test_campaign_output_problems_are_one_line_exit_5(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    (tmp_path / "thesis").mkdir()
    (tmp_path / "thesis" / "thesis.tex").write_text("precious")
    for out in ("file", "thesis"):
        for extra in ([], ["--overwrite"]):
            code = campaign_main([str(TINY), "--out", str(tmp_path / out), "--no-progress", *extra])
            assert code == 5
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and err[0].startswith("error:")
            assert ("names a file" if out == "file" else "holds no campaign") in err[0]
    assert (tmp_path / "thesis" / "thesis.tex").read_text() == "precious"
    assert sorted(p.name for p in (tmp_path / "thesis").iterdir()) == ["thesis.tex"]


@pytest.mark.parametrize(
    ("change", "expect"),
    [
        (
            ('faulty_robot = "any"', "faulty_robot = [5]"),
            "vary.faulty_robot: robot 5 does not exist",
        ),
        (('faulty_robot = "any"', "faulty_robot = [5]\nrobots = [3, 4]"), "in a team of 3"),
        (("base", "duration = [oops"), "not valid TOML"),
        (("base", b'name = "caf\xe9"\n'), "not UTF-8 text"),
        (("base", "robots_typo = 3\n"), "robots_typo"),
        # keys no drawn fault reads, and team sizes with the base's edge list: they ran
        # ignored, or failed as run 1's "not strongly connected" graph
        (
            ('fault_kind = ["stop"]\n', ""),
            "vary.faulty_robot: no run reads it: vary.fault_kind is not given",
        ),
        (
            ('faulty_robot = "any"', 'faulty_robot = "any"\nbias_magnitude = [0.1, 0.3]'),
            "vary.bias_magnitude: no run reads it: vary.fault_kind draws only stop",
        ),
        (
            ('faulty_robot = "any"', 'faulty_robot = "any"\nrobots = [4, 8]'),
            "vary.robots: the base scenario's team.graph lists the edges of its 4 robots",
        ),
    ],
)
def test_bad_campaign_inputs_are_one_line_before_running(tmp_path, capsys, change, expect):
    old, new = change
    if old == "base":
        base = tmp_path / "base.toml"
        if isinstance(new, bytes):
            base.write_bytes(new)
        else:
            base.write_text((ROOT / "scenarios" / "paper_case.toml").read_text() + new)
        spec_path = _tiny_variant(tmp_path, "s", 'scenario = "paper_case"', f'scenario = "{base}"')
    else:
        spec_path = _tiny_variant(tmp_path, "s", old, new)
    out = tmp_path / "out"
    assert campaign_main([str(spec_path), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and expect in err[0], err
    assert "Traceback" not in err[0]
    # a broken base scenario is named, not the spec's first run (it used to say "s.toml
    # (run 0): robots_typo: ...", pointing at a file that has no such key)
    assert str(spec_path if old != "base" else tmp_path / "base.toml") in err[0]
    assert not out.exists()


def test_a_grid_design_runs_every_combination_in_turn(tmp_path):
    path = tmp_path / "grid.toml"
    path.write_text(
        'name = "grid"\nscenario = "paper_case"\nruns = 12\n[vary]\ndesign = "grid"\n'
        'robots = [4, 5]\ngraph_family = ["ring_chords", "knn"]\nfault_kind = ["stop"]\n'
        '"onboard.thresholds" = ["paper", "l1", "block_row"]\n'
    )
    s = spec.load(path)
    combos = [
        (p["robots"], p["graph_family"], p["onboard.thresholds"])
        for p in (spec.draw(s, i) for i in range(12))
    ]
    assert len(set(combos)) == 12  # each of the 2 x 2 x 3 combinations exactly once
    assert spec.draw(s, 3) == spec.draw(s, 3)  # still a function of (seed, index) alone
    assert {spec.draw(s, i)["seed"] for i in range(12)} != {spec.draw(s, 0)["seed"]}


# --------------------------------------------------------------------------- facts per fault


def _campaign(tmp_path: Path, name: str, text: str) -> dict[int, dict]:
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    out = tmp_path / name
    assert campaign_main([str(path), "--workers", "1", "--out", str(out), "--no-progress"]) == 0
    return _rows(out)


def test_rows_describe_a_fault_of_the_base_scenario(tmp_path):
    """A campaign over a scenario with its own stop fault (no faulty_robot drawn): a run in
    which every teammate flagged the stopped robot and it alone was excluded reads detected,
    no false alarms and no wrong isolation."""
    rows = _campaign(
        tmp_path,
        "base_fault",
        'name = "base_fault"\nscenario = "paper_case"\nruns = 1\nseed = 1\n'
        "[set]\nduration = 52.0\n",
    )
    (row,) = rows.values()
    assert row["fault_kind"] == "base" and row["main_fault_kind"] == "stop"
    faults = json.loads(row["faults"])
    assert [(f["robot"], f["kind"]) for f in faults] == [(2, "bias"), (1, "stop")]
    stop = faults[1]
    assert stop["detected"] and stop["detected_by"] == 3 and stop["excluded"]
    # excluded at its t_r: the first teammate's flag + Δt_d,max (eq. 43)
    assert stop["exclusion_delay"] == pytest.approx(
        stop["delay_first"] + row["dt_d_max"], abs=0.011
    )
    assert row["detected"] and row["detected_by"] == 3 and row["excluded_faulty"]
    assert row["false_flags"] == 0 and row["healthy_exclusions"] == 0
    assert not row["wrong_isolation"]
    # the compensated bias was never flagged; the stop was excluded, so nothing to explain
    assert faults[0]["kept_why"] == "never_flagged" and stop["kept_why"] is None
    table = pq.read_table(tmp_path / "base_fault" / "results.parquet")
    assert {"faults", "false_flags", "false_flags_premises_held", "healthy_exclusions"} <= set(
        table.column_names
    )


def test_a_faulty_robot_still_in_the_team_at_the_end_says_why(tmp_path):
    """paper_case cut to 47 s: robot 1 stops at 41.8 s and is flagged at 45.07 s, but its t_r
    (50.07 s) comes after the end; robot 2's compensated bias is never flagged. Each fault's
    ``kept_why`` says so, and the report counts them by why (before, a flagged robot left in
    the team looked like a failed recovery, with nothing to say why)."""
    rows = _campaign(
        tmp_path,
        "cut",
        'name = "cut"\nscenario = "paper_case"\nruns = 1\nseed = 1\n[set]\nduration = 47.0\n',
    )
    (row,) = rows.values()
    faults = json.loads(row["faults"])
    assert [(f["kind"], f["detected"], f["kept_why"]) for f in faults] == [
        ("bias", False, "never_flagged"),
        ("stop", True, "due_after_end"),
    ]
    text = (tmp_path / "cut" / "report.md").read_text()
    assert "still in the team at the end of their run, by why (of 2 faults)" in text
    assert "| its t_r (first flag + Δt_d,max) came after the end | 0 | 1 |" in text
    assert "| no teammate flagged it | 1 | 0 |" in text


def test_a_robot_flagged_before_its_fault_keeps_that_flags_t_r_as_its_why():
    """Found in an N = 400 battery at seed 412: robot 25, flagged while premises were
    violated before it stopped, then flagged by 98 teammates after the stop, read
    ``never_flagged``. The recovery schedules t_r at a robot's first flag only, so the word
    in force at the onset is that earlier ``exclusion_scheduled``: here its t_r (Δt_d,max of
    an unsettled rule) comes after the end. A schedule cancelled before the onset, or one
    whose t_r passed before it, says nothing of the fault."""
    from dftc_mujoco.campaign.task import kept_why
    from dftc_mujoco.onboard.recovery import Recovery

    rec = Recovery(dt_d_max=5.0e6, max_faults=1)
    events = rec.flagged(10.0, [(3, 24)])  # before the stop at 13.8 s
    events += rec.flagged(14.1, [(5, 24), (7, 24)])  # after it: detections, nothing new
    assert [e["kind"] for e in events] == ["detection", "exclusion_scheduled"] + ["detection"] * 2
    assert kept_why(events, 25, 13.8, 60.0, 60.0) == "due_after_end"

    rec = Recovery(dt_d_max=2.0, max_faults=1)
    events = rec.flagged(10.0, [(3, 24)])  # t_r at 12 s, before the onset: cancelled then
    assert rec.due(12.0) == [24]
    events.append(rec.cancel(12.0, 24))
    assert kept_why(events, 25, 13.8, 60.0, 60.0) == "never_flagged"
    events += rec.flagged(14.1, [(5, 24)])  # flagged anew after the onset: t_r at 16.1 s
    assert kept_why(events, 25, 13.8, 15.0, 60.0) == "run_stopped"


def test_rows_describe_two_faults_in_one_run(tmp_path):
    """Two sequential stops from the base scenario: one entry each in ``faults``."""
    base = tmp_path / "two.toml"
    text = (ROOT / "scenarios" / "paper_case.toml").read_text()
    head, _, _ = text.partition("[[faults]]")
    base.write_text(
        head
        + '[[faults]]\nrobot = 1\nkind = "stop"\nt = 30.0\n\n'
        + '[[faults]]\nrobot = 3\nkind = "stop"\nt = 45.0\n\n'
        + text[text.index("[fdir]") :]
    )
    rows = _campaign(
        tmp_path,
        "two_faults",
        f'name = "two_faults"\nscenario = "{base}"\nruns = 1\nseed = 1\n'
        "[set]\nduration = 60.0\n[set.fdir]\nmax_faults = 2\n",
    )
    (row,) = rows.values()
    faults = json.loads(row["faults"])
    assert [(f["robot"], f["kind"]) for f in faults] == [(1, "stop"), (3, "stop")]
    assert all(f["detected"] and f["excluded"] for f in faults)
    assert row["fault_count"] == 2 and row["healthy_exclusions"] == 0


def test_a_drawn_two_stops_fault_gives_two_sequential_stops_and_a_line_graph(tmp_path):
    """``fault_kind = "two_stops"``: two different robots stop, the second 5-15 s after the
    first; ``graph_family = "line"``: i ⇄ i + 1."""
    path = tmp_path / "two.toml"
    path.write_text(
        'name = "two"\nscenario = "paper_case"\nruns = 8\nseed = 3\n'
        '[vary]\nrobots = [6]\nfault_kind = ["two_stops"]\ngraph_family = ["line"]\n'
        'faulty_robot = "any"\nfault_time = [10.0, 20.0]\n'
    )
    sp = spec.load(path)
    for i in range(8):
        p = spec.draw(sp, i)
        s = spec.scenario_for(sp, p)
        first, second = s.faults
        assert first.kind == second.kind == "stop" and first.robot != second.robot
        assert 5.0 <= second.t - first.t <= 15.0
        assert sorted(s.team.graph.edges) == sorted(
            [(k, k + 1) for k in range(5)] + [(k + 1, k) for k in range(5)]
        )


def test_a_stop_is_in_eq46s_domain_only_where_eq46_promises_something():
    """Eq. 46's promise (every teammate flags a constant fault at least the reference within
    Δt_d,max, from T_s on) is counted only for stops it covers. paper_case's stop of robot 1
    at 41.8 s (told 0.1 m/s, the reference): under l1 eq. 46 predicts 0.79 s and it is in
    the domain (kept: all three teammates within it); under paper eq. 46 predicts nothing
    (Δt_d,max falls back to 5 s) and it is not; and cut at 42 s, Δt_d,max ends after the
    run, so it cannot be observed."""
    from dftc_mujoco import load_scenario, simulate

    def stop(**over):
        s = load_scenario("paper_case", {"fdir.dt_d_max": "auto", **over})
        facts = runner.fault_facts(simulate(s).summary)
        return next(f for f in facts if f["kind"] == "stop")

    l1 = stop(**{"onboard.thresholds": "l1"})
    assert l1["in_domain"] and l1["command"] >= 0.1
    assert l1["detected_by"] == l1["teammates"] == 3 and l1["delay_last"] <= l1["dt_d_max"]
    assert not stop()["in_domain"]  # the paper rule: no finite prediction
    assert not stop(**{"onboard.thresholds": "l1", "duration": 42.0})["in_domain"]


def test_methods_meet_the_same_draws_and_are_reported_side_by_side(tmp_path):
    """[methods.NAME]: run i is draw i // M with method i % M; each draw's seed, faulty robot
    and fault time are the same for every method, rows carry `method`, and the report puts
    the methods side by side."""
    path = tmp_path / "m.toml"
    path.write_text(
        'name = "m"\nscenario = "paper_case"\nruns = 4\nseed = 5\n[set]\nduration = 20.0\n'
        '[vary]\nfault_kind = ["stop"]\nfaulty_robot = "any"\nfault_time = [10.0, 12.0]\n'
        '[methods.paper]\n[methods.l1]\nthresholds = "l1"\n'
    )
    s = spec.load(path)
    draws = [spec.draw(s, i) for i in range(4)]
    assert [d["method"] for d in draws] == ["paper", "l1", "paper", "l1"]
    for a, b in (draws[0:2], draws[2:4]):
        assert {k: v for k, v in a.items() if k not in ("run", "method")} == {
            k: v for k, v in b.items() if k not in ("run", "method")
        }
    assert spec.scenario_for(s, draws[1]).onboard.thresholds == "l1"
    out = tmp_path / "out"
    rows = runner.run(s, out, workers=1, progress=False).rows
    assert sorted(r["method"] for r in rows) == ["l1", "l1", "paper", "paper"]
    report.write(rows, out, "m")
    text = (out / "report.md").read_text()
    assert "Methods side by side" in text and "| l1 | 2 |" in text and "| paper | 2 |" in text
    assert (out / "figures" / "methods.png").stat().st_size > 5_000
    path.write_text(path.read_text().replace("runs = 4", "runs = 3"))
    with pytest.raises(ScenarioError, match="runs: expected a multiple of the 2 methods"):
        spec.load(path)


def test_the_none_method_shows_what_fault_detection_buys(tmp_path):
    """A built-in ``decision = "none"`` (no detection, no isolation) beside the paper's FDI on
    the same draw, a stop at 10 s: without FDI nobody is flagged, the stopped robot stays in
    the team and the mission is not completed; with it the stop is excluded and the robots
    left complete it. The rows carry the mission's outcome and each fault's, and the report's
    methods table shows both. A [methods.NAME.fdir] table reaches the scenario's [fdir]."""
    path = tmp_path / "n.toml"
    path.write_text(
        'name = "n"\nscenario = "paper_case"\nruns = 2\nseed = 5\n[set]\nduration = 30.0\n'
        '[vary]\nfault_kind = ["stop"]\nfaulty_robot = [1]\nfault_time = [10.0, 10.0]\n'
        '[methods.fdi]\n[methods.none]\ndecision = "none"\n[methods.none.fdir]\n'
        "compensate = false\n"
    )
    s = spec.load(path)
    blind = spec.scenario_for(s, spec.draw(s, 1))
    assert blind.onboard.decision == "none" and not blind.fdir.compensate
    out = tmp_path / "out"
    rows = {r["method"]: r for r in runner.run(s, out, workers=1, progress=False).rows}
    fdi, none = rows["fdi"], rows["none"]
    assert none["false_flags"] == 0 and json.loads(none["excluded"]) == []
    assert none["faults_missed"] == 1 and none["mission_completed"] is False
    assert fdi["faults_excluded"] == 1 and fdi["mission_completed"] is True
    assert fdi["final_slot_error"] < 0.05 < none["final_slot_error"]
    report.write(list(rows.values()), out, "n")
    text = (out / "report.md").read_text()
    assert "| none | 1 |" in text and "missions completed" in text
    # the rule table keeps the two methods apart, though both ran eq. 40
    assert {fdi["thresholds"], none["thresholds"]} == {"paper"}
    assert "| fdi: paper | 1 |" in text and "| none: paper | 1 |" in text


def test_a_client_server_that_gave_up_on_the_driver_says_what_to_do():
    """Ray's client server on a loaded head gives up on a driver's own server after 30 s; the
    one line said only "Initialization failure from server" (seen in CI, 2026-11-27)."""
    exc = ConnectionAbortedError("Initialization failure from server:\nTraceback ...")
    line = cluster._explain("ray://192.0.2.2:41477", exc, "")
    assert line.startswith(
        "--ray: cannot join ray://192.0.2.2:41477: Initialization failure from server: (the "
        "head's Ray client server did not start this driver's server in time"
    )
    assert "try again" in line and "\n" not in line
