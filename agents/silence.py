"""The silence of the sensors in a coverage gap, for the NCV GP in state-space form.

With clutter at the detecting sensors only (the paper's model), a sensor that senses the
target always reports (a zero-truncated Poisson number of target points, Sec. VI-A). A step
on which no awake sensor reports therefore says that the target lies in no awake sensor's
sensing disc, and inside the surveillance area. That likelihood is an indicator, so the
posterior in a gap is the prediction cut to the uncovered region: not Gaussian, often not
even connected, and cut again at every step of the gap. A Gaussian moment-matched at every
step compounds the cuts through the position-velocity correlation (on training seeds a
straight 9-step gap drifted 190 m), so the gap is filtered by particles drawn from the
state at its first step and collapsed back to a Gaussian at the next step with data.

Pure functions on particle arrays: states (N, 2 axes, 2) = [position, velocity] per axis,
weights (N,) summing to one; resampling and the kernel bandwidth are
:mod:`agents.particles`'.
"""

from __future__ import annotations

import numpy as np
from scipy import spatial, special

__all__ = [
    "draw_particles",
    "propagate_particles",
    "silent_region",
    "reporting_and_silent",
    "reporting_region",
    "region_cells",
    "region_truncation",
    "REGION_QUADRATURE",
    "particle_moments",
]


def draw_particles(mean: np.ndarray, cov: np.ndarray, n: int, rng: np.random.Generator):
    """``n`` states drawn from N(``mean``, ``cov``) per axis ((2, 2), (2, 2, 2)): (n, 2, 2)."""
    root = np.linalg.cholesky(cov + 1e-9 * np.eye(2))
    return mean + np.einsum("aij,naj->nai", root, rng.standard_normal((n, 2, 2)))


def propagate_particles(
    states: np.ndarray,
    dt: float,
    q: np.ndarray,
    manoeuvre_intensity: float,
    manoeuvre_probability: float,
    rng: np.random.Generator,
    turn_rates: np.ndarray | None = None,
    turn_intensity: float = 0.0,
) -> np.ndarray:
    """Each state carried ``dt`` seconds under the NCV model (:func:`agents.state_space.ncv_predict`'s
    F and Q) with white-acceleration intensity ``q`` (2,) per axis, plus
    ``manoeuvre_intensity`` on both axes with probability ``manoeuvre_probability``, drawn
    per particle (the two-component process noise of :class:`agents.state_space.Manoeuvre`).
    A particle whose ``turn_rates`` entry (N,) is not 0 turns instead: its velocity rotates
    by omega dt and its position moves along the arc (:func:`baselines.cpf.turn_transition`),
    with white-acceleration intensity ``turn_intensity`` on each axis and no manoeuvre
    component (the turn modes of :class:`agents.state_space_dgpt.StateSpaceDGPT`)."""
    n = states.shape[0]
    manoeuvring = rng.random((n, 1)) < manoeuvre_probability
    intensity = np.asarray(q, dtype=float)[None, :] + manoeuvring * manoeuvre_intensity
    turning = None
    if turn_rates is not None:
        turning = np.asarray(turn_rates, dtype=float) != 0.0
        intensity = np.where(turning[:, None], turn_intensity, intensity)
    a, b, d = intensity * dt**3 / 3.0, intensity * dt**2 / 2.0, intensity * dt
    # Cholesky factor of [[a, b], [b, d]] in closed form (a > 0 when dt > 0 and q > 0)
    l11 = np.sqrt(a)
    l21 = np.where(l11 > 0, b / np.where(l11 > 0, l11, 1.0), 0.0)
    l22 = np.sqrt(np.maximum(d - l21**2, 0.0))
    noise = rng.standard_normal((n, 2, 2))
    moved = np.empty_like(states)
    moved[..., 0] = states[..., 0] + dt * states[..., 1] + l11 * noise[..., 0]
    moved[..., 1] = states[..., 1] + l21 * noise[..., 0] + l22 * noise[..., 1]
    if turning is not None and turning.any():
        omega = np.asarray(turn_rates, dtype=float)[turning]
        velocity = states[turning, :, 1]  # (k, 2 axes)
        sine, cosine = np.sin(omega * dt), np.cos(omega * dt)
        along, across = sine / omega, (1.0 - cosine) / omega
        vx, vy = velocity[:, 0], velocity[:, 1]
        shift = np.column_stack([along * vx - across * vy, across * vx + along * vy])
        rotated = np.column_stack([cosine * vx - sine * vy, sine * vx + cosine * vy])
        moved[turning, :, 0] = states[turning, :, 0] + shift + l11[turning] * noise[turning, :, 0]
        moved[turning, :, 1] = (
            rotated + l21[turning] * noise[turning, :, 0] + l22[turning] * noise[turning, :, 1]
        )
    return moved


