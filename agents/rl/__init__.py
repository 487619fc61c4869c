"""Reinforcement-learning environments over the DGPT tracker (Stable-Baselines3 ready).

| id | class | the agent chooses, each step |
|---|---|---|
| ``DGPTrackWindow-v0`` | :class:`~agents.rl.tuning_envs.DGPTrackWindowEnv` | the sliding-window length C |
| ``DGPTrackGating-v0`` | :class:`~agents.rl.tuning_envs.DGPTrackGatingEnv` | the hard gating threshold |
| ``DGPTrackSensors-v0`` | :class:`~agents.rl.sensors_env.DGPTrackSensorsEnv` | which of the k sensors nearest the prediction to wake (kept to reproduce old results) |
| ``DGPTrackSensors-v1`` | :class:`~agents.rl.sensors_v1.DGPTrackSensorsV1Env` | how many charged sensors nearest the prediction to wake, or all (random paths and layouts, batteries, bounded reward; the SE DGPT-RBCM inside) |
| ``DGPTrackSensors-v2`` | the same class, ``tracker="dgpt-bcm"`` as 0.9.0 built it | the same task with the distributed NCV GP tracker inside, whose predictive standard deviation is calibrated |

They are registered with Gymnasium on ``import dgpt_gym`` as entry-point strings (like the
trackers), so ``dgpt_gym`` imports nothing from ``agents`` and
``gymnasium.make("DGPTrackWindow-v0")`` works after ``import dgpt_gym``. Each also has a
batched vector environment, ``gymnasium.make_vec(id, num_envs,
vectorization_mode="vector_entry_point")`` (:mod:`agents.rl.vector`).
"""
