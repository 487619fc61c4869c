"""What every RL environment of :mod:`agents.rl` shares: a ``DGPTrack-v0`` inside, a GP
tracker that processes its measurements, and the scoring of the tracker's estimate."""

from __future__ import annotations

import abc

import gymnasium as gym

from dgpt_gym.env import LAYOUT_MODES, DGPTrackEnv
from dgpt_gym.tracker import TrackerBase
from dgpt_gym.validation import check_choice, check_real

__all__ = ["TrackerInsideEnv", "LAYOUTS"]

LAYOUTS = LAYOUT_MODES
"""Where an RL environment's sensor layout comes from: ``"fixed"``, the inner env's
``layout_seed`` in every episode; ``"per_episode"``, the reset seed, so that evaluation
seeds 0-99 meet layouts that training with ``"per_episode"`` (seeds 1000 and up, or the
training environments' 10000 and up) never showed (:data:`dgpt_gym.env.LAYOUT_MODES`)."""


class TrackerInsideEnv(gym.Env, abc.ABC):
    """Base of the RL environments: owns the inner env (``self.inner``, which also draws the
    scene for ``render``), the tracker (``self.tracker``), the measurements of the coming
    step (``self._pending``), the error normalisation (``self.error_scale``) and where each
    episode's sensor layout comes from (``self.layout``, one of :data:`LAYOUTS`)."""

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 10}

    def __init__(
        self,
        tracker: TrackerBase,
        error_scale: float | None,
        env_kwargs: dict,
        layout: str = "fixed",
    ) -> None:
        self.layout = check_choice("layout", layout, LAYOUTS)
        self.inner = DGPTrackEnv(**env_kwargs)  # render_mode goes to it: it draws the scene
        self.render_mode = self.inner.render_mode
        self.tracker = tracker
        self.error_scale = (
            self.inner.sensing_range
            if error_scale is None
            else check_real("error_scale", error_scale, low=0.0, low_inclusive=False)
        )
        self._pending = None

    @abc.abstractmethod
    def fixed_actions(self) -> tuple[dict[str, object], str]:
        """The fixed baselines of this environment: ``{name: action}``, the grid in which the
        best fixed setting is searched (:func:`agents.rl.evaluation.baseline_policies`), and
        the name of the default one. Every RL environment defines its own."""

    def step(self, action):
        """Gymnasium's step: :meth:`begin_step`, the tracker's update, :meth:`end_step`. The
        batched vector environment (:mod:`agents.rl.vector`) runs the same two halves
        around one :meth:`agents.dgpt.DGPT.update_batch` for all its sub-environments."""
        return self.end_step(self.tracker.update(self.begin_step(action)))

    @abc.abstractmethod
    def begin_step(self, action) -> dict:
        """Validate and apply ``action``; return the observation the tracker takes this
        step."""

    @abc.abstractmethod
    def end_step(self, estimate):
        """Score the tracker's ``estimate`` of this step; return Gymnasium's ``(observation,
        reward, terminated, truncated, info)``."""

    def render(self):
        """The inner ``DGPTrack-v0`` scene: sensors, measurements, true path, estimates."""
        return self.inner.render()

    def close(self) -> None:
        self.inner.close()

    def _reset_inner(self, seed: int | None, options: dict | None) -> dict:
        """Reset the inner env (in the reset seed's layout with ``layout="per_episode"``)
        and the tracker; returns the inner reset info."""
        gym.Env.reset(self, seed=seed)
        if self.layout == "per_episode" and (options is None or isinstance(options, dict)):
            # the reset seed, or (autoreset without a seed) a draw of this env's generator
            # above the evaluation seeds, so that evaluation layouts stay unseen; other
            # options (not a dict) go to the inner env, which names what it allows
            layout_seed = (
                int(seed) if seed is not None else int(self.np_random.integers(1000, 2**31))
            )
            options = {"layout_seed": layout_seed, **(options or {})}
        observation, info = self.inner.reset(seed=seed, options=options)
        self.tracker.reset(info["problem_spec"], seed=seed)
        self._pending = observation
        return info

    def _check_started(self) -> None:
        if self._pending is None:
            raise gym.error.ResetNeeded("Cannot call step() before reset() or after the end")

    def _score(self, estimate) -> tuple[dict, bool, bool, dict]:
        """Step the inner env with the tracker's estimate: returns the next step's
        measurements, terminated, truncated and the inner info (with ``error``)."""
        observation, _, terminated, truncated, info = self.inner.step(estimate.mean)
        self._pending = None if truncated else observation
        return observation, terminated, truncated, info
