"""The paper's figures (Figs. 3-10) for any run, drawn from ``log.npz`` and ``summary.json``.

Each figure adapts to N and to the run's fault times: the snapshots of Fig. 3
are taken at the paper's fractions of the duration (22.8, 38 and 53.2 s of
60 s), Fig. 4 shows the robots with a bias fault (or, when there is none, the φ̂ of
the robots worth showing), and large teams show the robots worth showing
(``worth_showing``): at most six rows and columns in the residual grid, eight robots'
inputs and fault estimates.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from ..core.events import Kind
from ..core.record import matrix_rows
from ..runtime.atomic import atomic_write

SNAPSHOT_FRACTIONS = (22.8 / 60, 38 / 60, 53.2 / 60)  # paper Fig. 3
MAX_GRID = 6  # rows and columns of the residual grid
MAX_LINES = 8  # robots in the inputs and fault-estimate figures
FIGURES = ("fig3_paths", "fig4_fault_estimate", "fig5_8_residuals", "fig9_errors", "fig10_inputs")


def new_figure(*args, figsize=None, **kwargs):
    """A new Figure and its axes, made without pyplot: no backend is chosen or forced,
    nothing global is kept, and the Figure shows itself in a notebook."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*args, **kwargs)


def _faulty(summary: dict[str, Any]) -> dict[int, list[dict[str, Any]]]:
    out: dict[int, list[dict[str, Any]]] = {}
    for f in summary.get("faults", []):
        out.setdefault(f["robot"] - 1, []).append(f)
    return out


def _healthy_ratio(log: dict[str, np.ndarray], faulty: list[int]) -> np.ndarray:
    """(observer, monitored) largest ‖ⁱr_k‖ / ⁱμ_k over the run, for robots k without a fault
    (0 where there is none, and for the faulty robots' columns)."""
    r, mu = log["residual"], log["threshold"]
    ratio = np.zeros(r.shape[1:])
    with np.errstate(invalid="ignore", divide="ignore"):
        for a in range(0, len(r), 64):  # in chunks: the N x N logs may be large
            q = r[a : a + 64] / mu[a : a + 64]  # NaN for excluded robots, 0 for mu = inf
            np.fmax(ratio, np.nan_to_num(q, nan=0.0, posinf=0.0).max(axis=0), out=ratio)
    ratio[:, faulty] = 0.0
    return ratio


def worth_showing(
    log: dict[str, np.ndarray],
    summary: dict[str, Any],
    limit: int,
    role: str = "observer",
    ratio: np.ndarray | None = None,
) -> list[int]:
    """Up to ``limit`` robots (0-based) worth a figure in a large team, most telling first.

    The faulty robots; then, as observers (``role="observer"``), the first and the last
    robot to flag a faulty one, or, as monitored robots (``role="monitored"``), none; then
    the healthy robots that came closest to a false flag (largest healthy residual /
    threshold); then the rest in order. A team of at most ``limit`` robots is shown whole.
    ``ratio`` is that largest ratio per (observer, monitored) pair when the caller has it
    already (one pass over the N x N logs instead of one per call).
    """
    n = log["x"].shape[1]
    faulty = sorted(_faulty(summary))
    order: list[int] = list(faulty)
    if role == "observer":
        flags = sorted(summary.get("detections", []), key=lambda d: d["t"])
        if flags:
            order += [flags[0]["by"] - 1, flags[-1]["by"] - 1]
    if ratio is None and "residual" in log and "threshold" in log:
        ratio = _healthy_ratio(log, faulty)
    if ratio is not None:
        near = ratio.max(axis=1 if role == "observer" else 0)
        order += [int(i) for i in np.argsort(-near, kind="stable") if near[i] > 0]
    order += range(n)
    picked = list(dict.fromkeys(order))[: min(limit, n)]
    return picked if n > limit else sorted(picked, key=lambda i: (i not in faulty, i))


