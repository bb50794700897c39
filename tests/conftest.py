"""Shared helpers: scenarios derived from the shipped ones, and cached physics runs."""

from __future__ import annotations

import contextlib
import copy
import os
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

# the suite runs the compiled period wherever the blocks allow it, as it always did; the
# "auto" choice of a cold cache (dftc_mujoco.closed_loop.execution) is tested on its own,
# in processes with a cache of their own (tests/test_numba_cache.py)
os.environ.setdefault("DFTC_PERIOD", "compiled")

from dftc_mujoco import scenario
from dftc_mujoco.closed_loop.loop import RunResult, simulate
from dftc_mujoco.render import gl
from dftc_mujoco.runtime.paths import SCENARIOS

try:
    gl.probe()
    GL_ERROR = None
except gl.RenderError as exc:  # pragma: no cover - depends on the machine
    GL_ERROR = str(exc)
#: skips a test, saying why, where no GL backend can be created
needs_gl = pytest.mark.skipif(GL_ERROR is not None, reason=f"no GL backend: {GL_ERROR}")


def scenario_dict(name: str = "paper_case") -> dict[str, Any]:
    """A shipped scenario as a plain dict, to be modified by a test."""
    with open(SCENARIOS / f"{name}.toml", "rb") as fh:
        return tomllib.load(fh)


def ring_with_chords(n: int, chord: int = 3) -> list[list[int]]:
    """Directed ring 1 -> 2 -> ... -> n -> 1 plus a chord i -> i + chord from every robot."""
    edges = [[i, i % n + 1] for i in range(1, n + 1)]
    edges += [[i, (i + chord - 1) % n + 1] for i in range(1, n + 1)]
    return edges


def ring_team(n: int, radius: float, chord: int = 3, shift: float = 0.0) -> dict[str, Any]:
    """A ``[team]`` table: n robots evenly on a circle of ``radius`` about (shift, shift),
    on :func:`ring_with_chords`."""
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return {
        "robots": n,
        "graph": ring_with_chords(n, chord=chord),
        "initial_positions": (radius * np.c_[np.cos(ang), np.sin(ang)] + shift).tolist(),
    }


def make(data: dict[str, Any], source: str = "<test>") -> scenario.Scenario:
    return scenario.from_dict(copy.deepcopy(data), source=source)


def write_toml(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.fixture(scope="session")
def fault_free_run() -> RunResult:
    """paper_case without faults, 28 s: two avoidance episodes, then plain tracking."""
    d = scenario_dict()
    d["faults"] = []
    d["duration"] = 28.0
    return simulate(make(d))


#: one period of paper_case on each path: what most tests and their subprocesses compile
_WARM = (
    "from dftc_mujoco import Simulation, load_scenario\n"
    "from dftc_mujoco.closed_loop.execution import Execution\n"
    "with Simulation(load_scenario('paper_case'), execution=Execution({!r})) as sim:\n"
    "    sim.step(2)\n"
)


def pytest_configure(config: pytest.Config) -> None:
    """Fill numba's cache before the tests start (in the process that starts pytest-xdist's
    workers, once): on a fresh clone each worker, and each command-line run a test starts
    meanwhile, would otherwise compile the same functions side by side. Both paths compile
    at once, one process each; on a warm cache they only load it (a few seconds)."""
    if hasattr(config, "workerinput") or os.environ.get("NUMBA_DISABLE_JIT") == "1":
        return
    import subprocess
    import sys
    import time

    t0 = time.perf_counter()
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _WARM.format(period)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for period in ("compiled", "general")
    ]
    for proc in procs:
        _, err = proc.communicate()
        if proc.returncode != 0:  # the tests that need it will say what is wrong
            print(f"numba's cache was not filled: {err.strip().splitlines()[-1:]}")
    took = time.perf_counter() - t0
    print(f"numba's cache filled for the onboard period ({took:.0f} s)", flush=True)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run tests/test_ray.py first (the rest keeps its order). Its `ray://` test has the
    head node start a server process per driver; at the end of a full suite on the 2-core
    machine that process twice failed to come up (once within Ray's own 30 s, once within
    150 s), while the same tests pass alone, after test_campaign or test_platform, and
    after every module between them (one cause not found: each subset passed)."""
    items.sort(key=lambda item: item.path.name != "test_ray.py")


@contextlib.contextmanager
def _one_ray_at_a_time(factory: pytest.TempPathFactory) -> Iterator[None]:
    """Hold the lock that keeps Ray instances started by the tests apart: a bare `--ray`
    joins the one instance running on the machine, so no other test may start its own
    meanwhile. The lock file is in the folder every pytest-xdist worker's temp folder is
    in, so the workers of a parallel run (`pytest -n auto`) share it."""
    import fcntl

    with open(factory.getbasetemp().parent / "dftc-ray.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # waits for the other worker's Ray tests
        yield


@pytest.fixture(scope="module")
def ray_module_alone(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """The Ray lock for a whole module (tests/test_ray.py: its head node lives that long)."""
    with _one_ray_at_a_time(tmp_path_factory):
        yield


@pytest.fixture
def ray_alone(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """The Ray lock for one test that starts a local Ray instance."""
    with _one_ray_at_a_time(tmp_path_factory):
        yield
