"""The paper's trackers. :mod:`dgpt_gym.tracker` holds the tracker interface."""
