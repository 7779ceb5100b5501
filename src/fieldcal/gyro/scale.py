"""The gyroscope's scale checked against the other sensors before any fit: its unit and the
log's time base.

Over short stretches of motion, the turn the gyroscope integrates (``|Σ ω Δt|``) is compared
with the turn the accelerometer and magnetometer show (the rotation between the two-vector
frames of the stretch's ends, TRIAD; the accelerometer's direction change alone without a
magnetometer, a lower bound). Raw, uncalibrated readings distort that turn by their gains'
spread and biases, tens of percent, never a factor of three; a gyroscope read in deg/s as rad/s
is off by 57.3, a ``--rate`` ten times the log's by 0.1. The median ratio over the stretches
names the mistake before a fit that could not converge from it runs for a minute.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..errors import GYRO_UNIT, WRONG_RATE, InputError

__all__ = [
    "DEG_PER_RAD",
    "GYRO_UNITS",
    "RATE_PREFIX",
    "gyro_factor",
    "gyro_scale_problem",
    "turn_ratio",
]

Array = NDArray[np.float64]

#: Degrees in a radian: the ratio a gyroscope read in deg/s shows.
DEG_PER_RAD = 180.0 / math.pi
#: ``--gyro-unit`` names and their rad/s per raw unit (a number is taken as that factor).
GYRO_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0, "dps": math.pi / 180.0}
#: How a problem that blames ``--rate`` starts (every path refuses it: a wrong rate would be
#: absorbed into the gyroscope's gain and correct wrongly; a unit only the continuous path).
RATE_PREFIX = "--rate "
#: Ratios inside this band are the raw sensors' distortion, not a wrong unit or time base.
_ACCEPTED = (1.0 / 3.0, 3.0)
#: Stretches whose visible turn lies in this band (degrees) are compared: beyond the noise,
#: small enough for the summed rate to be the turn.
_VISIBLE_DEG = (5.0, 90.0)
#: The share of stretches compared: those the gyroscope finds fastest.
_FASTEST = 0.3
#: The stretches' lengths tried, in samples.
_LENGTHS = (8, 16, 32, 64, 128, 256)
#: Fewest stretches for a judgement.
_LEAST = 12


def gyro_factor(unit: str | float | None) -> float:
    """rad/s per raw unit of ``--gyro-unit``: a name of :data:`GYRO_UNITS` or a positive number
    (``None``: rad/s, 1)."""
    if unit is None:
        return 1.0
    text = str(unit).strip().lower().replace(" ", "")
    if text in GYRO_UNITS:
        return GYRO_UNITS[text]
    try:
        number = float(text)
    except ValueError:
        number = math.nan
    if not (math.isfinite(number) and number > 0):
        raise InputError(
            f"--gyro-unit must be rad/s, deg/s or a positive number (rad/s per raw unit), "
            f"got {str(unit)!r}"[:200]
        )
    return number


def _unit(v: Array) -> Array:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, norm, out=np.zeros_like(v), where=norm > 0)


def _centred(x: Array) -> Array:
    """Readings less a sphere's centre fitted to them (``2 x·c + d = |x|²``, least squares):
    a bias comparable to the field (hard iron, the seed paper's Table 1) bends the raw
    directions more than any gain does. Unchanged when the readings do not determine it."""
    design = np.column_stack([2.0 * x, np.ones(len(x))])
    solution, _, rank, _ = np.linalg.lstsq(design, np.einsum("ij,ij->i", x, x), rcond=None)
    centre = solution[:3]
    if rank < 4 or not np.all(np.isfinite(centre)):
        return x
    return x - centre


def _frames(a: Array, m: Array | None) -> Array:
    """Orthonormal frames (k, 3, 3) from the two field directions (rows: a, a×m, a×(a×m))."""
    x = _unit(a)
    if m is None:
        return x[:, None, :]
    y = _unit(np.cross(x, m))
    return np.stack([x, y, np.cross(x, y)], axis=1)


def _moving_mean(x: Array, k: int) -> Array:
    """Means of ``k`` consecutive rows (row ``i``: rows ``i .. i+k-1``), ``n-k+1`` of them."""
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    return (c[k:] - c[:-k]) / k


def _one_length(
    steps: Array, accel: Array, mag: Array | None, gyro: Array, step: int
) -> tuple[float, int] | None:
    """:func:`turn_ratio` over stretches of ``step`` samples, their ends' readings the means of
    half a stretch (the noise of one sample would hide a small turn)."""
    n = len(accel)
    k = max(3, step // 2)
    if n < 2 * step + k:
        return None
    a_all = _centred(_moving_mean(accel, k))
    m_all = None if mag is None else _centred(_moving_mean(mag, k))
    starts = np.arange(0, n - k + 1 - step, step)
    frames0 = _frames(a_all[starts], None if m_all is None else m_all[starts])
    frames1 = _frames(a_all[starts + step], None if m_all is None else m_all[starts + step])
    # the turn between a stretch's ends: R = F1ᵀ F0, its angle from the trace (two vectors),
    # or the angle between the accelerometer's directions (one)
    if frames0.shape[1] == 3:
        R = np.einsum("kji,kjl->kil", frames1, frames0)
        cos = (np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0
    else:
        cos = np.einsum("ki,ki->k", frames1[:, 0], frames0[:, 0])
    seen = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    # the gyroscope's turn between the ends' centres: |Σ ω Δt| (small turns: the vector sum)
    cumulative = np.cumsum(np.vstack([np.zeros((1, 3)), gyro[1:] * steps[:, None]]), axis=0)
    centre = starts + k // 2
    turned = np.degrees(np.linalg.norm(cumulative[centre + step] - cumulative[centre], axis=1))
    # the stretches the gyroscope finds fastest (a rank: the same whatever its unit), where
    # the turn stands out of the field sensors' noise, and within the small-turn band
    fastest = turned >= np.quantile(turned, 1.0 - _FASTEST)
    use = fastest & (seen > _VISIBLE_DEG[0]) & (seen < _VISIBLE_DEG[1]) & np.isfinite(turned)
    if int(use.sum()) < _LEAST:
        return None
    return float(np.median(turned[use] / seen[use])), int(use.sum())


def turn_ratio(
    time: Array, accel: Array, mag: Array | None, gyro: Array
) -> tuple[float, int] | None:
    """The median ratio of the gyroscope's integrated turn to the turn the field sensors show
    over short stretches of motion, and the number of stretches compared; ``None`` when too
    few stretches move visibly.

    The stretches are counted in samples, never in seconds: a wrong time base is what the
    ratio is to reveal. Of the lengths tried (8 to 256 samples), the longest that compares
    twice :data:`_LEAST` stretches is used: the longer the stretch, the less the field
    sensors' noise adds to the turn they show (which biases the ratio low).

    Parameters
    ----------
    time : (n,) array
        Seconds, increasing.
    accel, mag, gyro : (n, 3) arrays
        Raw readings (``mag`` may be ``None``); the gyroscope in the unit it is to be read in.
    """
    steps = np.diff(np.asarray(time, dtype=float))
    if len(steps) < 20 or not np.all(np.isfinite(steps)):
        return None
    found = [_one_length(steps, accel, mag, gyro, step) for step in _LENGTHS]
    enough = [f for f in found if f is not None and f[1] >= 2 * _LEAST]
    if enough:
        return enough[-1]
    tried = [f for f in found if f is not None]
    return max(tried, key=lambda f: f[1]) if tried else None


def gyro_scale_problem(
    time: Array,
    accel: Array,
    mag: Array | None,
    gyro: Array,
    *,
    rate: float | None,
    has_time: bool,
    unit: str | float | None,
) -> InputError | None:
    """What is wrong when the gyroscope's integrated turn disagrees with the field sensors' by
    more than a factor of three, naming the likely mistake: a gyroscope in deg/s
    (``--gyro-unit``), a ``--rate`` that contradicts the log, or a unit to give; ``None`` when
    they agree (or too little motion tells).

    ``gyro`` is already scaled by ``unit``; ``rate`` is the ``--rate`` given (``None``: the
    time column's); ``has_time``: the log has a time column. The pose path's gyroscope fit
    takes any unit (its gain absorbs it) but not a wrong rate, which it would absorb too and
    correct wrongly; the continuous estimator needs rad/s.
    """
    found = turn_ratio(time, accel, mag, gyro)
    if found is None:
        return None
    ratio, count = found
    # the accelerometer alone sees only the turn away from gravity: a ratio up to 2 on real logs
    high = _ACCEPTED[1] if mag is not None else 5.0
    if _ACCEPTED[0] <= ratio <= high:
        return None
    what = (
        f"the gyroscope's integrated turn is {ratio:.3g} times the turn the accelerometer"
        + (" and magnetometer show" if mag is not None else " shows")
        + f" (median of {count} stretches of motion)"
    )
    if unit is None and 0.6 * DEG_PER_RAD <= ratio <= 1.6 * DEG_PER_RAD:
        return InputError(
            f"the gyroscope seems to read in deg/s, not rad/s: {what}, and deg/s is off by "
            f"{DEG_PER_RAD:.1f}; give --gyro-unit deg/s (gyro_unit='deg/s')",
            code=GYRO_UNIT,
        )
    if rate is not None and 1 / 30 < ratio < 30:  # beyond, a raw unit more likely than a rate
        likely = rate * ratio
        against = "the log's time column" if has_time else "the log"
        return InputError(
            f"{RATE_PREFIX}{rate:g} contradicts {against}: at that rate {what}; the samples "
            f"come at about {likely:.3g} Hz: give --rate {likely:.3g}"
            + (" or leave --rate out to use the time column" if has_time else "")
            + " (or, if the rate is right, the gyroscope's unit with --gyro-unit)",
            code=WRONG_RATE,
        )
    return InputError(
        f"{what}; give the gyroscope's unit with --gyro-unit (rad/s, deg/s, or a number: rad/s "
        "per raw unit) and check that the time column is in seconds (--time-col)",
        code=GYRO_UNIT,
    )
