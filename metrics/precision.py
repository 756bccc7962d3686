"""Sample counts sized from the precision a score states, and the standard errors it reports.

A score's means and proportions are estimated from random samples: points drawn on a test mesh
and on the truth, or a random subset of a test cloud's points. ``score`` (no explicit sample
count) draws a pilot of ``defaults.PILOT_SAMPLES`` per side, estimates from it the standard
deviations of the two distance distributions and the two proportions within tau, and sizes
each side so that

- the Chamfer distance's standard error is at most ``precision`` times the Chamfer distance,
- the F-score's standard error is at most ``precision / 4``

(``plan``), then scores the further samples and checks again (``defaults.PRECISION_ROUNDS``
rounds at most; the counts are capped at ``defaults.MAX_SAMPLES`` per side, a cloud's sample
at ``defaults.CLOUD_SAMPLES``). The coverage lattice (``lattice_size``) and the edge metric's
sample of the points far from feature edges (``far_sample_fraction``) are sized beforehand for
a standard error of ``precision / 4`` on the coverage and the edge score at their worst case (a
precision whose lattice would take more than ``defaults.COVERAGE_MAX_BYTES`` is refused).
The standard errors of the samples actually scored are reported, whatever the target.

Formulas. A mean of n values drawn independently has the standard error ``s / sqrt(n)`` (s the
sample standard deviation); of n values drawn without replacement from a cloud of N points,
``s / sqrt(n) * sqrt(1 - n / N)`` (0 when every point is scored). Chamfer = (mean accuracy +
mean completeness) / 2, so its variance is a quarter of the sum of the two means'. A proportion
p of n has variance ``p (1 - p) / n`` (stated with Agresti and Coull's adjustment,
``proportion_se``); F = 2 P R / (P + R) has the gradient
``(2 R**2, 2 P**2) / (P + R)**2`` in (P, R), whose first-order (delta method) variance is
``fscore_se``. For a total variance ``v1 / n1 + v2 / n2`` at most T**2, the fewest samples
``n1 + n2`` are ``ni = sqrt(vi) (sqrt(v1) + sqrt(v2)) / T**2``, or, when one side already
has more samples than that, the other side what the rest of the budget asks (``_allocate``).

Which points of a cloud are scored must not depend on how the cloud is cut into blocks (a file
is streamed, an array is held whole, both give the same report): each point gets a key in
[0, 1) from a hash of its coordinates' bits and the seed (``point_keys``), and a sample of m
points is the m smallest keys (ties, i.e. copies of one point, by row). Keys below a bound are
a Bernoulli sample; the edge metric takes the points far from feature edges whose key is below
a fraction (``edges.edge_report``).
"""

from __future__ import annotations

import math

import numpy as np

from metrics import defaults

# splitmix64 (Steele, Lea and Flood 2014): a bijection of 64-bit words whose output bits each
# depend on every input bit; applied after each coordinate is mixed in.
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
# Salts of ``point_keys``: which points of a cloud its accuracy is averaged over, and which of
# its points far from feature edges the edge metric tests.
CLOUD_SALT = 3
EDGE_SALT = 4


def _splitmix(z: np.ndarray) -> np.ndarray:
    """splitmix64 of uint64 words, in place and returned."""
    z += _GOLDEN
    z ^= z >> np.uint64(30)
    z *= _MIX1
    z ^= z >> np.uint64(27)
    z *= _MIX2
    z ^= z >> np.uint64(31)
    return z


def point_keys(points: np.ndarray, seed: int, salt: int) -> np.ndarray:
    """A uniform pseudo-random key per point, a function of its coordinates, ``seed`` and
    ``salt`` only (not of its row or of the other points).

    Parameters
    ----------
    points : (n, 3) float64
    seed, salt : int, >= 0
        Different salts give independent keys for different uses of one seed.

    Returns
    -------
    (n,) float64, in [0, 1), multiples of 2**-53
    """
    bits = np.ascontiguousarray(points, dtype=np.float64).view(np.uint64)
    start = _splitmix(np.array([seed, salt], dtype=np.uint64)).sum(dtype=np.uint64)
    z = np.full(len(bits), start, dtype=np.uint64)
    for axis in range(3):  # three coordinates, each a vectorised pass
        z ^= bits[:, axis]
        _splitmix(z)
    return (z >> np.uint64(11)).astype(np.float64) * 2.0**-53


