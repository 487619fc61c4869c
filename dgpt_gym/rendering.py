"""Matplotlib rendering of :class:`~dgpt_gym.env.DGPTrackEnv`: sensors, the ranges of the
sensors that sense the target, the measurements of the current step, the true path so far,
the agent's estimates and, where the agent annotated it
(:meth:`~dgpt_gym.env.DGPTrackEnv.annotate`), the last estimate's 3-sigma ellipse and UCB
box. Axes in metres; the legend sits below the field, where it cannot hide the target."""

from __future__ import annotations

import numpy as np

__all__ = ["Renderer", "ELLIPSE_SIGMAS"]

ELLIPSE_SIGMAS = 3.0
"""Half-axes of the drawn ellipse, in standard deviations per axis."""


class Renderer:
    """Draws frames of one environment; ``render("rgb_array")`` returns an HxWx3 uint8 array."""

    def __init__(self, env, size_inches: float = 6.0, dpi: int = 80) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.env = env
        self.figure = Figure(figsize=(size_inches, size_inches), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.figure)
        self.axes = self.figure.add_axes((0.12, 0.2, 0.84, 0.74))
        self._window = None

    def _draw(self) -> None:
        from matplotlib.collections import PatchCollection
        from matplotlib.patches import Circle, Ellipse, Rectangle

        env, ax = self.env, self.axes
        step = min(env.step_, env.n_steps - 1)
        ax.clear()
        ax.set_xlim(0, env.area)
        ax.set_ylim(0, env.area)
        ax.set_aspect("equal")
        ax.set_title(f"{env.scenario.name}  step {env.step_}/{env.n_steps}", fontsize=9)
        sensors = env.network.positions
        ax.scatter(sensors[:, 0], sensors[:, 1], s=4, c="0.6", marker="^", label="sensor")
        active = env.scans_.detecting[step]
        discs = [Circle(tuple(p), env.sensing_range) for p in sensors[active]]
        ax.add_collection(
            PatchCollection(discs, facecolor="tab:blue", alpha=0.15, edgecolor="tab:blue")
        )
        rows = env.scans_.rows(step) if env.step_ < env.n_steps else slice(0, 0)
        z = env.scans_.measurements[rows]
        ax.scatter(z[:, 0], z[:, 1], s=8, c="tab:red", marker="x", label="measurement")
        path = env.trajectory_.positions[: step + 1]
        ax.plot(path[:, 0], path[:, 1], c="k", lw=1.0, label="true path")
        ax.plot(*path[-1], "o", c="k", ms=4)
        if env.estimates_:
            estimates = np.asarray(env.estimates_)
            ax.plot(estimates[:, 0], estimates[:, 1], c="tab:green", lw=1.0, label="estimate")
            last = env.uncertainties_[-1] if env.uncertainties_ else None
            if last is not None:
                var, ucb = last
                ax.add_patch(
                    Ellipse(
                        tuple(estimates[-1]),
                        *(2.0 * ELLIPSE_SIGMAS * np.sqrt(var)),
                        fill=False,
                        ec="tab:green",
                        lw=1.0,
                        label=f"{ELLIPSE_SIGMAS:g}-sigma ellipse",
                    )
                )
                if ucb is not None and np.all(np.isfinite(ucb)):
                    ax.add_patch(
                        Rectangle(
                            tuple(estimates[-1] - ucb),
                            *(2.0 * ucb),
                            fill=False,
                            ec="tab:purple",
                            ls="--",
                            lw=1.0,
                            label="UCB box",
                        )
                    )
        ax.set_xlabel("x (m)", fontsize=8)
        ax.set_ylabel("y (m)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=3, fontsize=7)

    def render(self, mode: str):
        self._draw()
        self.canvas.draw()
        frame = np.asarray(self.canvas.buffer_rgba())[..., :3].copy()
        if mode == "rgb_array":
            return frame
        import matplotlib.pyplot as plt

        if self._window is None:
            plt.ion()
            figure, axes = plt.subplots()
            axes.set_axis_off()
            self._window = (figure, axes.imshow(frame))
        else:
            self._window[1].set_data(frame)
        plt.pause(1.0 / self.env.metadata["render_fps"])
        return None

    def close(self) -> None:
        if self._window is not None:
            import matplotlib.pyplot as plt

            plt.close(self._window[0])
            self._window = None