def silent_region(
    positions: np.ndarray, sensor_positions: np.ndarray, sensing_range: float, area: float
) -> np.ndarray:
    """(N,) True where a position (N, 2) lies inside the square area [0, ``area``]^2 and
    farther than ``sensing_range`` from every sensor of ``sensor_positions`` (k, 2): where a
    target can be when none of these sensors reports."""
    inside = np.all((positions >= 0.0) & (positions <= area), axis=1)
    if len(sensor_positions) == 0:
        return inside
    distance, _ = spatial.cKDTree(sensor_positions).query(
        positions, k=1, distance_upper_bound=sensing_range
    )
    return inside & (distance > sensing_range)


def reporting_and_silent(
    sensor_positions: np.ndarray, sensors: np.ndarray, awake: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The positions of the sensors that report (those of ``sensors``, the step's reporting
    sensor of each measurement) and of the awake ones that do not (every other sensor
    without an ``awake`` mask), as :func:`reporting_region` takes them."""
    sensor_positions = np.asarray(sensor_positions, dtype=float)
    reporting = np.zeros(len(sensor_positions), dtype=bool)
    reporting[np.asarray(sensors, dtype=int)] = True
    silent = ~reporting if awake is None else np.asarray(awake, dtype=bool) & ~reporting
    return sensor_positions[reporting], sensor_positions[silent]


def _silent_meeting_reporting(
    reporting_positions: np.ndarray, silent_positions: np.ndarray, sensing_range: float
) -> np.ndarray:
    """The sensors of ``silent_positions`` whose disc can meet the region of
    :func:`reporting_region`: that region lies in the first reporting disc, which a silent
    disc meets only if its sensor is within 2 R (all of them without reporting sensors)."""
    silent_positions = np.asarray(silent_positions, dtype=float).reshape(-1, 2)
    if not len(reporting_positions):
        return silent_positions
    gap = np.sum((silent_positions - reporting_positions[0]) ** 2, axis=1)
    return silent_positions[gap <= (2 * sensing_range) ** 2]


def _reporting_box(
    reporting_positions: np.ndarray, sensing_range: float, area: float
) -> tuple[np.ndarray, np.ndarray]:
    """The box ``(low, high)`` ((2,) each) that holds the region of :func:`reporting_region`:
    the area cut by every reporting disc's bounding square."""
    if not len(reporting_positions):
        return np.zeros(2), np.full(2, float(area))
    low = np.maximum(np.max(reporting_positions, axis=0) - sensing_range, 0.0)
    return low, np.minimum(np.min(reporting_positions, axis=0) + sensing_range, area)


def reporting_region(
    positions: np.ndarray,
    reporting_positions: np.ndarray,
    silent_positions: np.ndarray,
    sensing_range: float,
    area: float,
) -> np.ndarray:
    """(N,) True where a position (N, 2) lies within ``sensing_range`` of every sensor of
    ``reporting_positions`` (k, 2) and where :func:`silent_region` holds for
    ``silent_positions``: where a target can be when exactly the first sensors report, with
    clutter only at sensors that sense the target."""
    if len(reporting_positions) == 0:
        return silent_region(positions, silent_positions, sensing_range, area)
    reporting_positions = np.asarray(reporting_positions, dtype=float)
    offsets = positions[:, None, :] - reporting_positions[None, :, :]
    inside = np.all(np.einsum("nki,nki->nk", offsets, offsets) <= sensing_range**2, axis=1)
    silent = _silent_meeting_reporting(reporting_positions, silent_positions, sensing_range)
    inside[inside] = silent_region(positions[inside], silent, sensing_range, area)
    return inside


def region_cells(
    reporting_positions: np.ndarray,
    silent_positions: np.ndarray,
    sensing_range: float,
    area: float,
    cell: float,
    resolution: int = 4,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A Gaussian mixture standing for the uniform density over the region of
    :func:`reporting_region`: the box that bounds the reporting discs' intersection within
    the area is cut into squares of side ``cell``, and each square that holds part of the
    region gives one component, its weight that part's share of the region's area, its mean
    the part's centroid, its variance (``cell`` / 2)^2 per axis. Gaussians of standard
    deviation half their spacing sum to a density that ripples by 2 exp(-pi^2 / 2), 1.4 %,
    per axis inside the region, and blur its edges over about a cell.
    Areas and centroids are those of a lattice of ``resolution``^2 points per square (a
    deterministic quadrature). Returns ``weights`` (K,), ``means`` (K, 2) and ``variances``
    (K, 2); K = 0 when no lattice point lies in the region."""
    reporting_positions = np.asarray(reporting_positions, dtype=float).reshape(-1, 2)
    low, high = _reporting_box(reporting_positions, sensing_range, area)
    spacing = cell / resolution
    axes = [
        np.arange(low[a] + spacing / 2, max(high[a], low[a] + spacing), spacing) for a in (0, 1)
    ]
    lattice = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    lattice = lattice[
        reporting_region(lattice, reporting_positions, silent_positions, sensing_range, area)
    ]
    if not lattice.shape[0]:
        return np.empty(0), np.empty((0, 2)), np.empty((0, 2))
    squares = np.floor((lattice - low) / cell).astype(np.int64)
    _, square, counts = np.unique(squares, axis=0, return_inverse=True, return_counts=True)
    square = square.ravel()
    means = np.stack([np.bincount(square, weights=lattice[:, a]) / counts for a in (0, 1)], axis=1)
    variances = np.full(means.shape, (cell / 2) ** 2)
    return counts / counts.sum(), means, variances


REGION_CHUNK = 2**20
"""About how many elements a temporary array of :func:`region_truncation` holds at most
(components x rows x silent discs): 8 MB of float64."""

REGION_QUADRATURE = {"half_width": 4.0, "points": 40}
"""The rows of :func:`region_truncation`: ``points`` values of y at the midpoints of equal
cells spanning the part of a component's +-``half_width`` standard-deviation box where the
region can lie (at most 0.2 standard deviations apart); along each row the integral over x
is exact."""


def _box_against_region(
    low: np.ndarray,
    high: np.ndarray,
    reporting_positions: np.ndarray,
    silent_positions: np.ndarray,
    sensing_range: float,
    area: float,
) -> tuple[np.ndarray, np.ndarray]:
    """For boxes [``low``, ``high``] (C, 2), ``(inside, outside)`` (C,) each: True where the
    box lies wholly in the region of :func:`reporting_region` (inside the area, its farthest
    corner inside every reporting disc, its nearest point outside every silent disc), and
    where it has no point in it (beyond the area, its nearest point outside a reporting disc,
    or its farthest corner inside a silent disc). A disc is convex, so the corners suffice."""
    radius2 = sensing_range**2
    inside = np.all((low >= 0.0) & (high <= area), axis=1)
    outside = np.any((high < 0.0) | (low > area), axis=1)
    if len(reporting_positions):
        farthest = _box_distance2(low, high, reporting_positions, farthest=True)
        inside &= np.all(farthest <= radius2, axis=1)
        outside |= np.any(_box_distance2(low, high, reporting_positions) > radius2, axis=1)
    if len(silent_positions):
        inside &= np.all(_box_distance2(low, high, silent_positions) > radius2, axis=1)
        farthest = _box_distance2(low, high, silent_positions, farthest=True)
        outside |= np.any(farthest <= radius2, axis=1)
    return inside, outside


def _box_distance2(
    low: np.ndarray, high: np.ndarray, points: np.ndarray, farthest: bool = False
) -> np.ndarray:
    """(C, k) squared distance from each box [``low``, ``high``] (C, 2) to each point (k, 2):
    to the box's nearest point, or with ``farthest`` to its farthest corner."""
    if farthest:
        offsets = np.maximum(
            np.abs(points[None, :, :] - low[:, None, :]),
            np.abs(points[None, :, :] - high[:, None, :]),
        )
    else:
        offsets = np.clip(points[None, :, :], low[:, None, :], high[:, None, :]) - points
    return np.sum(offsets**2, axis=2)


def _discs_reaching(
    low: np.ndarray, high: np.ndarray, positions: np.ndarray, sensing_range: float
) -> np.ndarray:
    """The sensors of ``positions`` whose disc reaches the box that holds every box
    [``low``, ``high``] (C, 2): only those can take mass from a component in it."""
    if not len(low):
        return positions[:0]
    box = np.min(low, axis=0)[None], np.max(high, axis=0)[None]
    return positions[_box_distance2(*box, positions)[0] <= sensing_range**2]


def _normal_interval_moments(lower: np.ndarray, upper: np.ndarray):
    """The standard normal's mass, first and second moments over [``lower``, ``upper``]
    (finite, ``lower`` <= ``upper``, elementwise): Phi(b) - Phi(a), phi(a) - phi(b) and
    Phi(b) - Phi(a) + a phi(a) - b phi(b). The mass of an interval in the upper tail is
    taken as Phi(-a) - Phi(-b), which keeps its digits."""
    # in the upper tail the mass is Phi(-a) - Phi(-b) = -(Phi(-b) - Phi(-a)): reflecting the
    # interval there gives both cases with one pair of Phi's, to the same bits
    sign = np.where(lower > 0.0, -1.0, 1.0)
    mass = sign * (special.ndtr(sign * upper) - special.ndtr(sign * lower))
    density_lower = np.exp(-0.5 * lower**2) / np.sqrt(2.0 * np.pi)
    density_upper = np.exp(-0.5 * upper**2) / np.sqrt(2.0 * np.pi)
    first = density_lower - density_upper
    second = mass + lower * density_lower - upper * density_upper
    return mass, first, second


def _row_pieces(
    rows: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    reporting_positions: np.ndarray,
    silent_positions: np.ndarray,
    sensing_range: float,
    area: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Along each horizontal line y = ``rows`` (any shape S) from x = ``left`` to ``right``
    (broadcast to S), the region of :func:`reporting_region` as disjoint intervals of x:
    ``(starts, ends)`` (S + (k + 1,)), the gaps that the silent discs' k chords leave in the
    one interval inside the area and every reporting disc's chord; empty pieces have zero
    width. Each piece is integrated directly, so a row the chords cover adds exactly 0."""
    lower = np.broadcast_to(np.maximum(left, 0.0), rows.shape)
    upper = np.where((rows >= 0.0) & (rows <= area), np.minimum(right, area), lower)
    for x, y in reporting_positions:
        half_chord2 = sensing_range**2 - (rows - y) ** 2
        half_chord = np.sqrt(np.maximum(half_chord2, 0.0))
        lower = np.maximum(lower, x - half_chord)
        upper = np.where(half_chord2 >= 0.0, np.minimum(upper, x + half_chord), lower)
    upper = np.maximum(upper, lower)[..., None]
    lower = lower[..., None]
    half_chord2 = sensing_range**2 - (rows[..., None] - silent_positions[:, 1]) ** 2
    half_chord = np.sqrt(np.maximum(half_chord2, 0.0))
    meets = half_chord2 > 0.0
    holes_lower = np.where(meets, np.clip(silent_positions[:, 0] - half_chord, lower, upper), lower)
    holes_upper = np.where(meets, np.clip(silent_positions[:, 0] + half_chord, lower, upper), lower)
    # sorted by start, the free piece before each chord runs from the farthest end of the
    # chords before it to its start
    order = np.argsort(holes_lower, axis=-1)
    holes_lower = np.take_along_axis(holes_lower, order, axis=-1)
    reach = np.maximum.accumulate(np.take_along_axis(holes_upper, order, axis=-1), axis=-1)
    starts = np.concatenate([lower, reach], axis=-1)
    ends = np.maximum(np.concatenate([holes_lower, upper], axis=-1), starts)
    return starts, ends


def region_truncation(
    means: np.ndarray,
    variances: np.ndarray,
    reporting_positions: np.ndarray,
    silent_positions: np.ndarray,
    sensing_range: float,
    area: float,
    half_width: float = REGION_QUADRATURE["half_width"],
    points: int = REGION_QUADRATURE["points"],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each Gaussian N(x; ``means[c]``, diag(``variances[c]``)) ((C, 2) each) cut to the
    region of :func:`reporting_region` (the target's position when exactly the reporting
    sensors report): ``(log_mass, means, variances)``, the log of its mass there and the
    moments of its truncation. With clutter only at the sensors that sense the target, the
    likelihood of which sensors report is that region's indicator, so this is the exact
    update of a Gaussian by it.

    ``variances`` must be positive. A component whose +-``half_width`` standard-deviation box
    lies wholly in the region is returned as it is, with mass 1 (what lies beyond the box is
    below 1.3e-4 of it at 4); one whose box has no point in it gets mass 0 (log -inf) and
    its moments unchanged. Otherwise the integral over y is a rule on ``points`` rows
    (:data:`REGION_QUADRATURE`) at the midpoints of equal cells spanning the box's y range
    inside the area and every reporting disc's y extent, each row weighted by the normal's
    exact mass and moments over its cell; along each row the integral over x, within the
    box, is exact: the region meets a horizontal line in one interval (the reporting discs'
    chords and the area) less the silent discs' chords, and over each piece a normal's
    moments are differences of Phi and phi. Each moment is divided by the same integral over
    the whole box, so that a component the region does not cut keeps its moments; a
    component's numbers depend on nothing beyond its box, up to rounding. A component the
    region leaves no mass on any row gets mass 0 and its moments unchanged."""
    means = np.asarray(means, dtype=float)
    variances = np.asarray(variances, dtype=float)
    reporting_positions = np.asarray(reporting_positions, dtype=float).reshape(-1, 2)
    silent_positions = _silent_meeting_reporting(
        reporting_positions, silent_positions, sensing_range
    )
    sd = np.sqrt(variances)
    low, high = means - half_width * sd, means + half_width * sd
    silent_positions = _discs_reaching(low, high, silent_positions, sensing_range)
    # Any number of components may come (a Gaussian sum holds up to 256 per prior, times
    # the priors): both passes go in chunks whose temporaries (components x silent discs,
    # then x rows) stay near REGION_CHUNK elements.
    # A box wholly in the region keeps its component (mass 1); one with no point in it
    # gives mass 0; only the rest need the rows.
    chunk = max(1, REGION_CHUNK // (len(silent_positions) + len(reporting_positions) + 1))
    boxes = [
        (low[start : start + chunk], high[start : start + chunk])
        for start in range(0, len(means), chunk)
    ]
    sets = (reporting_positions, silent_positions, sensing_range, area)
    tests = [_box_against_region(*box, *sets) for box in boxes] or [(np.zeros(0, bool),) * 2]
    untouched, missed = (np.concatenate(parts) for parts in zip(*tests))
    log_mass = np.where(missed, -np.inf, 0.0)
    means_out, variances_out = means.copy(), variances.copy()
    cut = np.flatnonzero(~untouched & ~missed)
    chunk = max(1, chunk // points)
    for start in range(0, cut.size, chunk):
        part = cut[start : start + chunk]
        log_mass[part], means_out[part], variances_out[part] = _cut_to_region(
            means[part],
            sd[part],
            reporting_positions,
            _discs_reaching(low[part], high[part], silent_positions, sensing_range),
            sensing_range,
            area,
            half_width,
            points,
        )
    return log_mass, means_out, variances_out


def _cut_to_region(
    means: np.ndarray,
    sd: np.ndarray,
    reporting_positions: np.ndarray,
    silent_positions: np.ndarray,
    sensing_range: float,
    area: float,
    half_width: float,
    points: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows' quadrature of :func:`region_truncation` for components (means and standard
    deviations (K, 2)) the region cuts, ``silent_positions`` the discs that reach their
    boxes. The rows are the midpoints of ``points`` equal cells spanning the box's y range
    where the region can lie (inside the area and every reporting disc's y extent); each
    cell weighs its row by the normal's exact mass and moments over the cell."""
    box_mass, _, box_second = _normal_interval_moments(np.array(-half_width), half_width)
    low, high = _reporting_box(reporting_positions, sensing_range, area)
    first_edge = np.clip((low[1] - means[:, 1]) / sd[:, 1], -half_width, half_width)
    last_edge = np.clip((high[1] - means[:, 1]) / sd[:, 1], first_edge, half_width)
    edges = first_edge[:, None] + (last_edge - first_edge)[:, None] * (
        np.arange(points + 1) / points
    )  # (K, P + 1), in standard deviations
    cells = np.stack(_normal_interval_moments(edges[:, :-1], edges[:, 1:]))  # (3, K, P)
    centre, scale = means[:, 0, None, None], sd[:, 0, None, None]
    starts, ends = _row_pieces(
        means[:, 1, None] + sd[:, 1, None] * (edges[:, :-1] + edges[:, 1:]) / 2,  # (K, P)
        (centre - half_width * scale)[..., 0],
        (centre + half_width * scale)[..., 0],
        reporting_positions,
        silent_positions,
        sensing_range,
        area,
    )
    # an empty piece (most of them: a silent chord that misses the row) adds exactly 0
    wide = ends > starts
    pieces = np.zeros((3,) + starts.shape)
    pieces[:, wide] = _normal_interval_moments(
        ((starts - centre) / scale)[wide], ((ends - centre) / scale)[wide]
    )
    rows = pieces.sum(axis=-1)  # (3, K, P): x mass, moments
    mass = np.sum(cells[0] * rows[0], axis=1)
    some = mass > 0
    safe = np.where(some, mass, 1.0)[:, None]
    first = np.column_stack([np.sum(cells[0] * rows[1], 1), np.sum(cells[1] * rows[0], 1)])
    second = np.column_stack([np.sum(cells[0] * rows[2], 1), np.sum(cells[2] * rows[0], 1)])
    first, second = first / safe, second / safe
    variance_ratio = np.maximum(second - first**2, 0.0) / (box_second / box_mass)
    log_mass = np.where(some, np.log(safe[:, 0] / box_mass**2), -np.inf)
    means_out = np.where(some[:, None], means + sd * first, means)
    variances_out = np.where(some[:, None], sd**2 * variance_ratio, sd**2)
    return log_mass, means_out, variances_out


def particle_moments(states: np.ndarray, weights: np.ndarray):
    """The weighted mean (2, 2) and covariance per axis (2, 2, 2) of the particles."""
    mean = np.einsum("n,nai->ai", weights, states)
    deviation = states - mean
    return mean, np.einsum("n,nai,naj->aij", weights, deviation, deviation)
