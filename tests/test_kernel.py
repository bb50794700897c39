"""The compiled team step (numba) and the numpy step are the same algorithm."""

import copy

import numpy as np
import pytest

from dftc_mujoco.onboard import kernel
from tests.test_onboard import _team

pytestmark = pytest.mark.skipif(
    not kernel.AVAILABLE,
    reason="numba is not installed (pip install -e '.[fast]'): only the numpy path exists",
)


@pytest.mark.parametrize(("n", "obstacles"), [(4, True), (4, False), (12, False)])
def test_both_paths_agree_step_by_step(n, obstacles):
    fast, x = _team(n, obstacles=obstacles, command_limit=1.0)
    slow = copy.deepcopy(fast)
    slow.config = type(slow.config)(**{**slow.config.__dict__, "compiled": False})
    slow.compiled = False
    assert fast.compiled
    rng = np.random.default_rng(n)
    v = np.array([0.0, 0.1]) if obstacles else np.array([0.1, 0.0])
    xs = x.copy()
    for k in range(1500):
        t = k * 0.01
        x_m = xs + rng.uniform(-1e-3, 1e-3, xs.shape)
        a = fast.step(t, x_m, v * t, v)
        b = slow.step(t, x_m, v * t, v)
        for name in (
            "u",
            "u_bar",
            "phi_hat",
            "x_hat",
            "x_d",
            "residual",
            "threshold",
            "flag",
            "flagged",
            "reactive",
            "avoiding",
            "active",
        ):
            np.testing.assert_allclose(
                getattr(a, name),
                getattr(b, name),
                rtol=0,
                atol=1e-10,
                err_msg=f"{name} at step {k}",
            )
        assert a.events == b.events
        phi = np.zeros_like(xs)
        if t > 8.0:
            phi[1] = [1.5, 0.0]  # beyond the command range: anti-windup and a detection
        xs = xs + 0.01 * (np.clip(a.u_bar, -1.0, 1.0) + phi)  # actuators saturate at 1 m/s
    for attr in ("y_hat", "int_u_hat", "int_u_own"):
        np.testing.assert_allclose(getattr(fast.state, attr), getattr(slow.state, attr), atol=1e-10)
    np.testing.assert_allclose(fast.estimator.int_e, slow.estimator.int_e, atol=1e-10)
    assert fast.detected == slow.detected and fast.detected  # the fault was caught on both
    assert list(fast.members) == list(slow.members)
