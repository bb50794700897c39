"""Loop cost as a ratio to bare ``mj_step`` replaying the run's own commands.

Shared by ``bench_step.py`` and ``bench_scale.py``. For one scenario, in this
process:

1. a warm-up :class:`~dftc_mujoco.closed_loop.loop.Simulation` of a few periods compiles
   (or loads from numba's cache) every compiled function, so that cost is not
   counted as loop time;
2. one recording run stores the actuator commands of every control period and the
   actuator parameters each time a fault changes them;
3. ``repeat`` times, interleaved: the closed loop (``Simulation.step`` to the
   end: faults, sensing, the onboard stacks, commands, logging) and the bare
   replay (the recorded commands written to ``data.ctrl``, the faults' parameter
   changes at their periods, and ``mj_step(model, data, nstep=substeps)``, nothing
   else) on the same model. The replay is the exact floor: its final state equals the
   closed loop's bit for bit (``exact`` in the result). Replayed with the faults
   cleared, a stopped robot drove on and collided, and the floor was 12-21 % slow.

Reported: the median and best of each, µs per control period, and their
ratio (median / median), plus the set-up and post-run derivation times.
"""

from __future__ import annotations

import statistics
import time

import mujoco
import numpy as np

from dftc_mujoco.closed_loop.loop import Simulation
from dftc_mujoco.scenario import Scenario
from dftc_mujoco.sim.plant import Plant


def measure(s: Scenario, repeat: int = 5) -> dict:
    """Loop and bare µs per control period for scenario ``s`` (see the module docstring)."""
    t0 = time.perf_counter()
    with Simulation(s) as warm:  # compile / load the numba cache outside the timings
        cold_setup = time.perf_counter() - t0  # a fresh process's set-up (κ/λ, numba cache)
        warm.step(3)
    commands: list[np.ndarray] = []
    faults: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # period -> actuator parameters

    def record(t: float, plant) -> None:
        m = plant.model
        params = (m.actuator_gainprm.copy(), m.actuator_biasprm.copy())
        last = faults[max(faults)] if faults else None
        if last is None or not all(np.array_equal(a, b) for a, b in zip(params, last, strict=True)):
            faults[len(commands)] = params
        commands.append(plant.data.ctrl.copy())

    with Simulation(s, hook=record) as sim:
        sim.run(progress=False)
        final = (sim.data.qpos.copy(), sim.data.qvel.copy())
    periods = len(commands)
    exact = True
    loop_us, bare_us, setup_s, derive_s = [], [], [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        sim = Simulation(s)
        t1 = time.perf_counter()
        sim.step(periods + 1)
        t2 = time.perf_counter()
        result = sim.result()
        t3 = time.perf_counter()
        sim.close()
        setup_s.append(t1 - t0)
        loop_us.append((t2 - t1) / (periods + 1) * 1e6)
        derive_s.append(t3 - t2)
        model, data = sim.scene.model, Plant.initial_data(sim.scene)  # the run's start
        healthy = (model.actuator_gainprm.copy(), model.actuator_biasprm.copy())
        nsub = s.physics.substeps
        ctrl = data.ctrl
        t0 = time.perf_counter()
        for k, c in enumerate(commands):
            if k in faults:
                model.actuator_gainprm[:], model.actuator_biasprm[:] = faults[k]
            ctrl[:] = c
            mujoco.mj_step(model, data, nstep=nsub)
        bare_us.append((time.perf_counter() - t0) / periods * 1e6)
        exact &= np.array_equal(data.qpos, final[0]) and np.array_equal(data.qvel, final[1])
        model.actuator_gainprm[:], model.actuator_biasprm[:] = healthy
    loop_med, bare_med = statistics.median(loop_us), statistics.median(bare_us)
    return {
        "periods": periods,
        "loop_us": loop_med,
        "loop_best_us": min(loop_us),
        "bare_us": bare_med,
        "bare_best_us": min(bare_us),
        "ratio": loop_med / bare_med,
        "exact": exact,
        "setup_s": statistics.median(setup_s),
        "cold_setup_s": cold_setup,
        "derive_s": statistics.median(derive_s),
        "path": result.summary["onboard"]["path"],
        "summary": result.summary,
    }
