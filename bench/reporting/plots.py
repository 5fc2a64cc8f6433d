"""Plots written next to the tables: convergence per (system, experiment)
and residual-versus-state.

Convergence: the best-so-far training MSE against wall-clock time on log-log
axes, one colour per method; each seed a faint line, the median over seeds a
solid line inside its interquartile band. A seed's curve is a step function
(the best MSE seen up to that time), read on a common grid of 200
log-spaced times; before its first point a seed has no value and is left out
of the median.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from bench.core.fileio import atomic_write


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_name(system: str, experiment: str, noise: float = 0.0) -> str:
    return f"convergence_{system}_{experiment}" + (f"_noise{noise:g}" if noise else "") + ".png"


def step_values(curve: list, grid, tolerance: float = 0.0) -> np.ndarray:
    """The step function of a ``[(seconds, value), ...]`` curve (times
    increasing) on ``grid``: the last value reached by each time, counting
    points up to ``tolerance`` seconds late; NaN before the curve's start."""
    grid = np.asarray(grid, dtype=np.float64)
    if not curve:
        return np.full(grid.shape, np.nan)
    t, y = np.asarray(curve, dtype=np.float64).T
    idx = np.searchsorted(t, grid + tolerance, side="right") - 1
    return np.where(idx >= 0, y[np.clip(idx, 0, None)], np.nan)


def best_so_far(curve: list, grid: np.ndarray) -> np.ndarray:
    """The best value so far of a ``[(seconds, mse), ...]`` curve on ``grid`` (NaN before its start)."""
    if not curve:
        return np.full(np.shape(grid), np.nan)
    t, y = np.asarray(curve, dtype=np.float64).T
    return step_values(np.column_stack([t, np.minimum.accumulate(y)]).tolist(), grid)


def _save_lines(plt, fig, ax, path: Path) -> Path:
    """Grid and legend of a one-axes line plot, then write it atomically as PNG and close it."""
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format="png"), binary=True)
    plt.close(fig)
    return path


def convergence_plot(records: list, path: Path, title: str) -> Path | None:
    """One convergence figure for the ``ok`` records
    (:class:`~bench.runner.records.Record`) of one (system, experiment);
    ``None`` when no record has a curve."""
    by_method = defaultdict(list)
    for r in records:
        if r.status == "ok" and r.curve:
            by_method[r.method].append([p for p in r.curve if p[0] > 0 and p[1] > 0])
    by_method = {m: [c for c in curves if c] for m, curves in by_method.items()}
    by_method = {m: c for m, c in by_method.items() if c}
    if not by_method:
        return None
    times = [p[0] for curves in by_method.values() for c in curves for p in c]
    grid = np.geomspace(min(times), max(times), 200)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=110)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (method, curves) in enumerate(sorted(by_method.items())):
        colour = colours[i % len(colours)]
        steps = np.stack([best_so_far(c, grid) for c in curves])
        for c in curves:
            t, y = np.asarray(c).T
            ax.step(t, np.minimum.accumulate(y), where="post", color=colour, alpha=0.15, linewidth=0.7)
        enough = np.sum(np.isfinite(steps), axis=0) >= max(1, (len(curves) + 1) // 2)
        with np.errstate(all="ignore"):
            q25, q50, q75 = (np.nanpercentile(steps[:, enough], p, axis=0) for p in (25, 50, 75))
        ax.fill_between(grid[enough], q25, q75, color=colour, alpha=0.25, linewidth=0)
        ax.plot(grid[enough], q50, color=colour, linewidth=1.8, label=f"{method} ({len(curves)} seeds)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall-clock time (s)")
    ax.set_ylabel("best training MSE so far")
    ax.set_title(title, fontsize=10)
    return _save_lines(plt, fig, ax, path)


def residual_plot(data, residual: np.ndarray, path: Path, title: str = "", after: np.ndarray | None = None) -> Path:
    """Torque residual of each joint against q, qd and qdd of that joint
    (rows: joints; columns: q, qd, qdd). ``after``, if given, is drawn over it
    in a second colour (the residual after a correction)."""
    plt = _pyplot()
    dof = data.dof
    fig, axes = plt.subplots(dof, 3, figsize=(9, 2.4 * dof), dpi=100, squeeze=False)
    n = len(data)
    pick = np.random.default_rng(0).choice(n, size=min(n, 4000), replace=False)
    for j in range(dof):
        for k, (name, values) in enumerate((("q", data.q), ("qd", data.qd), ("qdd", data.qdd))):
            ax = axes[j, k]
            ax.scatter(values[pick, j], residual[pick, j], s=2, alpha=0.35, label="before" if after is not None else None)
            if after is not None:
                ax.scatter(values[pick, j], after[pick, j], s=2, alpha=0.35, label="after")
            ax.axhline(0.0, color="black", linewidth=0.6)
            ax.set_xlabel(f"{name}_{j + 1}", fontsize=8)
            if k == 0:
                ax.set_ylabel(f"residual τ_{j + 1}", fontsize=8)
            ax.tick_params(labelsize=7)
    if after is not None:
        axes[0, 0].legend(fontsize=7, markerscale=4)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format="png"), binary=True)
    plt.close(fig)
    return path


