"""The whole team's control period as one compiled kernel (numba), when numba is installed.

At N = 4 a control period is ~80 small numpy calls whose overhead, not their
arithmetic, dominates: compiled, the onboard step goes from ~62 µs to ~2 µs
(``benchmarks/bench_compiled.py``). This kernel computes exactly what
:meth:`dftc_mujoco.onboard.team.Team.step` computes while every robot is in
the team (observer eqs. 19-21 and 35, controller 15-16, supervisor 18, fault
estimator 28-31 with anti-windup, decision window), in place, from the same
data: robot i's row reads only its own measurement and the messages on the
edges into it. ``tests/test_kernel.py`` checks both paths agree to 1e-12.
Without numba (``pip install -e ".[fast]"``) :data:`AVAILABLE` is False and
the numpy path runs.
"""

from __future__ import annotations

import numpy as np

try:
    import numba
except ImportError:  # the numpy path runs instead
    numba = None

AVAILABLE = numba is not None

if AVAILABLE:

    @numba.njit(cache=True)
    def team_step(
        t,
        x_m,
        c,
        c_dot,
        offsets,
        rates,
        rows,
        others,
        y_hat,
        int_u_hat,
        int_u_own,
        src,
        starts,
        indeg,
        kc,
        ko,
        dt,
        obs,
        safe,
        act,
        theta,
        release,
        active,
        z,
        int_e,
        phi_hat,
        K,
        g_inv,
        limit,
        above,
        below,
        flag,
        mu,
        window,
        u_out,
        ubar_out,
        rnorm_out,
    ):
        """One period for the team members ``rows`` (team row i is robot rows[i]).

        The robots in ``others`` (excluded) only run their fault estimator, with u = 0.
        x_m, z, int_e, phi_hat, u_out and ubar_out are on the robot axis (N); the other
        arrays on the team axis (M). Updates the state in place.
        """
        n = rows.shape[0]
        for j in range(others.shape[0]):
            u_out[others[j], 0] = 0.0
            u_out[others[j], 1] = 0.0
        # controller (eq. 15) on x_hat = y_hat + int_u_hat; own input (eq. 16)
        u_g = np.empty((n, 2))
        for i in range(n):
            for d in range(2):
                xd = c[d] + offsets[i, d]
                u_g[i, d] = (
                    c_dot[d] + rates[i, d] + kc * (xd - (y_hat[i, i, d] + int_u_hat[i, i, d]))
                )
        # supervisor (eq. 18): robot i's own measurement and what its sensors see
        du = np.zeros((n, 2))
        for i in range(n):
            best = -1
            best_m = 1e300
            r0 = 0.0
            r1 = 0.0
            bar = 0.0
            rad = 0.0
            for o in range(obs.shape[0]):
                e0 = x_m[rows[i], 0] - obs[o, 0]
                e1 = x_m[rows[i], 1] - obs[o, 1]
                dist = np.sqrt(e0 * e0 + e1 * e1)
                if dist >= act[o]:
                    continue
                h0 = e0 / max(dist, 1e-9)
                h1 = e1 / max(dist, 1e-9)
                radial = h0 * u_g[i, 0] + h1 * u_g[i, 1]
                barrier = theta * (safe[o] - dist)
                rel = release if active[i] == o else 0.0
                if radial < barrier + rel and dist - safe[o] < best_m:
                    best, best_m, r0, r1, bar, rad = o, dist - safe[o], h0, h1, barrier, radial
            active[i] = best
            if best >= 0:
                du[i, 0] = (bar - rad) * r0
                du[i, 1] = (bar - rad) * r1
        for i in range(n):
            u_out[rows[i], 0] = u_g[i, 0] + du[i, 0]
            u_out[rows[i], 1] = u_g[i, 1] + du[i, 1]
        # residual (eq. 35) from the messages on the edges into i; then eqs. 19-21
        r = np.empty((n, n, 2))
        for i in range(n):
            for k in range(n):
                for d in range(2):
                    acc = -indeg[i] * y_hat[i, k, d]
                    for e in range(starts[i], starts[i + 1]):
                        acc += y_hat[src[e], k, d]
                    r[i, k, d] = acc
            for d in range(2):
                r[i, i, d] += x_m[rows[i], d] - int_u_own[i, d] - y_hat[i, i, d]
        for i in range(n):
            for k in range(n):
                rnorm_out[i, k] = np.sqrt(r[i, k, 0] ** 2 + r[i, k, 1] ** 2)
                for d in range(2):
                    xd = c[d] + offsets[k, d]
                    uhat = (
                        c_dot[d] + rates[k, d] + kc * (xd - (y_hat[i, k, d] + int_u_hat[i, k, d]))
                    )
                    int_u_hat[i, k, d] += dt * uhat
            for d in range(2):
                int_u_hat[i, i, d] += dt * du[i, d]
                int_u_own[i, d] += dt * u_out[rows[i], d]
        for i in range(n):
            for k in range(n):
                for d in range(2):
                    y_hat[i, k, d] += ko * dt * r[i, k, d]
        # fault estimator (eqs. 28-31) with anti-windup, on the nominal input, every robot
        for i in range(x_m.shape[0]):
            e0 = x_m[i, 0] - z[i, 0]
            e1 = x_m[i, 1] - z[i, 1]
            k0 = K[0, 0] * int_e[i, 0] + K[0, 1] * int_e[i, 1]
            k1 = K[1, 0] * int_e[i, 0] + K[1, 1] * int_e[i, 1]
            p0 = g_inv[0, 0] * (e0 + k0) + g_inv[0, 1] * (e1 + k1)
            p1 = g_inv[1, 0] * (e0 + k0) + g_inv[1, 1] * (e1 + k1)
            phi_hat[i, 0] = p0
            phi_hat[i, 1] = p1
            s0, s1 = dt * e0, dt * e1
            v0 = u_out[i, 0] - p0
            v1 = u_out[i, 1] - p1
            if max(abs(v0), abs(v1)) > limit - 0.05:
                now = max(abs(v0) - limit, 0.0) + max(abs(v1) - limit, 0.0)
                a0 = K[0, 0] * (int_e[i, 0] + s0) + K[0, 1] * (int_e[i, 1] + s1)
                a1 = K[1, 0] * (int_e[i, 0] + s0) + K[1, 1] * (int_e[i, 1] + s1)
                q0 = g_inv[0, 0] * (e0 + a0) + g_inv[0, 1] * (e1 + a1)
                q1 = g_inv[1, 0] * (e0 + a0) + g_inv[1, 1] * (e1 + a1)
                nxt = max(abs(u_out[i, 0] - q0) - limit, 0.0) + max(
                    abs(u_out[i, 1] - q1) - limit, 0.0
                )
                if nxt > now and nxt > 0:
                    s0 = 0.0
                    s1 = 0.0
            int_e[i, 0] += s0
            int_e[i, 1] += s1
            ubar_out[i, 0] = v0
            ubar_out[i, 1] = v1
            z[i, 0] += dt * (u_out[i, 0] + K[0, 0] * e0 + K[0, 1] * e1)
            z[i, 1] += dt * (u_out[i, 1] + K[1, 0] * e0 + K[1, 1] * e1)
        # decision window (Remark 5.2)
        raised = 0
        for i in range(n):
            for k in range(n):
                if rnorm_out[i, k] > mu[i, k]:
                    above[i, k] += dt
                    below[i, k] = 0.0
                    if not flag[i, k] and above[i, k] >= window - 1e-9:
                        flag[i, k] = True
                        raised += 1
                else:
                    above[i, k] = 0.0
                    below[i, k] += dt
                    if flag[i, k] and below[i, k] >= window - 1e-9:
                        flag[i, k] = False
        return raised

else:  # pragma: no cover - exercised where numba is missing

    def team_step(*args):
        raise RuntimeError("numba is not installed")