def _mark_events(ax, summary: dict[str, Any], robot: int | None = None) -> None:
    """Vertical lines at fault instants (grey) and exclusions (black), optionally of one robot."""
    for f in summary.get("faults", []):
        if robot is None or f["robot"] - 1 == robot:
            ax.axvline(f["t"], color="0.6", lw=0.8, ls=":")
    for e in summary.get("exclusions", []):
        if robot is None or e["robot"] - 1 == robot:
            ax.axvline(e["t"], color="k", lw=0.9, ls="--")


def fig_paths(log: dict[str, np.ndarray], summary: dict[str, Any]):
    """Fig. 3: paths, desired centroid path, snapshots, initial and final configurations."""
    t, x = log["t"], log["x"]
    faulty = _faulty(summary)
    fig, ax = new_figure(figsize=(8, 6))
    for ox, oy, r, d in log["obstacles"]:
        ax.add_patch(Circle((ox, oy), r, color="0.55"))
        ax.add_patch(Circle((ox, oy), d, fill=False, ls="--", color="0.55", lw=0.8))
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Paths (paper Fig. 3)")
    if not len(t):  # the run stopped in its first period
        ax.text(0.5, 0.5, "no period was logged", transform=ax.transAxes, ha="center")
        return fig
    ax.plot(log["c_d"][:, 0], log["c_d"][:, 1], "b--", lw=1.2, label="desired centroid")
    for i in range(x.shape[1]):
        colour = "tab:red" if i in faulty else "tab:green"
        ax.plot(
            x[:, i, 0],
            x[:, i, 1],
            ls="--",
            color=colour,
            lw=1.0,
            label=(
                "faulty robots"
                if i == min(faulty, default=-1)
                else "healthy robots"
                if i == min(set(range(x.shape[1])) - set(faulty), default=-1)
                else None
            ),
        )
        ax.annotate(str(i + 1), x[0, i], textcoords="offset points", xytext=(4, 4), fontsize=8)
    duration = t[-1]
    for frac in SNAPSHOT_FRACTIONS:
        k = int(np.searchsorted(t, frac * duration))
        if k >= len(t):
            continue
        act = log["active"][k]
        pts = x[k][act]
        ax.plot(*np.vstack([pts, pts[:1]]).T, "k-", lw=0.8)
        ax.plot(pts[:, 0], pts[:, 1], "ko", mfc="none", ms=8)
        ax.annotate(f"{t[k]:.1f} s", pts.mean(axis=0), fontsize=8, ha="center")
    ax.plot(x[0, :, 0], x[0, :, 1], "kx", ms=7, label="initial")
    ax.plot(x[-1, :, 0], x[-1, :, 1], "kD", ms=5, mfc="none", label="final")
    ax.legend(fontsize=8, loc="best")
    return fig


def fig_fault_estimate(log: dict[str, np.ndarray], summary: dict[str, Any]):
    """Fig. 4: φ and φ̂ of every robot with a bias fault (components x and y)."""
    t = log["t"]
    biased = sorted({f["robot"] - 1 for f in summary.get("faults", []) if f["kind"] == "bias"})
    robots = biased[:MAX_LINES] or worth_showing(log, summary, MAX_LINES)
    fig, axes = new_figure(2, 1, figsize=(8, 5), sharex=True, squeeze=False)
    for c, name in enumerate("xy"):
        ax = axes[c, 0]
        for i in robots:
            ax.plot(t, log["phi_hat"][:, i, c], lw=0.6, label=f"φ̂{i + 1},{name}")
            if biased:
                ax.plot(t, log["phi"][:, i, c], "k--", lw=1.2, label=f"φ{i + 1},{name}")
        ax.set_ylabel(f"{name} [m/s]")
        ax.legend(fontsize=7, loc="upper left", ncol=2)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("t [s]")
    title = (
        "Fault and its estimate (paper Fig. 4)"
        if biased
        else "Fault estimates φ̂ (no bias fault in this run; robots worth showing)"
    )
    axes[0, 0].set_title(title)
    return fig


