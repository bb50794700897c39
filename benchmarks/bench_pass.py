"""The pass over the team's N × N state alone: its stages, and what float32 state would give.

    python benchmarks/bench_pass.py [--n 1000] [--repeat 7] [--periods 300]

The pass (``onboard/period.py``, ``team_rows``) is the part of a period that grows as N²:
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
  the whole pass, as the
  team runs it at this N between log rows (ŷ streamed past the caches where the team
  streams it, ``onboard/streaming.py``);
* the whole pass again with ŷ, ∫ⁱû_g and the next ŷ held in float32 (copies of the team's
  arrays, streamed and not): what float32 state would save. The project keeps float64: the
  records would change, and its thresholds are millimetres over positions of tens of metres.
  The largest difference of the next ŷ after one pass from the same state is printed
  beside the smallest threshold ⁱμ_k once the thresholds have settled.

For a team that shares its pass between threads (N ≥ ``sharing.PARALLEL_FROM``), the split
of ``--periods`` periods of the loop itself, in one ``Simulation.step`` call (means in ms,
from ``Sharing.sums``): the period; the work the calling thread does beside the pass (the
commands and MuJoCo's step); when the helper threads and the calling thread end their rows;
and what of the period is outside the shared part. Then when the helpers begin, how long
each works on its rows, and the period's work on all threads (the calling thread's period
but its wait for the helpers, and the helpers' rows): divided by the threads, the shortest
period this split of the work allows, were no thread ever idle.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from bench_scale import scene

from dftc_mujoco.loop import Simulation
from dftc_mujoco.onboard.decision import bound_squares
from dftc_mujoco.onboard.period import PeriodInputs, team_rows
from dftc_mujoco.onboard.sharing import PARALLEL_FROM, SUMMED

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


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--periods", type=int, default=300, help="periods of the split (shared)")
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
    streamed = team._stream  # as the team runs its pass at this N

    def inputs(fdir: bool, round_now: bool, stream: bool) -> PeriodInputs:
        return PeriodInputs(
            x_m, team.members, c, c_dot, offsets, rates, fdir, round_now, False, False, stream
        )

    ob, ctl, th = team.observer.record(), team.controller.record(), team._th
    dec, buf = team.decision.record(), team._buffers
    bound_squares(th, 2, buf.scale)  # the decision's scale, as the period's begin writes it
    ob32, buf32 = in_float32(ob, buf)

    def rows(inp, o, b):
        return lambda: team_rows(inp, o, ctl, th, dec, b, 0, m, 0)

    print(f"N = {n}, one core, the scene's state at {AFTER:g} s; µs a pass: min / median")
    lines = [
        ("the integrals only", rows(inputs(True, False, streamed), ob, buf)),
        ("+ the round, no decision", rows(inputs(False, True, streamed), ob, buf)),
        (f"+ the decision: the whole pass{' (streamed)' if streamed else ''}",
         rows(inputs(True, True, streamed), ob, buf)),
        ("the whole pass, float64, not streamed", rows(inputs(True, True, False), ob, buf)),
        ("the whole pass, float32 state, streamed", rows(inputs(True, True, True), ob32, buf32)),
        ("the whole pass, float32 state, not streamed",
         rows(inputs(True, True, False), ob32, buf32)),
    ]  # fmt: skip
    for name, call in lines:
        lo, med = timed(call, args.repeat)
        print(f"  {name:46s} {lo:9.1f} / {med:9.1f}")

    # one pass from the same state in both precisions: how far the next ŷ lands apart
    ob = team.observer.record()
    ob32, buf32 = in_float32(ob, buf)
    ob64 = ob._replace(
        y_hat=ob.y_hat.copy(), int_u_hat=ob.int_u_hat.copy(), y_next=ob.y_next.copy()
    )
    team_rows(inputs(False, True, False), ob64, ctl, th, dec, buf, 0, m, 0)
    team_rows(inputs(False, True, False), ob32, ctl, th, dec, buf32, 0, m, 0)
    gap = float(np.abs(ob64.y_next - ob32.y_next.astype(np.float64)).max())
    scale = float(np.abs(ob64.y_next).max())
    settled = float(np.nanmin(team.thresholds.mu(1e6)))  # the thresholds once settled
    print(
        f"  float32's next ŷ after one pass: at most {gap:.2e} m from float64's (|ŷ| up to "
        f"{scale:.1f} m); the scene's smallest threshold (eq. 40) once settled {settled:.3g} m"
    )
    sim.close()

    if n < PARALLEL_FROM:
        print(f"  (N < {PARALLEL_FROM}: the team runs its pass in one thread)")
        return
    k = args.periods
    # the scene's fault (a stop at half the duration) comes after the window
    with Simulation(scene(n, 2 * (AFTER + 0.01 * k) + 1.0)) as sim:
        sim.step(round(AFTER / sim.dt))
        sharing = sim.team._sharing
        passes, sums = sharing.passes, sharing.sums
        t0 = time.perf_counter()
        sim.step(k)
        period = (time.perf_counter() - t0) / k * 1e3
        runs, w = sharing.passes - passes, sharing.threads
        spent = zip(sums, sharing.sums, strict=True)
        mean = dict(zip(SUMMED, ((b - a) / runs * 1e3 for a, b in spent), strict=True))
    beside, helpers, caller = mean["beside"], mean["helpers_end"], mean["caller_end"]
    print(
        f"  the loop, {k} periods: a period {period:.3f} ms; in it the calling thread's work "
        f"beside the pass {beside:.3f} ms, the helpers end at {helpers:.3f} ms, the calling "
        f"thread at {caller:.3f} ms, the rest of the period {period - max(helpers, caller):.3f} ms"
    )
    # the calling thread works but while it waits for the helpers; each helper only on its rows
    work = period - (mean["joined"] - caller) + (w - 1) * mean["helper_work"]
    print(
        f"  the helpers begin their rows at {mean['helpers_start']:.3f} ms and work "
        f"{mean['helper_work']:.3f} ms each, the calling thread's rows take "
        f"{caller - beside:.3f} ms and it joins the helpers at {mean['joined']:.3f} ms: "
        f"{work:.3f} ms of work on {w} threads, {work / w:.3f} ms a period if none ever idled"
    )


if __name__ == "__main__":
    main()
