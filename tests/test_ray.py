"""Campaigns on a real local Ray cluster (`ray start --head` in a subprocess): by its
address, by bare --ray, through ray://, with token authentication; unreachable
addresses fail fast with one line."""

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import pytest

ray = pytest.importorskip("ray", reason="Ray is not installed (pip install -e '.[cluster]')")

ROOT = Path(__file__).resolve().parent.parent
TINY = ROOT / "campaigns" / "tiny.toml"
RAY = Path(sys.executable).parent / "ray"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _campaign(*args: str, env: dict[str, str], timeout: float = 900) -> tuple[int, str, str]:
    done = subprocess.run(
        [sys.executable, "-m", "dftc_mujoco.campaign", str(TINY), "--no-progress", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=timeout,
    )
    return done.returncode, done.stdout, done.stderr


def _rows(folder: Path) -> dict[int, dict]:
    rows = [json.loads(x) for x in (folder / "results.jsonl").read_text().splitlines()]
    return {r["run"]: {k: v for k, v in r.items() if k != "wall_time"} for r in rows}


@pytest.fixture(scope="module")
def head(ray_module_alone):
    """A Ray head node with token authentication, in a session of its own with a private
    temp folder (so that it neither meets nor leaves behind another instance's files);
    killed with its whole process group at the end."""
    if not RAY.exists():
        pytest.skip(f"no `ray` command beside {sys.executable}")
    from ray._private import services

    if services.find_gcs_addresses():
        pytest.skip("another Ray instance runs on this machine; this test needs to be alone")
    temp = Path(tempfile.mkdtemp(prefix="ray", dir="/tmp"))  # short: Unix socket paths
    port, client = _free_port(), _free_port()
    token = uuid.uuid4().hex
    env = {
        **os.environ,
        "RAY_AUTH_MODE": "token",
        "RAY_AUTH_TOKEN": token,
        "RAY_USAGE_STATS_ENABLED": "0",
        # the head's client proxy waits this long for the server process it starts per
        # ray:// driver (30 s by default: "Initialization failure from server" on a loaded
        # 2-core machine, once in a full suite)
        "RAY_CLIENT_SERVER_CHECK_CHANNEL_TIMEOUT_S": "150",
    }
    env.pop("RAY_ADDRESS", None)
    proc = subprocess.Popen(
        [
            *(str(RAY), "start", "--head", f"--port={port}", f"--ray-client-server-port={client}"),
            *("--num-cpus=2", "--include-dashboard=false", f"--temp-dir={temp}", "--block"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        start_new_session=True,
    )
    address = None
    deadline = time.time() + 900
    while time.time() < deadline and proc.poll() is None:
        line = proc.stdout.readline()
        found = re.search(r"--address='?([0-9A-Za-z.\-]+:[0-9]+)", line)
        if found and address is None:
            address = found.group(1)
        if "will now block" in line:
            break
    assert address, "ray start --head did not come up"
    host = address.rsplit(":", 1)[0]
    try:
        yield {"address": address, "client": f"ray://{host}:{client}", "env": env, "temp": temp}
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=900)
        shutil.rmtree(temp, ignore_errors=True)


@pytest.fixture(scope="module")
def local_rows(tmp_path_factory):
    out = tmp_path_factory.mktemp("local")
    code, _, err = _campaign(
        "--runs", "2", "--workers", "1", "--out", str(out), env=dict(os.environ)
    )
    assert code == 0, err
    return _rows(out)


def test_a_campaign_joins_a_running_cluster_by_address_and_by_bare_ray(head, local_rows, tmp_path):
    """--ray ADDRESS, then bare --ray, which used to fail ("num_cpus ... must not be
    provided") while a local cluster ran: both join the cluster started above."""
    env = head["env"]
    code, out, err = _campaign(
        "--runs", "2", "--ray", head["address"], "--out", str(tmp_path / "a"), env=env
    )
    assert code == 0, err
    assert f"on Ray at {head['address']}" in out
    assert _rows(tmp_path / "a") == local_rows
    code, out, err = _campaign("--runs", "2", "--ray", "--out", str(tmp_path / "b"), env=env)
    assert code == 0, err
    assert f"on Ray at {head['address']}" in out  # the running cluster, not a new one
    assert _rows(tmp_path / "b") == local_rows


def _client_server_logs(temp: Path, lines: int = 20) -> str:
    """The last lines of the head's Ray client server logs (the proxy and one per driver)."""
    logs = sorted((temp / "session_latest" / "logs").glob("ray_client_server*"))
    tails = [f"--- {f.name}\n" + "\n".join(f.read_text().splitlines()[-lines:]) for f in logs]
    return "\n".join(tails) or f"(no client server logs under {temp})"


def test_ray_client_addresses_work_with_the_cluster_extra(head, local_rows, tmp_path):
    pytest.importorskip("grpc", reason="ray[client] is not installed (the cluster extra)")
    # Ray's client server starts a server process per driver: tens of seconds on a
    # loaded 2-core machine (CI once gave up at 25 s), hence the long --ray-timeout. Twice
    # (2026-11-26, first in a full CI run) a driver was not let in within 150 s at all,
    # while the same test alone, or under two busy cores, joins in 15-20 s; once (2026-11-27,
    # CI beside a benchmark) the client server gave up on the driver's own server after 30 s
    # ("Initialization failure from server"): a driver that could not join is followed by one
    # more, and a second failure shows the head's logs.
    for attempt in (1, 2):
        out = tmp_path / f"attempt{attempt}"
        code, _, err = _campaign(
            *("--runs", "2", "--ray", head["client"], "--ray-timeout", "150"),
            *("--out", str(out)),
            env=head["env"],
            timeout=900,
        )
        if code == 0 or not ("could not join" in err or "Initialization failure" in err):
            break
    assert code == 0, f"{err}\n{_client_server_logs(head['temp'])}"
    assert _rows(out) == local_rows


def test_a_cluster_that_wants_a_token_says_so_in_one_line(head, tmp_path):
    env = {k: v for k, v in head["env"].items() if not k.startswith("RAY_AUTH")}
    code, _, err = _campaign("--ray", head["address"], "--out", str(tmp_path), env=env)
    assert code == 5
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "RAY_AUTH_MODE=token" in lines[0], err
    assert list(tmp_path.iterdir()) == []  # nothing written: the folder is prepared after joining


@pytest.mark.parametrize(
    "address", ["127.0.0.1:{port}", "ray://127.0.0.1:{port}", "nowhere.invalid:6379"]
)
def test_an_unreachable_address_fails_fast_in_one_line(tmp_path, address):
    """It used to hang for more than 120 s without a word."""
    address = address.format(port=_free_port())  # nothing listens there
    code, _, err = _campaign("--ray", address, "--out", str(tmp_path), env=dict(os.environ))
    assert code == 5  # in one line, within --ray-timeout (60 s), not a hang
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: --ray {address}: "), err
    assert "Traceback" not in err and list(tmp_path.iterdir()) == []
