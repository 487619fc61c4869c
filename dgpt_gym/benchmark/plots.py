"""Figures of the environment (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from dgpt_gym.benchmark.metrics import CI_SIGMAS
from dgpt_gym.network import SensorNetwork
from dgpt_gym.scenarios import SCENARIOS

__all__ = [
    "new_figure",
    "save_figure",
    "plot_scenarios",
    "plot_ucb_vs_ci",
    "plot_error_against_time",
    "plot_training_time",
    "read_training_time",
]


def new_figure(size: tuple[float, float], dpi: int = 70):
    """A matplotlib Figure on the Agg canvas (no display, no pyplot state)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=size, dpi=dpi)
    FigureCanvasAgg(figure)
    return figure


def save_figure(figure, path: str | Path) -> Path:
    """Lay out ``figure`` and write it to ``path`` (folders created); returns the path."""
    figure.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    return path


def plot_scenarios(path: str | Path, layout_seed: int = 0, n_random: int = 3) -> Path:
    """The paper's Fig. 3: each scenario's reference trajectory over the sensor field, with
    ``n_random`` random draws of the same model in grey. Writes a PNG to ``path``."""
    network = SensorNetwork.uniform(250, 1000.0, 50.0, layout_seed)
    figure = new_figure((9, 9))
    rng = np.random.default_rng(0)
    for index, (name, scenario) in enumerate(SCENARIOS.items()):
        axes = figure.add_subplot(2, 2, index + 1)
        axes.scatter(*network.positions.T, s=5, c="0.55", marker="^")
        for _ in range(n_random):
            axes.plot(*scenario.sample(rng).positions.T, c="0.75", lw=0.8)
        reference = scenario.reference().positions
        axes.plot(*reference.T, c="tab:red", lw=1.5)
        axes.plot(*reference[0], "o", c="tab:red", ms=5)
        axes.set(
            xlim=(0, 1000),
            ylim=(0, 1000),
            aspect="equal",
            title=f"{name}: {type(scenario).__name__}",
        )
        axes.tick_params(labelsize=7)
    figure.suptitle(
        "Reference trajectories (red, start marked), random draws (grey), sensors (triangles)",
        fontsize=9,
    )
    return save_figure(figure, path)


def plot_ucb_vs_ci(result, path: str | Path, title: str) -> Path:
    """The paper's Figs. 4-7 for one episode (a :class:`dgpt_gym.benchmark.episodes.EpisodeResult`
    of a tracker with a UCB): per axis (rows), the true coordinate, the estimate and the band
    estimate +- UCB half-width (left) or +- 3 sigma (right), with the share of steps whose
    band covers the truth."""
    figure = new_figure((11, 6.5))
    steps = np.arange(result.truth.shape[0])
    bands = [
        ("UCB (Theorem 2)", result.ucb),
        (f"{CI_SIGMAS:g} sigma confidence interval", CI_SIGMAS * np.sqrt(result.var)),
    ]
    for row, axis in enumerate("XY"):
        for column, (name, half_width) in enumerate(bands):
            axes = figure.add_subplot(2, 2, 2 * row + column + 1)
            mean, truth, width = result.mean[:, row], result.truth[:, row], half_width[:, row]
            covered = np.mean(np.abs(mean - truth) <= width)
            axes.fill_between(steps, mean - width, mean + width, color="tab:blue", alpha=0.25)
            axes.plot(steps, truth, c="k", lw=1.2, label="true")
            axes.plot(steps, mean, c="tab:blue", lw=1.0, label="estimate")
            axes.set_title(
                f"{name}, {axis}: covers the truth at {100 * covered:.0f} % of steps", fontsize=9
            )
            axes.set_xlabel("step", fontsize=8)
            axes.set_ylabel(f"{axis} (m)", fontsize=8)
            axes.tick_params(labelsize=7)
            if row == column == 0:
                axes.legend(fontsize=7)
    figure.suptitle(title, fontsize=10)
    return save_figure(figure, path)


def plot_error_against_time(
    curves: dict[str, dict[str, np.ndarray]], path: str | Path, settings: str = ""
) -> Path:
    """2-D error against time step, one panel per scenario: for every tracker the median over
    runs and the band between the 25th and 75th percentiles (``curves``: ``{scenario:
    {tracker: (runs, steps) errors}}``, :func:`dgpt_gym.benchmark.outputs.error_curves`).
    The error axis is logarithmic: gaps cost tens of metres, sensed steps a few."""
    scenarios = list(curves)
    columns = min(2, len(scenarios))
    rows = -(-len(scenarios) // columns)
    figure = new_figure((5.5 * columns, 3.4 * rows))
    colours = {}
    for index, scenario in enumerate(scenarios):
        axes = figure.add_subplot(rows, columns, index + 1)
        for tracker, errors in curves[scenario].items():
            colour = colours.setdefault(tracker, f"C{len(colours)}")
            steps = np.arange(errors.shape[1])
            low, median, high = np.percentile(errors, [25, 50, 75], axis=0)
            axes.fill_between(steps, low, high, color=colour, alpha=0.2, lw=0)
            axes.plot(steps, median, c=colour, lw=1.0, label=f"{tracker} ({errors.shape[0]} runs)")
        axes.set_yscale("log")
        axes.set_title(scenario, fontsize=9)
        axes.set_xlabel("step (s)", fontsize=8)
        axes.set_ylabel("2-D error (m)", fontsize=8)
        axes.tick_params(labelsize=7)
        axes.legend(fontsize=6, loc="upper left")
    title = "Error against time: median and interquartile band over runs"
    figure.suptitle(f"{title}, {settings}" if settings else title, fontsize=10)
    return save_figure(figure, path)


def read_training_time(path: str | Path) -> list[dict]:
    """Rows (N, M, seconds) of the training-time benchmark CSV (``scripts/bench.py``)."""

    with Path(path).open() as handle:
        return [
            {"N": int(row["N"]), "M": int(row["M"]), "seconds": float(row["seconds"])}
            for row in csv.DictReader(handle)
        ]


def plot_training_time(rows: list[dict], path: str | Path) -> Path:
    """The paper's Fig. 2: time of the log likelihood and its gradient against the training
    size N, full GP (M = 1) and DGP with M experts, log-log."""
    figure = new_figure((6, 4), dpi=80)
    axes = figure.add_subplot(1, 1, 1)
    for m in sorted({row["M"] for row in rows}):
        points = [(row["N"], row["seconds"]) for row in rows if row["M"] == m]
        axes.plot(*zip(*points), marker="o", label="full GP" if m == 1 else f"DGP, M = {m}")
    axes.set(
        xscale="log",
        yscale="log",
        xlabel="training data N",
        ylabel="log likelihood + gradient (s)",
        title="Training time (paper Fig. 2): f(x) = 5 x1^2 + sin(12 x2)",
    )
    axes.legend()
    return save_figure(figure, path)