def smallest_keys(keys: np.ndarray, m: int) -> np.ndarray:
    """Rows of the ``m`` smallest keys, ascending by (key, row).

    Returns
    -------
    (min(m, n),) int64
    """
    if m >= len(keys):
        return np.argsort(keys, kind="stable")
    bound = np.partition(keys, m - 1)[m - 1]
    rows = np.flatnonzero(keys <= bound)
    return rows[np.argsort(keys[rows], kind="stable")][:m]


class KeySample:
    """The ``limit`` smallest keys of a stream of points, kept as the blocks go by.

    The same rows, in the same order, as ``smallest_keys`` of the whole stream's keys: rows are
    kept in stream order while their key is at most the bound, and the bound falls when more
    than twice ``limit`` are held (a stable sort keeps the first ``limit``).
    """

    def __init__(self, limit: int, seed: int, salt: int):
        self.limit, self.seed, self.salt = int(limit), int(seed), int(salt)
        self.bound = 1.0
        self.keys: list[np.ndarray] = []
        self.points: list[np.ndarray] = []
        self.normals: list[np.ndarray | None] = []
        self.n = 0
        self.low, self.high = np.full(3, np.inf), np.full(3, -np.inf)   # of every point

    def add(self, points: np.ndarray, normals: np.ndarray | None) -> None:
        """A block: points (b, 3) float64 metres, normals (b, 3) or None."""
        if len(points) == 0:
            return
        self.n += len(points)
        self.low = np.minimum(self.low, points.min(axis=0))
        self.high = np.maximum(self.high, points.max(axis=0))
        keys = point_keys(points, self.seed, self.salt)
        keep = keys <= self.bound
        self.keys.append(keys[keep])
        self.points.append(points[keep])
        self.normals.append(None if normals is None else normals[keep])
        if sum(map(len, self.keys)) > 2 * self.limit:
            self._trim()

    def _trim(self) -> None:
        keys = np.concatenate(self.keys)
        rows = np.argsort(keys, kind="stable")[:self.limit]
        rows.sort()   # back in stream order
        self.bound = float(keys[rows].max())
        self.keys = [keys[rows]]
        self.points = [np.concatenate(self.points)[rows]]
        self.normals = [None if self.normals[0] is None
                        else np.concatenate(self.normals)[rows]]

    def sample(self) -> tuple[np.ndarray, np.ndarray | None]:
        """Points (m, 3) and normals (m, 3) or None of the smallest keys, ascending."""
        keys = np.concatenate(self.keys)
        rows = np.argsort(keys, kind="stable")[:self.limit]
        normals = None if self.normals[0] is None else np.concatenate(self.normals)[rows]
        return np.concatenate(self.points)[rows], normals


def proportion_se(p: float, n: int, population: int | None = None) -> float:
    """Standard error of a proportion ``p`` of ``n`` draws (without replacement from
    ``population`` when given), Agresti and Coull's: that of the proportion of x + 2 in
    n + 4 (x = p n), so a sample that saw none (or all) still states an error, ~1 / n."""
    if n < 1:
        return 0.0
    adjusted = (p * n + 2.0) / (n + 4.0)
    se = math.sqrt(adjusted * (1.0 - adjusted) / (n + 4.0))
    return se if population is None else se * math.sqrt(max(0.0, 1.0 - n / population))


def fscore_se(precision: float, recall: float, precision_se: float, recall_se: float) -> float:
    """First-order standard error of F = 2 P R / (P + R) from those of P and R (independent
    samples); 0 when P + R = 0."""
    total = precision + recall
    if total <= 0:
        return 0.0
    return 2.0 * math.hypot(recall**2 * precision_se, precision**2 * recall_se) / total**2


def _allocate(sd1: float, sd2: float, target: float, have1: int, have2: int
              ) -> tuple[float, float]:
    """Fewest further samples: (n1, n2) with ``sd1**2 / n1 + sd2**2 / n2 <= target**2``, n1
    >= have1 and n2 >= have2. The unconstrained optimum is ``ni = sdi (sd1 + sd2) /
    target**2``; when a side already has more than its optimum, the other side needs only
    what is left of the variance budget."""
    if target <= 0:
        return math.inf, math.inf
    scale = (sd1 + sd2) / target**2
    n1, n2 = sd1 * scale, sd2 * scale
    if have1 > n1:   # side 1 keeps what it has (more than it needs)
        n2 = _rest(sd2, target**2 - sd1**2 / have1)
    elif have2 > n2:
        n1 = _rest(sd1, target**2 - sd2**2 / have2)
    return n1, n2


