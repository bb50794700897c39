"""The team in a web browser (``--web``, MuJoCo Studio's web viewer): a real headless
Chromium opens the page of a live run, the scene appears and simulated time advances, and
Ctrl-C keeps the run's records; a replay is served from a run's records; where the viewer
cannot serve, one error line and the documented exit code.

The browser is Debian's ``chromium`` (``apt-get install chromium``) driven by Playwright
(the dev extra), never a browser Playwright downloads. Each wait below is a safety net for
a stuck process, not a measure of speed: nothing here depends on how fast the machine is.
"""

from __future__ import annotations

import io
import json
import os
import queue
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
import urllib.request

import mujoco
import numpy as np
import pytest

from dftc_mujoco import load_scenario
from dftc_mujoco.closed_loop.loop import simulate
from dftc_mujoco.errors import EXIT_SERVE
from dftc_mujoco.render.display import HEALTHY

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
SAFETY = 600.0  # [s] the longest any one wait may take before the test calls it stuck

try:
    import mujoco.studio.web_viewer

    STUDIO = None
except Exception as exc:  # pragma: no cover - depends on the installation
    STUDIO = f"MuJoCo Studio's web viewer cannot be imported: {exc}"
needs_studio = pytest.mark.skipif(STUDIO is not None, reason=str(STUDIO))


class Served:
    """A command that serves a page: its output read line by line, the address it prints."""

    def __init__(self, args: list[str], cwd) -> None:
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", *args],
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.said: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line)
        self.lines.put("")  # the end

    def url(self) -> str:
        """The address of the one ``web:`` line (waits for it)."""
        deadline = time.monotonic() + SAFETY
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=1.0)
            except queue.Empty:
                continue
            self.said.append(line)
            if not line:
                break
            if line.startswith("web:"):
                found = re.search(r"http://\S+", line)
                assert found, line
                return found.group(0)
        pytest.fail("no web: line\n" + "".join(self.said))

    def interrupt(self) -> tuple[int, str]:
        """Ctrl-C; the exit code and everything it said."""
        self.proc.send_signal(signal.SIGINT)
        code = self.proc.wait(timeout=SAFETY)
        while True:
            line = self.lines.get(timeout=SAFETY)
            if not line:
                break
            self.said.append(line)
        return code, "".join(self.said)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def _browser(playwright, profile):
    """Debian's Chromium, headless, in a profile of its own."""
    if not os.path.exists(CHROMIUM):
        pytest.skip("Chromium is not installed (apt-get install chromium)")
    try:
        return playwright.chromium.launch_persistent_context(
            str(profile),
            executable_path=CHROMIUM,
            headless=True,
            args=ARGS,
            viewport={"width": 960, "height": 640},
        )
    except Exception as exc:  # a browser that cannot start here (no sandbox support, ...)
        pytest.skip(f"Chromium does not start here: {str(exc).splitlines()[0]}")


def _webgl(page) -> str | None:
    """What renders WebGL 2 in this browser, or None where nothing does."""
    return page.evaluate(
        "() => { const g = document.createElement('canvas').getContext('webgl2');"
        " return g ? String(g.getParameter(g.VERSION)) : null; }"
    )


def _time(frame: bytes) -> float | None:
    """The simulated time in a state frame of the web viewer's /state stream: after its
    header and the state's signature, ``mj_getState``'s first number (mjSTATE_TIME)."""
    sig = struct.pack("<I", int(mujoco.mjtState.mjSTATE_INTEGRATION))
    if not frame.startswith(b"MJWS"):
        return None
    at = frame.find(sig, 8)
    if at < 0 or at + 12 > len(frame):
        return None
    return struct.unpack_from("<d", frame, at + 4)[0]


