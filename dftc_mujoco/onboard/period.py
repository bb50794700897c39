"""One control period of the whole team with the paper's blocks, compiled as one call.

This is not a second implementation: it calls, in the order of Fig. 1, the
same compiled functions the blocks call one by one (observer
:func:`~.observer.estimate` / :func:`~.observer.residual` /
:func:`~.observer.update`, controller :func:`~.controller.collective_input` /
:func:`~.controller.own_input`, supervisor :func:`~.supervisor.supervise`,
fault estimator :func:`~.fault_estimator.estimate_faults`, decision
:func:`~.fdir.decide`). Composed in one compiled call, the period costs no
Python overhead per block; :class:`~.team.Team` uses it whenever the team runs
the paper's blocks (any thresholds rule included: ⁱμ_k comes in as an array),
and composes the blocks' Python methods otherwise.
"""

from __future__ import annotations

from numba import njit

from .controller import collective_input, own_input
from .fault_estimator import estimate_faults
from .fdir import decide
from .observer import estimate, residual, update
from .supervisor import supervise

RAISED = 1  # some flag was raised (detection events to report)
SWITCHED = 2  # some robot switched behaviour (reactive events to report)


@njit(cache=True)
def team_period(
    x_m,
    rows,
    c,
    c_dot,
    offsets,
    rates,
    kc,
    ko,
    dt,
    y_hat,
    int_u_hat,
    int_u_own,
    src,
    first_edge,
    in_degree,
    obs,
    safe,
    act,
    theta,
    release,
    active,
    fdir,
    compensate,
    z,
    int_e,
    phi_hat,
    applied,
    K,
    g_inv,
    limit,
    alpha,
    mu,
    above,
    below,
    flag,
    window,
    exclusive,
    x_own,
    x_d,
    xd_dot,
    x_hat,
    u_hat_g,
    u_g,
    u_mem,
    du,
    r,
    r_norm,
    raised,
    u,
    u_bar,
):  # pragma: no cover - compiled
    """One period for the members ``rows`` (team row i is robot ``rows[i]``); returns flags.

    ``x_m``, ``z``, ``int_e``, ``phi_hat``, ``applied``, ``u`` and ``u_bar`` are on
    the original robot axis (N); the others on the members' axis (M). Robots
    that are not members get u = 0 and only run their fault estimator.
    Returns RAISED | SWITCHED bits.
    """
    m = rows.shape[0]
    code = 0
    for i in range(m):
        for d in range(2):
            x_own[i, d] = x_m[rows[i], d]
            x_d[i, d] = c[d] + offsets[i, d]  # J⁻¹σ_d, the mission (eq. 14)
            xd_dot[i, d] = c_dot[d] + rates[i, d]
    estimate(y_hat, int_u_hat, x_hat)  # eq. 21
    collective_input(x_hat, x_d, xd_dot, kc, u_hat_g)  # eq. 15
    own_input(u_hat_g, u_g)  # eq. 16
    if supervise(x_own, u_g, obs, safe, act, theta, release, active, u_mem, du):  # eqs. 8, 18
        code |= SWITCHED
    residual(y_hat, int_u_own, x_own, src, first_edge, in_degree, r, r_norm)  # eq. 35
    update(y_hat, int_u_hat, int_u_own, r, u_hat_g, du, u_mem, ko, dt)  # eqs. 19-21
    if m < u.shape[0]:
        u[:] = 0.0  # an excluded robot is told to stay where it is
    for i in range(m):
        for d in range(2):
            u[rows[i], d] = u_mem[i, d]
    if fdir:
        estimate_faults(x_m, u, z, int_e, phi_hat, applied, K, g_inv, dt, limit, alpha, u_bar)
        if not compensate:
            u_bar[:] = u
        if decide(r_norm, mu, above, below, flag, dt, window, exclusive, raised):  # eq. 39
            code |= RAISED
    else:
        u_bar[:] = u
    return code