def adaptation_plot(results: list[dict], checkpoints, path: Path, title: str = "") -> Path:
    """Test MSE against fitting time after a switch in the system
    (:mod:`bench.studies.adaptation`): one colour per learner, each seed a faint step
    line, the median over seeds at the checkpoints a solid line inside its
    interquartile band. The time axis is symmetric-log, so that t = 0 (the
    model at the switch) is drawn. Errors more than 1e4 times below the
    smallest median at the switch (round-off) are drawn at that floor, which
    the legend says, so that they do not flatten the other curves."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=110)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    learners = list(dict.fromkeys(r["learner"] for r in results))
    grid = np.asarray(checkpoints, dtype=np.float64)
    floor = 1e-4 * min(np.median([r["curve"][0][1] for r in results if r["learner"] == lr]) for lr in learners)
    for i, learner in enumerate(learners):
        colour = colours[i % len(colours)]
        curves = [r["curve"] for r in results if r["learner"] == learner]
        clipped = any(p[1] < floor for c in curves for p in c)
        curves = [[[t, max(y, floor)] for t, y in c] for c in curves]
        if clipped:
            learner = f"{learner}, at the floor: below {floor:.0e}"
        for c in curves:
            t, y = np.asarray(c, dtype=np.float64).T
            ax.step(np.append(t, grid[-1]), np.append(y, y[-1]), where="post", color=colour, alpha=0.2, linewidth=0.7)
        values = np.array([step_values(c, grid, 1e-9) for c in curves])
        q25, q50, q75 = (np.percentile(values, p, axis=0) for p in (25, 50, 75))
        ax.fill_between(grid, q25, q75, color=colour, alpha=0.2, linewidth=0, step="post")
        ax.step(grid, q50, where="post", color=colour, linewidth=1.8, label=f"{learner} ({len(curves)} seeds)")
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_yscale("log")
    ax.set_xlim(0, grid[-1])
    ax.set_xlabel("fitting time after the switch (s)")
    ax.set_ylabel("test torque MSE")
    if title:
        ax.set_title(title, fontsize=9)
    return _save_lines(plt, fig, ax, path)


def line_plot(series: dict[str, list[tuple[float, float]]], path: Path, *, xlabel: str, ylabel: str, title: str = "",
              markers: dict[str, tuple[float, float]] | None = None) -> Path:
    """One line per label through its ``(x, y)`` points, on log–log axes;
    ``markers`` add one diamond per label in the same colour (a point off the line).

    A log axis has no place for zero: points with ``y <= 0`` are left out
    (a line breaks there), and the x axis is labelled at the data's own x."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=110)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    if len(series) > len(colours):  # no two lines in one colour
        colours = [plt.get_cmap("tab20")(k) for k in range(20)]
    xs = set()
    for i, (label, points) in enumerate(sorted(series.items())):
        colour = colours[i % len(colours)]
        x, y = np.asarray(sorted(points), dtype=np.float64).T
        xs.update(x)
        ax.plot(x, np.where(y > 0, y, np.nan), "o-", color=colour, linewidth=1.5, markersize=3.5, label=label)
        if markers and label in markers and markers[label][1] > 0:
            ax.plot(*markers[label], "D", color=colour, markersize=6, markeredgecolor="black", markeredgewidth=0.6)
            xs.add(markers[label][0])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ticks = []
    for t in sorted(xs):  # a tick too close to the one before it would print over it
        if not ticks or t > ticks[-1] * 1.06:
            ticks.append(t)
    ax.set_xticks(ticks, [f"{t:.3g}" for t in ticks])
    ax.xaxis.set_minor_locator(plt.NullLocator())
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title, fontsize=10)
    return _save_lines(plt, fig, ax, path)