@needs_studio
def test_a_live_run_in_a_browser(tmp_path):
    """The page loads, the scene appears (blue robots on the canvas), simulated time
    advances between two readings of what the browser receives, and Ctrl-C ends the run
    keeping its records (exit 130, as any interrupted run)."""
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="Playwright is not installed (the dev extra)"
    )
    out = tmp_path / "run"
    served = Served(
        [
            *("dftc_mujoco.run", "paper_case", "--web", "--port", "0", "--no-video"),
            *("--no-progress", "--out", str(out)),
        ],
        tmp_path,
    )
    times: list[float] = []
    try:
        url = served.url()
        with sync_api.sync_playwright() as pw:
            context = _browser(pw, tmp_path / "profile")
            try:
                page = context.new_page()

                def listen(ws) -> None:
                    if "/state" in ws.url:
                        ws.on("framereceived", lambda f: _note(f, times))

                page.on("websocket", listen)
                page.goto(url, timeout=SAFETY * 1000)
                if _webgl(page) is None:
                    pytest.skip("this Chromium cannot render WebGL 2 here (no GPU, no SwiftShader)")
                first = _wait(page, lambda: [t for t in times if t > 0], "a state with t > 0")[0]
                _wait(page, lambda: times[-1] > first, "simulated time to advance")
                second = times[-1]
                shot = page.screenshot()
            finally:
                context.close()
        code, said = served.interrupt()
    finally:
        served.kill()
    assert second > first > 0
    _the_scene_is_on(shot)
    assert code == 130, said
    assert "Traceback" not in said
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    assert 0 < summary["simulated_time"] < 60


def _note(frame, times: list[float]) -> None:
    if isinstance(frame, bytes):
        t = _time(frame)
        if t is not None:
            times.append(t)


def _wait(page, ready, what: str):
    """Until ``ready()`` is true; the browser's events are delivered while Playwright waits
    (``wait_for_timeout``), not while Python sleeps."""
    deadline = time.monotonic() + SAFETY
    while time.monotonic() < deadline:
        got = ready()
        if got:
            return got
        page.wait_for_timeout(200)
    pytest.fail(f"waited {SAFETY:g} s for {what}")


def _the_scene_is_on(png: bytes) -> None:
    """The screenshot is not blank: many colours, and the healthy robots' blue among them."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    assert img.std() > 5, "a blank page"
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 100
    blue = np.array(HEALTHY[:3]) * 255
    near = np.abs(img - blue).max(axis=2) < 40
    assert near.sum() > 50, "no robot in its state's colour"


@needs_studio
def test_a_replay_is_served_from_the_records(tmp_path):
    """``plot RUN --web`` serves the page (the web viewer's client) and stops on Ctrl-C."""
    run = tmp_path / "run"
    simulate(load_scenario("paper_case", {"duration": 1.0})).save(run)
    served = Served(["dftc_mujoco.plot", str(run), "--web", "--port", "0"], tmp_path)
    try:
        url = served.url()
        with urllib.request.urlopen(url, timeout=SAFETY) as reply:
            page = reply.read().decode()
        code, said = served.interrupt()
    finally:
        served.kill()
    assert "<canvas" in page
    assert code == 0, said
    assert "stopped by SIGINT" in said and "Traceback" not in said


@needs_studio
@pytest.mark.parametrize("command", ["run", "plot"])
def test_a_taken_port_is_one_error_line(command, tmp_path):
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("0.0.0.0", 0))
        taken.listen()
        port = taken.getsockname()[1]
        what = ["paper_case", "--no-video"] if command == "run" else [str(tmp_path)]
        done = subprocess.run(
            [sys.executable, "-m", f"dftc_mujoco.{command}", *what, "--web", "--port", str(port)],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=SAFETY,
        )
    assert f"port {port}" in done.stderr
    errors = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, done.stderr
    assert done.returncode == EXIT_SERVE and "Traceback" not in done.stderr
    assert "--port" in errors[0]


def test_without_the_web_viewer_one_error_line(tmp_path):
    code = (
        "import sys; sys.modules['mujoco.studio'] = None\n"
        "from dftc_mujoco.run import main\n"
        "sys.exit(main(['paper_case', '--web', '--no-video']))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=SAFETY
    )
    assert done.returncode == EXIT_SERVE, done.stderr
    assert done.stderr.count("error:") == 1 and "Traceback" not in done.stderr
    assert "pip install 'mujoco-studio" in done.stderr
    assert not (tmp_path / "renders").exists()  # refused before anything was built