def fig_residuals(log: dict[str, np.ndarray], summary: dict[str, Any]):
    """Figs. 5-8: ‖ⁱr_k‖ and ⁱμ_k, rows i (observer), columns k (monitored robot)."""
    t, r, mu = log["t"][matrix_rows(log)], log["residual"], log["threshold"]
    ratio = _healthy_ratio(log, sorted(_faulty(summary)))  # once for rows and columns
    cols = worth_showing(log, summary, MAX_GRID, role="monitored", ratio=ratio)
    rows = worth_showing(log, summary, MAX_GRID, role="observer", ratio=ratio)
    fig, axes = new_figure(
        len(rows), len(cols), figsize=(2.6 * len(cols), 1.9 * len(rows)), sharex=True, squeeze=False
    )
    for a, i in enumerate(rows):
        for b, k in enumerate(cols):
            ax = axes[a, b]
            ax.semilogy(t, r[:, i, k], "b-", lw=0.7)
            ax.semilogy(t, mu[:, i, k], "g--", lw=0.9)
            m = mu[:, i, k]
            m = m[np.isfinite(m) & (m > 0)]
            if m.size:  # a residual that starts at 0 would stretch the axis to 1e-40
                ax.set_ylim(bottom=max(ax.get_ylim()[0], float(m.min()) * 1e-3))
            _mark_events(ax, summary, robot=k)
            for d in summary.get("detections", []):
                if d["by"] - 1 == i and d["robot"] - 1 == k:
                    ax.axvline(d["t"], color="r", lw=1.0)
            if a == 0:
                ax.set_title(f"k = {k + 1}", fontsize=9)
            if b == 0:
                ax.set_ylabel(f"i = {i + 1}", fontsize=9)
            ax.tick_params(labelsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]", fontsize=8)
    fig.suptitle(
        "‖ⁱr_k‖ (blue) and ⁱμ_k (green dashed); detection (red), fault (grey), "
        "exclusion (black) — paper Figs. 5-8",
        fontsize=9,
    )
    fig.tight_layout()
    return fig


def estimation_error(log: dict[str, np.ndarray]) -> np.ndarray:
    """‖x̃*‖ over the robots in the team at each N × N sample (paper Fig. 9, top)."""
    rows = matrix_rows(log)
    err = log["x_hat"] - log["x"][rows][:, None, :, :]
    act = log["active"][rows]
    mask = act[:, :, None] & act[:, None, :]
    sq = np.where(mask, (err**2).sum(axis=-1), 0.0)
    return np.sqrt(sq.sum(axis=(1, 2)))


def fig_errors(log: dict[str, np.ndarray], summary: dict[str, Any]):
    """Fig. 9: ‖x̃*‖ (top) and the task errors ‖σ̃₁‖, ‖σ̃₂‖ (bottom)."""
    t = log["t"]
    fig, (top, bottom) = new_figure(2, 1, figsize=(8, 5), sharex=True)
    top.semilogy(t[matrix_rows(log)], estimation_error(log), "b-", lw=0.8)
    top.set_ylabel("‖x̃*‖ [m]")
    top.set_title("Estimation and task errors (paper Fig. 9)")
    bottom.semilogy(t, log["sigma_err"][:, 0], lw=0.8, label="‖σ̃₁‖ centroid")
    bottom.semilogy(t, log["sigma_err"][:, 1], lw=0.8, label="‖σ̃₂‖ formation")
    bottom.set_ylabel("[m]")
    bottom.set_xlabel("t [s]")
    bottom.legend(fontsize=8)
    for ax in (top, bottom):
        _mark_events(ax, summary)
        for sp in summary.get("reactive", []):
            ax.axvspan(
                sp["t_on"],
                sp["t_off"] if sp["t_off"] is not None else t[-1],
                color="tab:green",
                alpha=0.08,
            )
        ax.grid(alpha=0.3)
    return fig


