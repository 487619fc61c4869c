"""A tracker that fails on one seed, for the evaluation sweep's failure handling."""

from baselines.centroid import GatedCentroidTracker

FAILING_SEED = 1


class FlakyTracker(GatedCentroidTracker):
    """The reference tracker, except that ``reset`` raises on seed :data:`FAILING_SEED`."""

    def reset(self, spec, seed=None):
        if seed == FAILING_SEED:
            raise FloatingPointError(f"diverged on seed {seed}")
        super().reset(spec, seed)
