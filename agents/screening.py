"""Which reporting sensors sense the target, when every sensor reports clutter.

The paper's gating (Sec. IV-C, eqs. (27)-(28)) assumes that a sensor reports only when it
senses the target, so every reporting sensor's summary is a training point. With
``clutter_sensors="all"`` every sensor reports Poisson clutter each step, and a sensor
whose reports are all clutter must neither become an expert nor start a track. Both tests
here compare, per sensor, "it senses the target" with "it reports clutter only" under the
measurement model of Sec. VI-A (known rates, as the hybrid filter assumes): a sensing
sensor reports a zero-truncated Poisson(lambda_T) number of target points N(x, sigma^2 I)
plus Poisson(lambda_c) clutter uniform over its disc of area A_sen; a sensor that does not
sense the target reports the clutter only. The likelihood ratio of a sensor's scan
z_1..z_n for a target at x is then exactly

    LR(x) = e^(-lambda_T) (prod_j (1 + lambda_T N(z_j; x, sigma^2 I) / c) - 1) / (1 - e^(-lambda_T)),

with c = lambda_c / A_sen (eq. (42)'s factors divided by the clutter-only ones, minus the
"no target point" term that the truncation removes). It is 0 for a sensor with no point
near x: a sensor that senses the target always reports it (the detection is certain), which
is what makes a clutter point that other sensors fail to confirm recognisable.

- :func:`sensing_probability` (a track exists): the posterior probability that each
  reporting sensor senses the target, from the prior probability that the predicted
  target lies in its disc and LR integrated over the prediction.
- :func:`initiation_scores` (no track): for each measurement as a candidate position, the
  log-likelihood ratio summed over the other sensors that must sense a target there.
- :func:`scan_log_likelihood_ratios`: log LR of a whole step, every awake sensor at once,
  for a target at each of many positions: the product over the sensors whose disc holds the
  position. A sensor covering the position with no point near it makes it 0; a position in
  no awake disc gives 1 (the silence of :mod:`agents.silence` is the case without points).
- :func:`joint_sensing_probability` and :func:`scan_posterior`: the two uses of it, the
  sensing probabilities under the whole scan (a track exists) and the position's posterior
  from one scan with a uniform prior (no track yet).
- :class:`ClutterScreen`: one episode's use of these, for any tracker that broadcasts a
  prediction (:class:`agents.dgpt.DGPT`, :class:`agents.state_space_dgpt.StateSpaceDGPT`).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import spatial, stats

from agents.gating import group_starts
from dgpt_gym.problem import ProblemSpec

__all__ = [
    "ClutterScreen",
    "MAX_TARGET_SPEED",
    "scan_likelihood_ratio",
    "scan_log_likelihood_ratio",
    "scan_log_likelihood_ratios",
    "area_log_likelihood_ratios",
    "joint_sensing_probability",
    "scan_posterior",
    "sensing_probability",
    "initiation_scores",
    "disc_probability",
    "near_densities",
    "pair_indices",
    "draws_near_candidates",
]

MAX_TARGET_SPEED = 50.0
"""m/s: the farthest a target moves per second, twice every scenario's top speed; a track
starts only from candidates at consecutive steps this close."""


def scan_likelihood_ratio(
    densities: np.ndarray,
    groups: np.ndarray,
    n_groups: int,
    detection_rate: float,
    clutter_density: float,
) -> np.ndarray:
    """LR of the module docstring for ``n_groups`` scans at once.

    Args:
        densities: (m,) target densities N(z_j; x, S) of the measurements that count, m^-2.
        groups: (m,) the scan (0 .. n_groups - 1) of each; scans with none get LR 0.
        detection_rate: lambda_T > 0.
        clutter_density: c = lambda_c / A_sen > 0.
    """
    log_product = _log_products(densities, groups, n_groups, detection_rate, clutter_density)
    # e^-lT (prod - 1) / (1 - e^-lT) with the product in log space: expm1 is exact near 0
    return np.exp(-detection_rate) * np.expm1(log_product) / -np.expm1(-detection_rate)


def _log_products(densities, groups, n_groups, detection_rate, clutter_density) -> np.ndarray:
    """l = sum_j log(1 + lambda_T N_j / c) per scan (n_groups,)."""
    # bincount sums each group in the order of the measurements, as np.add.at does
    return np.bincount(
        groups, weights=np.log1p(detection_rate * densities / clutter_density), minlength=n_groups
    )


def near_densities(
    positions: np.ndarray,
    points: np.ndarray,
    noise_var: float,
    position_tree: spatial.cKDTree | None = None,
):
    """The (position, point) pairs closer than 6 sigma (beyond, N(z; x, sigma^2 I) is below
    2e-8 of its peak): ``(position index (p,), point index (p,), N(z; x, sigma^2 I) (p,))``.
    ``position_tree``: a k-d tree of ``positions`` already built (a caller that queries them
    twice builds it once; the pairs are the same)."""
    if position_tree is None:
        position_tree = spatial.cKDTree(positions)
    near = position_tree.sparse_distance_matrix(
        spatial.cKDTree(points), 6.0 * np.sqrt(noise_var), output_type="ndarray"
    )
    density = np.exp(-0.5 * near["v"] ** 2 / noise_var) / (2.0 * np.pi * noise_var)
    return near["i"].astype(np.int64), near["j"].astype(np.int64), density


def scan_log_likelihood_ratios(
    positions: np.ndarray,
    points: np.ndarray,
    sensors: np.ndarray,
    sensor_positions: np.ndarray,
    sensing_range: float,
    noise_var: float,
    detection_rate: float,
    clutter_density: float,
    awake: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """log LR of a whole step's scans for a target at each of ``positions`` (N, 2) against
    no target: the sum over the awake sensors whose disc holds the position of the log of
    LR(x) (module docstring), with N(z_j; x, sigma^2 I). Sensors that do not cover x report
    clutter only under both hypotheses and cancel.

    Args:
        positions: (N, 2) candidate target positions.
        points: (n, 2) every measurement of the step; ``sensors`` (n,) their sensors.
        sensor_positions: (n_sensors, 2); ``sensing_range``: r.
        noise_var: sigma^2, the measurement noise variance per axis.
        detection_rate, clutter_density: lambda_T and lambda_c / A_sen (> 0).
        awake: optional boolean per sensor; a sleeping sensor's silence says nothing.

    Returns ``(log_ratio (N,), pair_position (p,), pair_sensor (p,))``: -inf where an awake
    sensor covers the position and has no point within 6 sigma of it (its detection is
    certain), 0 where no awake sensor covers it; and the (position, sensor) pairs with the
    position inside the awake sensor's disc.
    """
    n = positions.shape[0]
    sensor_index = np.arange(sensor_positions.shape[0])
    if awake is not None:
        sensor_index = sensor_index[np.asarray(awake, dtype=bool)]
    position_tree = spatial.cKDTree(positions)
    covering = position_tree.sparse_distance_matrix(
        _tree_of(sensor_positions[sensor_index]), sensing_range, output_type="ndarray"
    )
    pair_position = covering["i"].astype(np.int64)
    pair_sensor = sensor_index[covering["j"].astype(np.int64)]
    if not pair_position.size:
        return np.zeros(n), pair_position, pair_sensor
    if points.shape[0]:
        near_position, near_point, densities = near_densities(
            positions, points, noise_var, position_tree
        )
        # a point counts for the pair of its position and its sensor; points of sensors
        # that do not cover the position (or sleep) belong to no pair
        at = pair_indices(
            pair_position,
            pair_sensor,
            near_position,
            sensors[near_point],
            n,
            sensor_positions.shape[0],
        )
        counted = at >= 0
        densities, at = densities[counted], at[counted]
    else:
        densities, at = np.empty(0), np.empty(0, dtype=np.int64)
    # a pair without a point near its position gets l = 0, log LR = -inf: ruled out
    pair_log_ratio = scan_log_likelihood_ratio(
        densities, at, pair_position.size, detection_rate, clutter_density
    )
    return (
        np.bincount(pair_position, weights=pair_log_ratio, minlength=n),
        pair_position,
        pair_sensor,
    )


DENSE_PAIR_TABLE = 1 << 20
"""Largest (positions x covering sensors) table :func:`pair_indices` fills; beyond, it
sorts the pairs instead (same answer, no large allocation)."""


def pair_indices(
    pair_position: np.ndarray,
    pair_sensor: np.ndarray,
    query_position: np.ndarray,
    query_sensor: np.ndarray,
    n_positions: int,
    n_sensors: int,
    max_table_cells: int = DENSE_PAIR_TABLE,
) -> np.ndarray:
    """For each query (position, sensor) (m,) the index of the same pair among the distinct
    pairs ``(pair_position, pair_sensor)`` (p,), or -1 where it is not one of them. Position
    indices are below ``n_positions``, sensor indices below ``n_sensors``.

    A table over the positions and the sensors that occur in a pair when it has at most
    ``max_table_cells`` cells (a step's draws around a prediction meet a few dozen
    sensors); otherwise a binary search among the sorted pair keys."""
    if not pair_position.size:
        return np.full(query_position.size, -1, dtype=np.int64)
    occurs = np.zeros(n_sensors, dtype=bool)
    occurs[pair_sensor] = True
    column = np.cumsum(occurs) - 1
    width = int(column[-1]) + 1
    index = np.full(query_position.size, -1, dtype=np.int64)
    asked = occurs[query_sensor]
    query_key = query_position[asked] * width + column[query_sensor[asked]]
    pair_key = pair_position * width + column[pair_sensor]
    if n_positions * width <= max_table_cells:
        table = np.full(n_positions * width, -1, dtype=np.int64)
        table[pair_key] = np.arange(pair_key.size)
        index[asked] = table[query_key]
        return index
    order = np.argsort(pair_key)
    sorted_key = pair_key[order]
    at = np.minimum(np.searchsorted(sorted_key, query_key), sorted_key.size - 1)
    index[asked] = np.where(sorted_key[at] == query_key, order[at], -1)
    return index


@functools.lru_cache(maxsize=16)
def _tree_of_bytes(data: bytes) -> spatial.cKDTree:
    return spatial.cKDTree(np.frombuffer(data).reshape(-1, 2))


def _tree_of(points: np.ndarray) -> spatial.cKDTree:
    """The k-d tree of (m, 2) ``points``, kept for the next call with equal points: the
    sensors are the same at every step of an episode, and a tree built from equal points is
    the same tree (the same pairs in the same order)."""
    return _tree_of_bytes(np.ascontiguousarray(points, dtype=float).tobytes())


def area_log_likelihood_ratios(
    positions: np.ndarray,
    points: np.ndarray,
    sensors: np.ndarray,
    spec: ProblemSpec,
    noise_var: float,
    awake: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`scan_log_likelihood_ratios` (N,) with the sensors, range and rates of
    ``spec``, and -inf at the positions outside its area (the target is inside it)."""
    log_ratio, _, _ = scan_log_likelihood_ratios(
        positions,
        points,
        sensors,
        np.asarray(spec.sensor_positions),
        spec.sensing_range,
        noise_var,
        spec.detection_rate,
        spec.clutter_density,
        awake,
    )
    inside = np.all((positions >= 0.0) & (positions <= spec.area), axis=1)
    return np.where(inside, log_ratio, -np.inf)


