"""The paper's trackers. :mod:`agents.base` holds the tracker interface."""