def fig_inputs(log: dict[str, np.ndarray], summary: dict[str, Any]):
    """Fig. 10: each robot's nominal input uᵢ (x and y)."""
    t, u = log["t"], log["u"]
    robots = worth_showing(log, summary, MAX_LINES)
    n = len(robots)
    fig, axes = new_figure(n, 1, figsize=(8, 1.4 * n + 0.8), sharex=True, squeeze=False)
    for a, i in enumerate(robots):
        ax = axes[a, 0]
        ax.plot(t, u[:, i, 0], lw=0.7, label="x")
        ax.plot(t, u[:, i, 1], lw=0.7, label="y")
        _mark_events(ax, summary)
        ax.set_ylabel(f"u{i + 1} [m/s]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[0, 0].set_title("Control inputs (paper Fig. 10)")
    axes[-1, 0].set_xlabel("t [s]")
    return fig


def fig_network(log: dict[str, np.ndarray], summary: dict[str, Any]):
    """The communication timeline of a run over a network: the age of the message each link
    holds (above; the two dashed levels: no loss, and a whole round, beyond which the
    premise 'network' breaks) and the messages lost per second (below)."""
    t, age = log["t"], np.asarray(log["link_age"], float) * 1000.0
    links = log["links"]
    fresh, whole = (1000.0 * float(b) for b in log["link_bounds"])
    fig, (a0, a1) = new_figure(2, 1, figsize=(8.5, 5.5), sharex=True)
    show = min(len(links), 24)  # the links whose ages were the largest
    order = np.argsort(-np.nanmax(np.where(np.isfinite(age), age, -1.0), axis=0))[:show]
    img = a0.imshow(
        age[:, order].T,
        aspect="auto",
        origin="lower",
        extent=(float(t[0]), float(t[-1]), -0.5, show - 0.5),
        cmap="viridis",
        vmin=0.0,
        vmax=max(whole * 1.5, 1.0),
        interpolation="nearest",
    )
    a0.set_yticks(range(show))
    a0.set_yticklabels([f"{a}→{b}" for a, b in links[order]], fontsize=6)
    a0.set_ylabel("link (from → to)")
    a0.set_title(f"Age of the message each link holds [ms] (no loss ≤ {fresh:g}, round {whole:g})")
    fig.colorbar(img, ax=(a0, a1), label="message age [ms]", fraction=0.04, pad=0.02)
    lost = np.asarray(log["link_lost"], float)
    if len(t) > 1:  # messages lost over the last second, per link
        back = np.searchsorted(t, t - 1.0)
        span = np.maximum(t - t[back], 1e-9)[:, None]
        per_s = (lost - lost[back]) / span
        a1.plot(t[1:], per_s[1:].mean(axis=1), lw=1, label="mean over links")
        a1.plot(t[1:], per_s[1:].max(axis=1), lw=0.8, alpha=0.7, label="worst link")
    a1.axhline(0.0, color="k", lw=0.5)
    for e in summary.get("events", []):
        if e["kind"] in (Kind.RADIO_FAULT, Kind.ROBOT_SILENT):
            for ax in (a0, a1):
                ax.axvline(e["t"], color="r", lw=0.8, ls=":")
    a1.set_ylabel("lost per second (1 s window)")
    a1.set_xlabel("t [s]")
    a1.legend(fontsize=7)
    a1.grid(alpha=0.3)
    return fig


def figures_of(log: dict[str, np.ndarray]) -> tuple[str, ...]:
    """The figures a run has: the paper's, and the communication timeline over a network."""
    return (*FIGURES, "network") if "link_age" in log else FIGURES


DRAW = {
    "network": fig_network,
    "fig3_paths": fig_paths,
    "fig4_fault_estimate": fig_fault_estimate,
    "fig5_8_residuals": fig_residuals,
    "fig9_errors": fig_errors,
    "fig10_inputs": fig_inputs,
}


def make_all(log: dict[str, np.ndarray], summary: dict[str, Any]) -> dict[str, Figure]:
    """Every figure of a run as a matplotlib Figure, by name (nothing is written or shown)."""
    return {name: DRAW[name](log, summary) for name in figures_of(log)}


def draw_all(log: dict[str, np.ndarray], summary: dict[str, Any], folder: Path) -> list[Path]:
    """Draw every figure as a PNG in ``folder`` (each written atomically); returns the paths."""
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name in figures_of(log):
        fig = DRAW[name](log, summary)
        path = folder / f"{name}.png"
        atomic_write(path, partial(fig.savefig, dpi=110, format="png"))
        written.append(path)
    return written