def joint_sensing_probability(
    positions: np.ndarray,
    points: np.ndarray,
    sensors: np.ndarray,
    spec: ProblemSpec,
    noise_var: float,
    awake: np.ndarray | None = None,
) -> np.ndarray | None:
    """Posterior probability that each sensor senses the target, given every scan of the
    step, for a target drawn from the prediction as the sample ``positions`` (N, 2): the
    share of the sample's posterior weight (:func:`scan_log_likelihood_ratios`) inside each
    sensor's disc. Unlike :func:`sensing_probability`, which weighs each sensor's scan alone,
    a point near the prediction counts only as far as the other sensors covering it confirm
    it, and a sensor covering the prediction that reports nothing near it rules that part
    out. Returns (n_sensors,), or None when the scans rule out every position of the sample
    (the prediction cannot explain them: the track is lost)."""
    log_ratio, pair_position, pair_sensor = scan_log_likelihood_ratios(
        positions,
        points,
        sensors,
        spec.sensor_positions,
        spec.sensing_range,
        noise_var,
        spec.detection_rate,
        spec.clutter_density,
        awake,
    )
    if not np.any(np.isfinite(log_ratio)):
        return None
    weights = np.exp(log_ratio - np.max(log_ratio))
    weights /= weights.sum()
    return np.bincount(
        pair_sensor, weights=weights[pair_position], minlength=spec.sensor_positions.shape[0]
    )


