"""numba's cache is emptied when a source changed: a compiled caller keeps its callees' old
code, and a stale one crashed runs (segmentation fault) after the records changed."""

from __future__ import annotations

from dftc_mujoco.runtime import numba_cache


def test_a_changed_source_empties_the_cache_once(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    (pkg / "__pycache__").mkdir()
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    cached = [pkg / "__pycache__" / "a.f-1.py311.nbi", pkg / "sub" / "__pycache__" / "b.g.nbc"]
    for c in cached:
        c.write_bytes(b"old")
    assert numba_cache.refresh(pkg)  # no stamp yet: whatever is cached is of unknown age
    assert not any(c.exists() for c in cached)
    for c in cached:
        c.write_bytes(b"fresh")
    assert not numba_cache.refresh(pkg)  # nothing changed: the cache stays
    assert all(c.exists() for c in cached)
    (pkg / "sub" / "b.py").write_text("y = 3  # edited\n")
    assert numba_cache.refresh(pkg)
    assert not any(c.exists() for c in cached)
    assert (pkg / "a.py").exists() and (pkg / "sub" / "b.py").exists()  # sources untouched


def _run(tmp_path, name, env):
    import json
    import subprocess
    import sys

    out = tmp_path / name
    done = subprocess.run(
        [sys.executable, "-m", "dftc_mujoco.run", "paper_case", "--no-video", "--duration", "12",
         "--out", str(out)],
        env=env, capture_output=True, text=True, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    return done, json.loads((out / "summary.json").read_text()), out


def test_a_cold_cache_runs_at_once_and_the_next_run_is_compiled(tmp_path):
    """A first run on a machine (numba's cache empty) says that it compiles, reports its
    simulation time without the compilation, runs the general path (the same numbers) while
    a background process compiles the one-call period; the next run finds it cached."""
    import fcntl
    import os

    import numpy as np

    from dftc_mujoco.closed_loop import warm

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "DFTC_PERIOD": "auto"}
    first, cold, out1 = _run(tmp_path, "first", env)
    assert "compiling the onboard code for this machine" in first.stderr
    assert "compiling the onboard code: once for this machine" in first.stdout
    assert cold["onboard"]["path"] == "general" and cold["onboard"]["compiling_in_background"]
    assert cold["compile_time"] > 0
    # the background process holds its lock until the compiled period is in the cache
    (lock,) = (tmp_path / "cache").rglob(warm.LOCK)
    with open(lock) as f:
        fcntl.flock(f, fcntl.LOCK_EX)  # blocks until it is done
    log = next((tmp_path / "cache").rglob(warm.LOG)).read_text()
    assert "compiled the control period for paper_case" in log, log
    second, warmed, out2 = _run(tmp_path, "second", env)
    assert warmed["onboard"]["path"] == "compiled"
    assert "compiling_in_background" not in warmed["onboard"]
    assert "compiling" not in second.stderr, second.stderr
    with np.load(out1 / "log.npz") as a, np.load(out2 / "log.npz") as b:
        for k in a.files:  # the general path is the same computation, bit for bit
            assert np.array_equal(a[k], b[k], equal_nan=True), k
    assert cold["events"] == warmed["events"]


def test_the_background_compilation_compiles_the_types_the_run_calls_with():
    """The background process gets the scenario pickled, and a read-only array of the
    scenario comes back writable: the compiled period took K read-only in the run and
    writable in the background, so the run after the background compilation compiled again."""
    import pickle

    from numba import typeof

    from dftc_mujoco.closed_loop.loop import Simulation
    from dftc_mujoco.scenario import load_scenario

    s = load_scenario("paper_case", {"duration": 0.1})

    def period_types(scenario):
        team = Simulation(scenario).team
        return [typeof(a) for a in team._th + team._fields()]

    assert period_types(s) == period_types(pickle.loads(pickle.dumps(s)))


def test_tracing_lists_the_compiled_functions_a_period_calls_with_their_types():
    """What the background process compiles for a first run: the functions the general path
    calls from Python, in the run's order, with the types a run calls them with (the
    scenario pickled to that process too); the module's functions are compiled ones again
    afterwards."""
    import pickle

    from numba.core.registry import CPUDispatcher

    from dftc_mujoco.closed_loop.execution import Execution
    from dftc_mujoco.closed_loop.loop import Simulation
    from dftc_mujoco.onboard import supervisor
    from dftc_mujoco.scenario import load_scenario

    s = load_scenario("paper_case", {"duration": 1.0})

    def traced(scenario):
        with Simulation(scenario, execution=Execution("general")) as sim:
            calls = numba_cache.traced_calls(lambda: sim.step(2))
            assert sim.k == 2  # the two periods ran, as plain Python
        return [(c.name, c.types) for c in calls]

    calls = traced(s)
    names = [name.rsplit(".", 1)[1] for name, _ in calls]
    assert {"supervise", "residual", "decide", "estimate_faults"} <= set(names), names
    assert names.index("supervise") < names.index("decide")  # the order of a period
    assert len(set(calls)) == len(calls)
    assert calls == traced(pickle.loads(pickle.dumps(s)))
    assert isinstance(supervisor.supervise, CPUDispatcher)


def test_the_background_process_leaves_the_general_path_compiled(tmp_path):
    """On an empty cache the background process compiles the general path's functions for
    the scenario (the first run meets it half-way): a general run after it compiles
    nothing."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    scenario = "load_scenario('paper_case', {'duration': 1.0})"
    helper = subprocess.run(
        [sys.executable, "-c", "from dftc_mujoco.precompile import general; "
         f"from dftc_mujoco import load_scenario; general({scenario}, [])"],
        env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert helper.returncode == 0, helper.stderr
    assert "compiled the general path's" in helper.stdout
    run = subprocess.run(
        [sys.executable, "-c", "from dftc_mujoco import load_scenario, Simulation; "
         "from dftc_mujoco.runtime import numba_cache; "
         "from dftc_mujoco.closed_loop.execution import Execution; clock = numba_cache.clock(); "
         f"sim = Simulation({scenario}, execution=Execution('general')); sim.step(2); "
         "print('compiled', clock.functions)"],
        env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert run.stdout.split()[-2:] == ["compiled", "0"], run.stdout