def _rest(sd: float, budget: float) -> float:
    """Samples for a variance ``sd**2 / n`` within ``budget`` (> 0: the other side's share is
    below the whole target)."""
    return sd**2 / budget if budget > 0 else math.inf


def plan(accuracy: np.ndarray, completeness: np.ndarray, tau: float, precision: float,
         population: int | None = None) -> tuple[int, int]:
    """Samples per side (accuracy, completeness) for the stated precision, from a pilot.

    Parameters
    ----------
    accuracy, completeness : (n1,), (n2,) float64, metres
        Distances of the samples scored so far (test to truth, truth to test).
    tau : float, metres
    precision : float
        Relative standard error wanted of the Chamfer distance; the F-score's (absolute) is a
        quarter of it.
    population : int, optional
        Points of a test cloud (its accuracy side cannot have more samples).

    Returns
    -------
    n_accuracy, n_completeness : int
        At least the samples already scored, at most ``defaults.MAX_SAMPLES`` (a cloud's
        accuracy side: ``population`` and ``defaults.CLOUD_SAMPLES``).
    """
    chamfer = 0.5 * (accuracy.mean() + completeness.mean())
    sd_a, sd_c = (float(np.std(d, ddof=1)) if len(d) > 1 else 0.0
                  for d in (accuracy, completeness))
    # Chamfer: the two means' variances over four.
    have = (len(accuracy), len(completeness))
    need_a, need_c = _allocate(0.5 * sd_a, 0.5 * sd_c, precision * chamfer, *have)
    p, r = float(np.mean(accuracy < tau)), float(np.mean(completeness < tau))
    if p + r > 0:
        grad_p, grad_r = 2 * r**2 / (p + r)**2, 2 * p**2 / (p + r)**2
        f_a, f_c = _allocate(grad_p * math.sqrt(p * (1 - p)), grad_r * math.sqrt(r * (1 - r)),
                             0.25 * precision, *have)
        need_a, need_c = max(need_a, f_a), max(need_c, f_c)
    cap_a = (defaults.MAX_SAMPLES if population is None
             else min(population, defaults.CLOUD_SAMPLES))
    return (_clip(need_a, len(accuracy), cap_a),
            _clip(need_c, len(completeness), defaults.MAX_SAMPLES))


def _clip(need: float, have: int, cap: int) -> int:
    """``ceil(need)`` (with 2 % to spare, as a pilot's deviations are estimates) kept within
    ``have..cap`` (``have`` itself when it already exceeds the cap)."""
    want = math.ceil(1.02 * need) if math.isfinite(need) else cap
    return max(have, min(want, cap))


def lattice_size(precision: float) -> int:
    """Target size of the coverage lattice for the stated precision: the count whose binomial
    standard error at a coverage of 1/2 (the worst case) is ``precision / 4``."""
    return math.ceil(0.25 / (0.25 * precision)**2)


def far_share_points(precision: float) -> int:
    """Points of smallest edge keys whose share far from feature edges sizes the far sample
    (``far_sample_fraction``): eight times the sample the precision asks, so the share is
    known to about 0.01."""
    return 8 * math.ceil(0.25 / (0.5 * precision)**2)


def far_sample_fraction(n_points: int, far_share: float, precision: float) -> float:
    """Fraction of a cloud's points far from feature edges whose edge test is run, for the
    false-edge rate's standard error to be at most ``precision / 2`` (the edge score's at most
    ``precision / 4``) at the worst rate 1/2: ``0.25 / (precision / 2)**2`` of the
    ``n_points * far_share`` far points expected, and 10 % more (1 for small clouds)."""
    far = n_points * far_share
    # 10 % to spare: the sample's size is itself random (a Bernoulli sample of the keys).
    return 1.0 if far <= 0 else min(1.0, 1.1 * 0.25 / (0.5 * precision)**2 / far)


def check_precision(value) -> float:
    """``value`` as a relative standard error in (0, 0.5]."""
    from formats.errors import InputError

    if (isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating)
            or not np.isfinite(value) or not 0 < value <= 0.5):
        raise InputError(f"precision must be a number in (0, 0.5], got {value!r}",
                         argument="precision")
    return float(value)