def draws_near_candidates(
    candidates: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    noise_var: float,
    n: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` importance draws for a position posterior whose modes sit at ``candidates``
    (m, 2): one third uniform over the box [``low``, ``high``] (2,) each, two thirds
    N(c, ``noise_var`` I) around candidates c drawn uniformly (all uniform when m = 0).
    Returns ``(positions (n, 2), proposal density (n,))``, the density of the mixture the
    draws come from (the Gaussians cut at 6 sigma, :func:`near_densities`)."""
    if n < 3:
        raise ValueError(f"n must be at least 3 (a third of the draws are uniform); got {n}")
    m = candidates.shape[0]
    n_uniform = n if m == 0 else n // 3
    positions = low + rng.random((n, 2)) * (high - low)
    proposal = np.full(n, n_uniform / n / np.prod(high - low))
    if m:
        chosen = rng.integers(0, m, n - n_uniform)
        scatter = rng.standard_normal((n - n_uniform, 2)) * np.sqrt(noise_var)
        positions[n_uniform:] = candidates[chosen] + scatter
        near_position, _, density = near_densities(positions, candidates, noise_var)
        proposal += (
            (n - n_uniform) / n / m * np.bincount(near_position, weights=density, minlength=n)
        )
    return positions, proposal


def scan_posterior(
    points: np.ndarray,
    sensors: np.ndarray,
    spec: ProblemSpec,
    noise_var: float,
    n: int,
    rng: np.random.Generator,
    awake: np.ndarray | None = None,
    with_log_evidence: bool = False,
):
    """The posterior of the target's position from one step's scans and a prior uniform
    over the area, as ``n`` importance-weighted positions: one third drawn uniformly, two
    thirds around the measurements (N(z_j, sigma^2 I), z_j uniform among them), weighted by
    the scans' likelihood ratio (:func:`scan_log_likelihood_ratios`) over the proposal
    density. Returns ``(positions (n, 2), weights (n,) summing to one)``, and with
    ``with_log_evidence`` also the log of the weights' mean before normalising times the
    prior's density: log E[LR] under the uniform prior, the scans' evidence against no
    target. None when the scans rule out every drawn position."""
    area = spec.area
    positions, proposal = draws_near_candidates(
        points, np.zeros(2), np.full(2, area), noise_var, n, rng
    )
    log_weight = area_log_likelihood_ratios(
        positions, points, sensors, spec, noise_var, awake
    ) - np.log(proposal)
    if not np.any(np.isfinite(log_weight)):
        return None
    top = np.max(log_weight)
    weights = np.exp(log_weight - top)
    if with_log_evidence:
        log_evidence = top + np.log(weights.mean()) - 2.0 * np.log(area)
        return positions, weights / weights.sum(), log_evidence
    return positions, weights / weights.sum()


def scan_log_likelihood_ratio(
    densities: np.ndarray,
    groups: np.ndarray,
    n_groups: int,
    detection_rate: float,
    clutter_density: float,
) -> np.ndarray:
    """log of :func:`scan_likelihood_ratio`, computed in log space so that scans with many
    points near x do not overflow: log LR = -lambda_T + l + log(1 - e^(-l)) - log(1 -
    e^(-lambda_T)) with l = sum_j log(1 + lambda_T N_j / c); -inf for scans without a
    point (l = 0)."""
    log_product = _log_products(densities, groups, n_groups, detection_rate, clutter_density)
    with np.errstate(divide="ignore"):
        return (
            -detection_rate
            + log_product
            + np.log(-np.expm1(-log_product))
            - np.log(-np.expm1(-detection_rate))
        )


def disc_probability(
    centres: np.ndarray, radius: float, mean: np.ndarray, variance: float
) -> np.ndarray:
    """P(|x - centre| <= radius) for x ~ N(mean, variance I) (2-D), per centre (k, 2): the
    non-central chi-square distribution with 2 degrees of freedom."""
    variance = max(float(variance), 1e-12)
    distance2 = np.sum((centres - mean) ** 2, axis=1)
    return stats.ncx2.cdf(radius**2 / variance, 2, distance2 / variance)


def sensing_probability(
    points: np.ndarray,
    sensors: np.ndarray,
    sensor_positions: np.ndarray,
    sensing_range: float,
    predicted_mean: np.ndarray,
    target_var: np.ndarray,
    noise_var: np.ndarray,
    detection_rate: float,
    clutter_density: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Posterior probability that each reporting sensor senses the target.

    Args:
        points: (n, 2) measurements; ``sensors`` (n,) their sensors.
        sensor_positions: (n_sensors, 2); ``sensing_range``: r.
        predicted_mean, target_var: (2,) predicted target position and its variance per axis.
        noise_var: (2,) measurement noise variance per axis.
        detection_rate, clutter_density: lambda_T and lambda_c / A_sen (> 0).

    Returns ``(reporting sensors (k,) ascending, probability (k,))``. LR is evaluated with
    N(z_j; mu, P + sigma^2 I) in place of N(z_j; x, sigma^2 I), exact for scans with one
    point near the prediction; the prior is the probability that x ~ N(mu, P) (isotropic
    with P's mean variance) lies in the sensor's disc. No measurements: two empty arrays.
    """
    if not sensors.size:
        return sensors[:0], np.empty(0)
    order = np.argsort(sensors, kind="stable")
    points, sensors = points[order], sensors[order]
    starts = group_starts(sensors)
    reporting = sensors[starts]
    group = np.repeat(np.arange(starts.size), np.diff(np.r_[starts, sensors.size]))
    variance = np.asarray(target_var, dtype=float) + np.asarray(noise_var, dtype=float)
    densities = np.exp(-0.5 * np.sum((points - predicted_mean) ** 2 / variance, axis=1)) / (
        2.0 * np.pi * np.sqrt(np.prod(variance))
    )
    ratio = scan_likelihood_ratio(densities, group, starts.size, detection_rate, clutter_density)
    prior = disc_probability(
        sensor_positions[reporting], sensing_range, predicted_mean, float(np.mean(target_var))
    )
    # posterior odds = prior odds x LR, written to stay finite at prior 1 or LR infinite
    evidence = prior * ratio
    return reporting, np.where(evidence > 0, evidence / (evidence + (1.0 - prior)), 0.0)


def initiation_scores(
    points: np.ndarray,
    sensors: np.ndarray,
    sensor_positions: np.ndarray,
    sensing_range: float,
    noise_var: float,
    detection_rate: float,
    clutter_density: float,
    awake: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Evidence that the target is at each measurement, for starting a track.

    For each measurement c_i, the sensors other than its own whose discs contain every
    point within 3 sqrt(2) sigma of c_i (distance <= r - 3 sqrt(2) sigma; a target there is
    surely sensed by them) are the witnesses; the score is the sum of their log LR(c_i),
    with N(z_j; c_i, 2 sigma^2 I) since c_i is itself a noisy target point. A witness with
    no point near c_i contributes log 0 = -inf. Own sensors are not witnesses (their
    evidence is c_i itself).

    ``awake`` (boolean per sensor, default all): only sensors that could report are
    witnesses (a sleeping sensor's silence says nothing).

    Returns ``(scores (n,), witnesses (n,))``: the score (-inf when any witness disagrees,
    0 with no witness) and the number of witnesses.
    """
    n = points.shape[0]
    if n == 0:
        return np.empty(0), np.empty(0, dtype=int)
    pair_var = 2.0 * noise_var
    reach = 3.0 * np.sqrt(pair_var)
    inner = max(sensing_range - reach, 0.0)
    covering = spatial.cKDTree(points).sparse_distance_matrix(  # witnesses and own sensor
        spatial.cKDTree(sensor_positions), inner, output_type="ndarray"
    )
    witness_point, witness_sensor = covering["i"].astype(np.int64), covering["j"].astype(np.int64)
    keep = witness_sensor != sensors[witness_point]
    if awake is not None:
        keep &= np.asarray(awake, dtype=bool)[witness_sensor]
    witness_point, witness_sensor = witness_point[keep], witness_sensor[keep]
    witnesses = np.bincount(witness_point, minlength=n)
    # the measurements near each candidate, by sensor
    pairs = spatial.cKDTree(points).query_pairs(4.0 * np.sqrt(pair_var), output_type="ndarray")
    first = np.concatenate([pairs[:, 0], pairs[:, 1]])
    second = np.concatenate([pairs[:, 1], pairs[:, 0]])
    n_sensors = sensor_positions.shape[0]
    witness_key = witness_point * n_sensors + witness_sensor
    pair_key = first * n_sensors + sensors[second]
    counted = np.isin(pair_key, witness_key)
    first, second, pair_key = first[counted], second[counted], pair_key[counted]
    distance2 = np.sum((points[first] - points[second]) ** 2, axis=1)
    densities = np.exp(-0.5 * distance2 / pair_var) / (2.0 * np.pi * pair_var)
    keys, group = np.unique(pair_key, return_inverse=True)
    ratio = scan_likelihood_ratio(densities, group, keys.size, detection_rate, clutter_density)
    with np.errstate(divide="ignore"):
        log_ratio = np.log(ratio)
    scores = np.zeros(n)
    np.add.at(scores, keys // n_sensors, log_ratio)
    confirmed = np.bincount(keys // n_sensors, minlength=n)
    scores[confirmed < witnesses] = -np.inf  # a witness with no point near the candidate
    return scores, witnesses


class ClutterScreen:
    """Which of a step's measurements come from sensors that sense the target, with clutter
    at every sensor (``clutter_sensors="all"``), for one episode of a tracker.

    With a track (the tracker's prediction of the position): the reporting sensors whose
    posterior probability of sensing the predicted target is at least
    ``admission_probability`` (:func:`sensing_probability`). When none is (or there is no
    track, or the track is lost because the predicted standard deviation exceeds the sensing
    range, so the prediction no longer says which sensors sense it), a track starts at the
    best candidate whose evidence (:func:`initiation_scores`), plus that of a consistent
    candidate of the last step (closer than :data:`MAX_TARGET_SPEED` allows), beats the
    prior odds that a given pair of measurements of the two steps is the target's,
    1 / (n_t n_(t-1)); the tracker then restarts from the measurements around it. With
    ``start_gate`` = g, a track that holds (not searching) starts anew only at a candidate
    whose squared Mahalanobis distance to the prediction (its variance plus the noise's) is
    at most g (a target in a coverage gap is unseen, not lost); once the prediction's
    standard deviation exceeds the sensing range, or the scans rule out every drawn
    position, the search is open again. Off by default: it ends some false starts in gaps
    but keeps some wrong tracks from being left, and on training seeds no gate changed the
    RMSE beyond its interval (docs/analysis.md, "Clutter at every sensor: where the error
    lies").

    With ``particles`` = N > 0 (the registered state-space trackers) the sensing probabilities
    are those of all scans together (:func:`joint_sensing_probability`, N positions drawn
    from the prediction with ``rng``), and a track whose every drawn position the scans rule
    out is lost at once. Per sensor (N = 0, the class default and DGPT's), a clutter point
    near the prediction admits its sensor even when the other sensors covering it report
    nothing there: on S1-S4 at clutter rate 1 (training seeds 1000-1015, both path modes)
    the joint screen, with the scan posterior as the estimate before a track
    (:func:`scan_posterior`), took the state-space DGPT-RBCM's RMSE from 73.5 to 56.5 m
    (docs/analysis.md, "0.13.0").

    Uses the rates and noise of the spec (as the hybrid filter does): the paper's DGPT has
    no model of sensors that report clutter only.

    Attributes: ``searching`` (no track yet, or the last one was lost), ``candidates``
    (k, 3) the track-start candidates of the last step (x, y, score), ``previous_count``
    the number of measurements at that step.
    """

    def __init__(
        self,
        spec: ProblemSpec,
        admission_probability: float = 0.5,
        particles: int = 0,
        rng: np.random.Generator | None = None,
        start_gate: float | None = None,
    ) -> None:
        if particles and rng is None:
            raise ValueError("rng must be a numpy Generator when particles > 0")
        self.start_gate = start_gate
        self.spec = spec
        self.admission_probability = admission_probability
        self.particles = particles
        self.rng = rng
        self.clutter_density = spec.clutter_density
        self.candidates = np.empty((0, 3))
        self.previous_count = 1
        self.searching = True

    def screen(self, points, sensors, prediction, noise_var, awake=None):
        """The measurements of a step that count.

        Args:
            points: (n, 2) measurements; ``sensors`` (n,) their sensors.
            prediction: ``(mean, var)`` (2,) each, the tracker's prediction of the
                position at this step, or None without one.
            noise_var: (2,) the measurement noise variance per axis.
            awake: optional boolean per sensor, False for sensors that could not report
                (asleep in the RL sensor task).

        Returns ``(keep, started)``: a boolean (n,) over the measurements, and whether a
        track starts from them (the tracker forgets its old one)."""
        spec = self.spec
        if not self.searching and (
            prediction is None or np.sqrt(np.max(prediction[1])) > spec.sensing_range
        ):
            self.searching = True
        if not self.searching and self.particles:
            drawn = prediction[0] + self.rng.standard_normal((self.particles, 2)) * np.sqrt(
                prediction[1]
            )
            probability = joint_sensing_probability(
                drawn, points, sensors, spec, float(np.mean(noise_var)), awake
            )
            if probability is None:
                self.searching = True
            else:
                keep = probability[sensors] >= self.admission_probability
        elif not self.searching:
            reporting, probability = sensing_probability(
                points,
                sensors,
                spec.sensor_positions,
                spec.sensing_range,
                prediction[0],
                prediction[1],
                noise_var,
                spec.detection_rate,
                self.clutter_density,
            )
            keep = np.isin(sensors, reporting[probability >= self.admission_probability])
        if not self.searching and np.any(keep):
            self.candidates = np.empty((0, 3))
            return keep, False
        gate = None
        if not self.searching and self.start_gate is not None:
            gate = (prediction[0], prediction[1] + noise_var)
        start = self._track_start(points, sensors, awake, gate)
        if start is None:
            return np.zeros(points.shape[0], dtype=bool), False
        self.searching = False
        return start, True

    def track_started(self) -> None:
        """A track started elsewhere (the tracker's search, :mod:`agents.search`): stop
        searching and forget the last step's start candidates, as a start here does."""
        self.searching = False
        self.candidates = np.empty((0, 3))

    def _track_start(self, points, sensors, awake, gate=None) -> np.ndarray | None:
        """The measurements (boolean (n,)) around the candidate a track starts from, or
        None; ``candidates`` keeps this step's candidates and their scores for the next.
        ``gate`` = (mean, var) (2,) each: only candidates within ``start_gate`` of it may
        start one (every candidate is kept for the next step's consistency either way)."""
        spec = self.spec
        noise_var = spec.model_noise_std**2
        scores, witnesses = initiation_scores(
            points,
            sensors,
            spec.sensor_positions,
            spec.sensing_range,
            noise_var,
            spec.detection_rate,
            self.clutter_density,
            awake,
        )
        candidate = (witnesses > 0) & (scores > 0)
        previous, previous_count = self.candidates, self.previous_count
        self.candidates = np.column_stack([points[candidate], scores[candidate]])
        self.previous_count = points.shape[0]
        if not np.any(candidate) or not previous.shape[0]:
            return None
        reach = 3.0 * np.sqrt(2.0 * noise_var)
        distance2 = np.sum((points[candidate][:, None] - previous[None, :, :2]) ** 2, axis=2)
        consistent = distance2 <= (MAX_TARGET_SPEED * spec.dt + 2.0 * reach) ** 2
        evidence = scores[candidate] + np.max(
            np.where(consistent, previous[None, :, 2], -np.inf), axis=1
        )
        if gate is not None:
            offset = points[candidate] - gate[0]
            outside = np.sum(offset**2 / gate[1], axis=1) > self.start_gate
            evidence = np.where(outside, -np.inf, evidence)
        best = int(np.argmax(evidence))
        if evidence[best] <= np.log(points.shape[0]) + np.log(previous_count):
            return None
        self.candidates = np.empty((0, 3))
        centre = points[candidate][best]
        return np.sum((points - centre) ** 2, axis=1) <= 18.0 * noise_var  # within 3 sqrt(2) sigma
