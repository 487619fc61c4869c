"""Reinforcement-learning environments over the DGPT tracker (Stable-Baselines3 ready).

| id | class | the agent chooses, each step |
|---|---|---|
| ``DGPTrackWindow-v0`` | :class:`~agents.rl.tuning_envs.DGPTrackWindowEnv` | the sliding-window length C |
| ``DGPTrackGating-v0`` | :class:`~agents.rl.tuning_envs.DGPTrackGatingEnv` | the hard gating threshold |
| ``DGPTrackSensors-v0`` | :class:`~agents.rl.sensors_env.DGPTrackSensorsEnv` | which of the k sensors nearest the prediction to wake |

They are registered with Gymnasium on ``import dgpt_gym`` as entry-point strings (like the
trackers), so ``dgpt_gym`` imports nothing from ``agents`` and
``gymnasium.make("DGPTrackWindow-v0")`` works after ``import dgpt_gym``.
"""
