"""The benchmark harness: runs trackers on the environment and reports what they achieve.

- :mod:`~dgpt_gym.benchmark.episodes`: the run loop (one episode, or many in lockstep) and
  per-cell summaries; :mod:`~dgpt_gym.benchmark.metrics`: NRMSE, NEES, coverage, track loss.
- :mod:`~dgpt_gym.benchmark.protocol`: training and evaluation seeds, the paper's tracker sets.
- :mod:`~dgpt_gym.benchmark.sweep`: grids of runs on local processes or a Dask cluster,
  stored as they finish in :mod:`~dgpt_gym.benchmark.store` (SQLite, resumable).
- :mod:`~dgpt_gym.benchmark.windows` (the tuned windows) and
  :mod:`~dgpt_gym.benchmark.tuning` (the searches that produce them and the baselines'
  settings, on training seeds).
- :mod:`~dgpt_gym.benchmark.report`, :mod:`~dgpt_gym.benchmark.baseline_report`,
  :mod:`~dgpt_gym.benchmark.outputs`, :mod:`~dgpt_gym.benchmark.plots`: tables and figures.
- :mod:`~dgpt_gym.benchmark.cli` (``dgpt-evaluate``) and
  :mod:`~dgpt_gym.benchmark.speed` (``dgpt-bench``).
"""
