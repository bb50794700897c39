"""The pass over the team's N × N state alone: its stages, and what float32 state would give.

    python benchmarks/bench_pass.py [--n 1000] [--repeat 7] [--periods 300]

The pass (``onboard/execution/period.py``, ``team_rows``) is the part of a period that grows as N²:
every robot estimates the whole team (the paper's design), so each period reads and writes
N × N × 2 numbers of ŷ and of ∫ⁱû_g and writes N × N × 2 of the next ŷ. At N = 1000 it is
what keeps the loop above twice the physics floor (docs/performance.md). On the
scale benchmark's scene (``bench_scale.scene``) after 3 s, on one core, the minimum and
median of ``--repeat`` timings (µs) of:

* the integrals only: ⁱx̂ and ∫ⁱû_g (eqs. 15, 20, 21), a period between two rounds of a
  network;
* plus the round: the residual (eq. 35) and the next ŷ (eq. 19); without FDIR and a log
  row the pass computes no norms;
* plus the decision (eq. 39): each row at rest tested in the residual's own loop against
  its share of eq. 40's bound (``onboard/decision.py``, ``quiet_sums``), else from its
  residual's squares (``quiet_row``), and the norms taken only for the rows that fail both:
  the whole pass, as the team runs it at this N between log rows;
* the whole pass again with ŷ, ∫ⁱû_g and the next ŷ held in float32 (copies of the team's
  arrays): what float32 state would save. The project keeps float64: the records would
  change, and its thresholds are millimetres over positions of tens of metres. The largest
  difference of the next ŷ after one pass from the same state is printed beside the
  smallest threshold ⁱμ_k once the thresholds have settled.

For a team that shares its pass between threads (N ≥ ``Execution.shared_from``), the loop
itself over ``--periods`` periods, in one ``Simulation.step`` call, with its pass shared
(every core) and in one thread, alternately, the best of ``--repeat`` each (ms a period),
and how many of the pass's chunks of rows the calling thread took (it takes those left once
it has sent the commands and stepped the physics).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from bench_scale import scene

from dftc_mujoco.closed_loop.execution import SHARED_FROM, Execution
from dftc_mujoco.closed_loop.loop import Simulation
from dftc_mujoco.onboard.decision import bound_squares
from dftc_mujoco.onboard.execution.period import PeriodInputs, team_rows

#: [s] the state the pass is timed on: after the transient's start, before the fault
AFTER = 3.0


def timed(call, repeat: int) -> tuple[float, float]:
    """(min, median) of ``repeat`` timings of ``call()`` after one untimed call, µs."""
    call()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        call()
        times.append((time.perf_counter() - t0) * 1e6)
    return min(times), statistics.median(times)


def in_float32(ob, buf):
    """Copies of the observer's record and the period's buffers with ŷ, ∫ⁱû_g, the next ŷ,
    the links' messages and ⁱx̂ in float32."""
    f4 = np.float32
    ob32 = ob._replace(
        y_hat=ob.y_hat.astype(f4),
        int_u_hat=ob.int_u_hat.astype(f4),
        y_next=ob.y_next.astype(f4),
        links=ob.links.astype(f4),  # the messages a network delivered: ŷ as it was sent
    )
    return ob32, buf._replace(x_hat=buf.x_hat.astype(f4))


