"""What a run's summary says beyond its events: estimates that agree with each other but not
with the world are warned about (e.g. a plug-in settled on a perfect square while the
real formation was 0.16 m off, and nothing said so)."""

import numpy as np

from dftc_mujoco import Simulation, load_scenario
from dftc_mujoco.blocks import paper


class _Agreed(paper.Observer):
    """Every robot's estimate puts robot 3 0.3 m further in x than it stands (an observer
    that drifts, in agreement): the controllers settle the estimates on a perfect square,
    so the real robot 3 ends 0.3 m off its slot."""

    def estimate(self):
        x_hat = np.array(super().estimate(), copy=True)
        x_hat[:, 2, 0] += 0.3
        return x_hat


def _warnings(blocks=None):
    s = load_scenario("paper_case", overrides={"faults": [], "duration": 20.0})
    return Simulation(s, blocks=blocks).run(progress=False).summary


def test_estimates_that_agree_but_not_with_the_world_are_warned_about():
    fine = _warnings()
    assert fine["warnings"] == []
    off = _warnings({"observer": _Agreed()})
    assert off["errors"]["final_formation"] > 0.05  # the real formation is off
    said = [w for w in off["warnings"] if "estimates of robot" in w]
    assert len(said) == 1 and said[0].startswith("the team's estimates of robot 3 were")
    assert off["estimation_error"]["per_robot_rms"][2] > 0.25


def test_a_run_with_a_hundred_thousand_flags_is_summarised_in_seconds():
    """Which flags and exclusions hit healthy robots is looked up from each robot's first
    fault, not searched for among the events per flag: an N = 400 run of the untuned battery
    (no_false_exclusion_400, run 36: 136 141 detections among 161 797 events) took 36 min to
    summarise that way, and 1.7 s now. Here 40 000 made-up flags on a paper_case run whose
    robot 2 has a bias from 19 s: the counts are right and the summary takes seconds."""
    s = load_scenario("paper_case", overrides={"duration": 21.0})
    with Simulation(s) as sim:
        sim.step(sim.steps + 1)
        before = sim.result().summary
        for k in range(40_000):  # robot 2 flagged before and after its fault, robot 3 always
            t = 0.0005 * k
            sim.events.add(t, "detection", by=1, robot=2 + k % 2, premises=[])
        after = sim.result().summary  # seconds; the search per flag took minutes
    assert before["faults"][0]["robot"] == 2 and before["faults"][0]["t"] == 19.0
    # robot 3's 20 000 flags, and robot 2's up to 19 s (t = 0.0005 k < 19 for k < 38 000)
    made = 20_000 + 19_000
    assert after["healthy_flags"] == before["healthy_flags"] + made


def _numpy_peak_ratio(residual, threshold, columns):
    """The definition of the summary's margin, in numpy (float32 logs, float64 ratios)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = residual.astype(float) / threshold
    ratio = np.where(columns[:, None, :], ratio, np.nan)
    finite = np.isfinite(ratio)
    return float(np.nanmax(np.where(finite, ratio, np.nan))) if finite.any() else 0.0


def _numpy_estimation_errors(x_hat, x, rows, keep):
    """The definition of the summary's estimation error, in numpy, one sample at a time."""
    n = x.shape[1]
    total, count, worst = np.zeros(n), np.zeros(n), 0.0
    for j in keep:
        e = np.linalg.norm(x_hat[j].astype(float) - x[rows[j]][None], axis=-1)
        np.fill_diagonal(e, np.nan)
        ok = np.isfinite(e)
        total += np.where(ok, e**2, 0.0).sum(axis=0)
        count += ok.sum(axis=0)
        if ok.any():
            worst = max(worst, float(np.nanmax(e)))
    return total, count, worst


def test_the_compiled_derivations_give_numpys_numbers_bit_for_bit():
    # the summary's margin and estimation error are computed entry by entry after the run
    # (at N = 1000 numpy's N × N temporaries took a second); on float32 logs with NaN
    # (excluded robots) and inf (unbounded thresholds) they must be numpy's numbers
    from dftc_mujoco.reporting.results import _estimate_sums, peak_ratio

    rng = np.random.default_rng(7)
    t, n = 40, 23
    residual = rng.uniform(0, 2, (t, n, n)).astype(np.float32)
    threshold = rng.uniform(0.3, 3, (t, n, n)).astype(np.float32)
    residual[:, 4, :] = np.nan
    threshold[:, :, 5] = np.inf
    threshold[3, 2, 7] = 0.0  # a ratio of inf: not finite, skipped
    columns = rng.uniform(size=(t, n)) < 0.5
    expected = _numpy_peak_ratio(residual, threshold, columns)
    assert peak_ratio(residual, threshold, columns) == expected > 1.0
    assert peak_ratio(residual, threshold, np.zeros_like(columns)) == 0.0

    x = rng.uniform(-20, 20, (3 * t, n, 2))
    x_hat = (x[::3, None, :, :] + rng.normal(0, 0.3, (t, n, n, 2))).astype(np.float32)
    x_hat[:, 6] = np.nan  # an excluded robot's estimates
    x_hat[9, 1, 2] = np.inf
    rows = np.arange(t) * 3
    keep = np.arange(5, t)
    total, count = np.zeros(n), np.zeros(n)
    worst = _estimate_sums(x_hat, x, rows, keep, total, count)
    want = _numpy_estimation_errors(x_hat, x, rows, keep)
    assert np.array_equal(total, want[0]) and np.array_equal(count, want[1])
    assert worst == want[2] == np.inf  # the infinite estimate is the largest, as numpy's
