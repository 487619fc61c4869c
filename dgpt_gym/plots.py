"""Figures of the environment (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dgpt_gym.network import SensorNetwork
from dgpt_gym.scenarios import SCENARIOS

__all__ = ["plot_scenarios"]


def plot_scenarios(path: str | Path, layout_seed: int = 0, n_random: int = 3) -> Path:
    """The paper's Fig. 3: each scenario's reference trajectory over the sensor field, with
    ``n_random`` random draws of the same model in grey. Writes a PNG to ``path``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    network = SensorNetwork.uniform(250, 1000.0, 50.0, layout_seed)
    figure = Figure(figsize=(9, 9), dpi=70)
    FigureCanvasAgg(figure)
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
    figure.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)
    return path