def shared_periods(n: int, k: int, threads: int | None) -> tuple[float, int, int]:
    """(ms a period, chunks the calling thread took, chunks) over ``k`` periods of the loop
    after the scene's first ``AFTER`` s, its pass in ``threads`` threads (None: every core)."""
    # the scene's fault (a stop at half the duration) comes after the window
    with Simulation(
        scene(n, 2 * (AFTER + 0.01 * k) + 1.0), execution=Execution(threads=threads)
    ) as sim:
        sim.step(round(AFTER / sim.dt))
        sharing = sim.team._sharing
        mine, chunks = (sharing.caller_chunks, sharing.chunks) if sharing else (0, 0)
        t0 = time.perf_counter()
        sim.step(k)
        period = (time.perf_counter() - t0) / k * 1e3
        if sharing:
            mine, chunks = sharing.caller_chunks - mine, sharing.chunks - chunks
    return period, mine, chunks


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--periods", type=int, default=300, help="periods of the shared loop")
    args = p.parse_args()
    n = args.n
    sim = Simulation(scene(n, 2 * AFTER + 1.0))  # its stop fault comes after AFTER
    sim.step(round(AFTER / sim.dt))
    team = sim.team
    m = len(team.members)
    j = sim.k
    offsets, rates = team.plan.at(sim.k * sim.dt)
    x_m = sim.snapshot().x_m
    c, c_dot = sim.path.position[j], sim.path.velocity[j]

    def inputs(fdir: bool, round_now: bool) -> PeriodInputs:
        return PeriodInputs(
            x_m, team.members, c, c_dot, offsets, rates, fdir, round_now, False, False
        )

    ob, ctl, th = team.observer.record(), team.controller.record(), team._th
    dec, buf = team.decision.record(), team._buffers
    bound_squares(th, 2, buf.scale)  # the decision's scale, as the period's begin writes it
    ob32, buf32 = in_float32(ob, buf)

    def rows(inp, o, b):
        return lambda: team_rows(inp, o, ctl, th, dec, b, 0, m, 0)

    print(f"N = {n}, one core, the scene's state at {AFTER:g} s; µs a pass: min / median")
    lines = [
        ("the integrals only", rows(inputs(True, False), ob, buf)),
        ("+ the round, no decision", rows(inputs(False, True), ob, buf)),
        ("+ the decision: the whole pass", rows(inputs(True, True), ob, buf)),
        ("the whole pass, float32 state", rows(inputs(True, True), ob32, buf32)),
    ]
    for name, call in lines:
        lo, med = timed(call, args.repeat)
        print(f"  {name:46s} {lo:9.1f} / {med:9.1f}")

    # one pass from the same state in both precisions: how far the next ŷ lands apart
    ob = team.observer.record()
    ob32, buf32 = in_float32(ob, buf)
    ob64 = ob._replace(
        y_hat=ob.y_hat.copy(), int_u_hat=ob.int_u_hat.copy(), y_next=ob.y_next.copy()
    )
    team_rows(inputs(False, True), ob64, ctl, th, dec, buf, 0, m, 0)
    team_rows(inputs(False, True), ob32, ctl, th, dec, buf32, 0, m, 0)
    gap = float(np.abs(ob64.y_next - ob32.y_next.astype(np.float64)).max())
    scale = float(np.abs(ob64.y_next).max())
    settled = float(np.nanmin(team.thresholds.mu(1e6)))  # the thresholds once settled
    print(
        f"  float32's next ŷ after one pass: at most {gap:.2e} m from float64's (|ŷ| up to "
        f"{scale:.1f} m); the scene's smallest threshold (eq. 40) once settled {settled:.3g} m"
    )
    sim.close()

    if n < SHARED_FROM:
        print(f"  (N < {SHARED_FROM}: the team runs its pass in one thread)")
        return
    best: dict[str, tuple[float, int, int]] = {}
    for _ in range(args.repeat):
        for way, threads in (("shared", None), ("one thread", 1)):
            got = shared_periods(n, args.periods, threads)
            if way not in best or got[0] < best[way][0]:
                best[way] = got
    shared, one = best["shared"], best["one thread"]
    print(
        f"  the loop, {args.periods} periods: {shared[0]:.3f} ms a period with its pass shared, "
        f"{one[0]:.3f} ms in one thread ({1 - shared[0] / one[0]:.0%} less); the calling "
        f"thread took {shared[1]} of the pass's {shared[2]} chunks"
    )


if __name__ == "__main__":
    main()
