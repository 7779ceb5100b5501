"""Pose statistics of Sec. 3: per-pose means (Eq. 5), counts Δ_i and pooled covariance (Eq. 7).

Also the input checks every method shares: what a "sequence of N pose arrays" may be and the
one-line errors for what it may not.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._frozen import ArrayDataclass
from ..limits import LARGEST, power_of_two
from .pose_temperature import PoseTemperature
from .trimming import MIN_SAMPLES, unsteady

__all__ = [
    "LARGEST",
    "PoseStats",
    "Samples",
    "SensorStats",
    "as_pose_list",
    "as_readings",
    "brief",
    "check_spread",
    "power_of_two",
    "stats_from_means",
    "summarize",
    "summarize_scaled",
]

Array = NDArray[np.float64]


#: One sensor's raw input as a user gives it: N per-pose (n_i, 3) arrays (any sequence of
#: array-likes) or an (N, n, 3) array; methods that take continuous input also accept one
#: (n, 3) array. Checked at run time (:func:`summarize`), with a one-line error.
Samples: TypeAlias = Sequence[ArrayLike] | NDArray[np.generic]


@dataclass(frozen=True, eq=False)
class SensorStats(ArrayDataclass):
    """One sensor's summary of N static poses, with the noise model of each pose mean.

    Attributes
    ----------
    means : (N, 3) array
        ``μ̂_s[i]``, Eq. 5.
    counts : (N,) int array
        ``Δ_s[i]``, samples per pose.
    cov : (3, 3) array or None
        ``Σ̂_s``, Eq. 7 (pooled within-pose scatter divided by ``ΣΔ − N``, the generalised
        Bessel correction), or the user's; ``None`` when no pose has more than one sample.
    dof : int
        ``ΣΔ − N``, the degrees of freedom of ``cov`` (a Wishart variate).
    pose_var : float
        ``q²``: variance per axis of the pose-level error of each mean, ``Q = q² I``.
    trimmed : (N,) int array or None
        Samples cut per pose as not still (:mod:`fieldcal.stats.trimming`), when trimmed.
    scatter : (N,) array or None
        Each pose's own within-pose variance per axis (trace of its scatter / 3Δ_i): a pose
        whose readings swing (the device turned) stands out from the rest.
    """

    means: Array
    counts: NDArray[np.int64]
    cov: Array | None
    dof: int
    pose_var: float = 0.0
    trimmed: NDArray[np.int64] | None = None
    scatter: Array | None = None

    @property
    def n_poses(self) -> int:
        return int(self.means.shape[0])

    def mean_covariances(self) -> Array:
        """(N, 3, 3): the covariance of each pose mean, ``Σ/Δ_i + q² I``."""
        n = self.n_poses
        if self.cov is None:
            total = np.zeros((n, 3, 3))
        else:
            total = self.cov[None, :, :] / self.counts[:, None, None]
        total.reshape(n, 9)[:, ::4] += self.pose_var
        return total

    def with_pose_var(self, pose_var: float) -> SensorStats:
        """The same poses with another pose-level variance."""
        return dataclasses.replace(self, pose_var=float(pose_var))

    def subset(self, index: ArrayLike) -> SensorStats:
        """Statistics of a subset of poses, keeping the pooled covariance as it is."""
        index = np.asarray(index)
        return dataclasses.replace(
            self,
            means=self.means[index],
            counts=self.counts[index],
            trimmed=None if self.trimmed is None else self.trimmed[index],
            scatter=None if self.scatter is None else self.scatter[index],
        )


@dataclass(frozen=True, eq=False)
class PoseStats(ArrayDataclass):
    """Both sensors' summaries; either may be ``None`` for single-sensor calibration.

    ``memo`` holds what fitting code derives from these statistics once (e.g. the whitened
    problem of :mod:`fieldcal.methods.mle`), so a fit and the evaluation of its result on the
    same statistics do not repeat it; a replaced or subset copy starts empty. ``temperature``:
    the poses' mean temperatures and the temperature terms to fit (``None``: no temperature).
    """

    accel: SensorStats | None
    mag: SensorStats | None
    temperature: PoseTemperature | None = None
    memo: dict[object, object] = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def n_poses(self) -> int:
        sensor = self.accel if self.accel is not None else self.mag
        return 0 if sensor is None else sensor.n_poses

    @functools.cached_property
    def sensors(self) -> tuple[str, ...]:
        """The sensors present, accelerometer first (asked for many times per fit: kept)."""
        return tuple(s for s in ("accel", "mag") if getattr(self, s) is not None)

    def sensor(self, name: str) -> SensorStats:
        value: SensorStats | None = getattr(self, name)
        if value is None:
            raise ValueError(f"no {name} poses")
        return value

    def replace(self, **sensors: SensorStats | None) -> PoseStats:
        """The same statistics with some sensors replaced (a new object: ``memo`` empty)."""
        unknown = sorted(set(sensors) - {"accel", "mag"})
        if unknown:
            raise TypeError(f"PoseStats has no sensor {unknown[0]!r}")
        return PoseStats(
            sensors.get("accel", self.accel), sensors.get("mag", self.mag), self.temperature
        )

    def with_temperature(self, temperature: PoseTemperature | None) -> PoseStats:
        """The same poses with other temperature terms (a new object: ``memo`` empty)."""
        return PoseStats(self.accel, self.mag, temperature)

    def subset(self, index: ArrayLike) -> PoseStats:
        return PoseStats(
            None if self.accel is None else self.accel.subset(index),
            None if self.mag is None else self.mag.subset(index),
            None if self.temperature is None else self.temperature.subset(index),
        )


def brief(value: object, limit: int = 60) -> str:
    """``repr(value)`` on one line and at most ``limit`` characters, for error messages (an
    array's repr spans lines)."""
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


#: dtype kinds that are not readings, and what to call them.
_NOT_READINGS = {
    "b": "true/false values",
    "c": "complex numbers (pass the real part if the imaginary parts are zero)",
    "U": "text",
    "S": "bytes",
    "M": "dates",
    "m": "time spans",
    "V": "records",
}


def as_readings(value: object, what: str) -> Array:
    """``value`` as a float array, refusing what is not real numbers in one line.

    Complex numbers are refused (their imaginary parts would be dropped silently), and so
    are booleans, text, dates, masked entries and objects that are not numbers; ``what``
    names the value in the message (e.g. ``"accel: pose 3"``).
    """
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{what} is text, not numeric readings ({brief(value, 30)})")
    if isinstance(value, np.ma.MaskedArray) and np.ma.is_masked(value):
        raise ValueError(f"{what} has masked entries; drop those samples first")
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):
        raise ValueError(
            f"{what} is not an array of numbers (rows of different lengths?)"
        ) from None
    kind = array.dtype.kind
    if kind in _NOT_READINGS:
        raise ValueError(f"{what} holds {_NOT_READINGS[kind]}, not numeric readings")
    if kind == "O":
        items = array.ravel().tolist()
        if not all(
            isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            for v in items
        ):
            raise ValueError(f"{what} is not numeric: it holds Python objects that are not numbers")
    try:
        return np.asarray(array, dtype=np.float64)
    except OverflowError:  # Python integers beyond the float range
        raise ValueError(f"{what} has numbers too large for floating point") from None


def as_pose_list(samples: object, name: str) -> list[Array]:
    """Validate one sensor's input: N arrays of shape (n_i, 3), or an (N, n, 3) array.

    Raises ``ValueError`` with a one-line message naming the problem and the fix.
    """
    poses = _pose_arrays(samples, name)
    _check_values(poses, name)
    return poses


def _pose_arrays(samples: object, name: str) -> list[Array]:
    """The poses as float (n_i, 3) arrays, their shapes and kinds checked (not their values:
    the summary's one pass over the samples does that, :func:`_moments`)."""
    if isinstance(samples, np.ndarray) and samples.ndim == 3:
        poses = list(samples)
    elif isinstance(samples, np.ndarray) and samples.ndim == 2:
        raise ValueError(
            f"{name}: got one ({samples.shape[0]}, {samples.shape[1]}) array; pass a list with one "
            "(n_i, 3) array per static pose (or use method='ellipsoid' for continuous samples)"
        )
    elif isinstance(samples, Sequence) and not isinstance(samples, (str, bytes)):
        poses = list(samples)
    else:
        raise ValueError(
            f"{name}: expected a sequence of per-pose (n_i, 3) arrays, got {type(samples).__name__}"
        )
    if not poses:
        raise ValueError(f"{name}: no poses given; pass one (n_i, 3) array per static pose")
    out = []
    for i, pose in enumerate(poses):
        # the common case, a float (n, 3) array, needs none of as_readings' conversions
        if (
            type(pose) is np.ndarray
            and pose.dtype == np.float64
            and pose.ndim == 2
            and pose.shape[1] == 3
            and pose.shape[0] > 0
        ):
            out.append(pose)
            continue
        array = as_readings(pose, f"{name}: pose {i}")
        if array.ndim == 1 and array.shape == (3,):
            array = array[None, :]
        if array.ndim != 2 or array.shape[1] != 3:
            raise ValueError(
                f"{name}: pose {i} has shape {array.shape}; each pose must be an (n_i, 3) array "
                "of x, y, z readings"
            )
        if array.shape[0] == 0:
            raise ValueError(f"{name}: pose {i} has no samples; drop it or record it again")
        out.append(array)
    return out


def _check_values(poses: list[Array], name: str) -> None:
    """Refuse NaN, inf and readings whose squares overflow, naming where (a full scan: used
    when the one-pass summary found something wrong, or by :func:`as_pose_list`)."""
    counts = np.array([len(a) for a in poses], dtype=np.int64)
    stacked = poses[0] if len(poses) == 1 else np.concatenate(poses, axis=0)
    _check_finite(stacked, counts, name)
    _check_range(stacked, counts, name)


def _check_finite(stacked: Array, counts: NDArray[np.int64], name: str) -> None:
    """One vectorised pass; the message names the poses with non-finite readings."""
    finite = np.isfinite(stacked)
    if finite.all():
        return
    bad_rows = np.flatnonzero(~finite.all(axis=1))
    bad = np.unique(np.searchsorted(np.cumsum(counts), bad_rows, side="right"))
    shown = ", ".join(map(str, bad[:5])) + (" ..." if len(bad) > 5 else "")
    raise ValueError(
        f"{name}: NaN or inf readings in {len(bad)} pose(s) ({shown}); "
        "remove those samples before calibrating"
    )


def _check_range(stacked: Array, counts: NDArray[np.int64], name: str) -> None:
    """Readings whose squares overflow are refused, naming the pose, sample and axis."""
    if stacked.size == 0 or float(np.max(np.abs(stacked))) <= LARGEST:
        return
    row, axis = np.unravel_index(int(np.argmax(np.abs(stacked))), stacked.shape)
    ends = np.cumsum(counts)
    pose = int(np.searchsorted(ends, row, side="right"))
    sample = int(row - (ends[pose - 1] if pose else 0))
    raise ValueError(
        f"{name}: readings up to {float(np.abs(stacked[row, axis])):.3g} (pose {pose}, sample "
        f"{sample}, axis {'xyz'[axis]}) are too large to square in floating point; give them in "
        "a smaller unit (e.g. divide by a power of ten) and scale the gain back"
    )


#: Samples per block of the summary: a block's two work arrays ((3, BLOCK), under 1 MB each)
#: stay in the CPU cache and are reused, so each sample is read from memory once however many
#: there are, and no temporary grows with the input.
BLOCK = 1 << 15


class _Scratch:
    """Work arrays shared by every step of one summary (both sensors): memory a process has
    not touched yet costs a page fault per 4 KB, more than the arithmetic on it, so the steps
    write into these rather than into fresh temporaries."""

    def __init__(self) -> None:
        self._floats = np.empty(0)

    def floats(self, rows: int, k: int) -> Array:
        """A C-contiguous (rows, k) float array (contents undefined)."""
        if self._floats.size < rows * k:
            self._floats = np.empty(rows * k)
        return self._floats[: rows * k].reshape(rows, k)


@dataclass
class _Moments:
    """Sums of one sensor's samples shifted by a reading of their pose, ``x0``, in units of
    ``unit`` (``d = (x − x0) / unit``): per pose ``Σ d`` and ``Σ d²`` (per axis), over all
    samples ``Σ d_x d_y, Σ d_x d_z, Σ d_y d_z``; the smallest and largest reading when asked
    for.

    ``unit`` is a power of two of the size of the readings (:func:`_unit`): dividing by it
    changes no digit, and the squares of readings in any unit, 1e-300 or 1e100, neither
    underflow nor overflow.
    """

    x0: Array
    sums: Array
    squares: Array
    cross: Array
    unit: float = 1.0
    extremes: tuple[float, float] | None = None

    @classmethod
    def empty(cls, x0: Array, unit: float) -> _Moments:
        n = len(x0)
        return cls(x0, np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(3), unit)

    @property
    def finite(self) -> bool:
        """Whether every sample was finite (a NaN or inf reaches the sums of squares; an
        overflow of the sums themselves is reported as non-finite too, and rechecked)."""
        return bool(np.isfinite(self.squares).all() and np.isfinite(self.sums).all())

    def bound(self) -> float:
        """An upper bound of ``|x|``: ``|x0| + unit · sqrt(Σ d²)`` per pose and axis."""
        return float(np.max(np.abs(self.x0) + self.unit * np.sqrt(self.squares)))

    def add(
        self,
        x: Array,
        ids: NDArray[np.intp],
        rows: NDArray[np.int64],
        work: Array,
    ) -> None:
        """Add a block: ``x`` (3, k) holds the consecutive poses ``ids`` (``rows`` samples
        each) and is overwritten; ``work`` is a (3, ≥ k) scratch array.

        Shifting each pose by its own first sample keeps the sums of squares of the size of
        the noise, so Eq. 7's ``Σ d dᵀ − Δ d̄ d̄ᵀ`` loses nothing to cancellation whatever
        the offset. Axes as rows: every reduction runs over contiguous memory.
        """
        k = x.shape[1]
        shift = self.x0[ids].T
        d = np.subtract(x, shift if len(ids) == 1 else np.repeat(shift, rows, axis=1), out=x)
        if self.unit != 1.0:
            d /= self.unit  # exact: a power of two (its reciprocal may not exist, 2^-1030)
        self.add_deviations(d, np.multiply(d, d, out=work[:, :k]), ids, rows)

    def add_deviations(
        self, d: Array, d2: Array, ids: NDArray[np.intp], rows: NDArray[np.int64]
    ) -> None:
        """Add a block already shifted by ``x0``: ``d`` (3, k) and its square ``d2``."""
        starts = np.zeros(1, dtype=np.intp) if len(ids) == 1 else np.cumsum(rows) - rows
        self.sums[ids] += np.add.reduceat(d, starts, axis=1).T
        self.squares[ids] += np.add.reduceat(d2, starts, axis=1).T
        self.cross += (d[0] @ d[1], d[0] @ d[2], d[1] @ d[2])


def _unit(x: Array) -> float:
    """A power of two of the size of the readings ``x`` (1 for zeros or non-finite ones)."""
    return power_of_two(float(np.max(np.abs(x)))) if x.size else 1.0


def _moments(
    poses: Sequence[Array],
    counts: NDArray[np.int64],
    extremes: bool,
    scratch: _Scratch,
    unit: float | None = None,
) -> _Moments:
    """One pass over the samples (Eq. 5 and 7's sums), block by block in the cache: runs of
    small poses copied side by side into one reused array (one call), a large pose in pieces
    of :data:`BLOCK` samples. O(N) bookkeeping in Python, nothing per sample. Each pose is
    shifted by its first sample; ``unit`` defaults to the size of those."""
    first = np.array([p[0] for p in poses])
    mo = _Moments.empty(first, _unit(first) if unit is None else unit)
    width = min(BLOCK, int(counts.sum()))
    work = scratch.floats(6, width)
    block, work = work[:3], work[3:]
    lo, hi = np.inf, -np.inf
    group: list[int] = []
    rows = 0

    def flush() -> None:
        nonlocal lo, hi
        x = np.concatenate([poses[i].T for i in group], axis=1, out=block[:, :rows])
        if extremes:
            lo, hi = min(lo, float(x.min())), max(hi, float(x.max()))
        ids = np.array(group, dtype=np.intp)
        mo.add(x, ids, counts[ids], work)

    for i, n in enumerate(counts.tolist()):
        if group and rows + n > BLOCK:
            flush()
            group, rows = [], 0
        if n <= BLOCK:
            group.append(i)
            rows += n
            continue
        for a in range(0, n, BLOCK):  # a large pose: pieces copied transposed, in the cache
            part = poses[i][a : a + BLOCK]
            x = block[:, : len(part)]
            np.copyto(x, part.T)
            if extremes:
                lo, hi = min(lo, float(x.min())), max(hi, float(x.max()))
            mo.add(x, np.array([i], dtype=np.intp), np.array([len(part)]), work)
    if group:
        flush()
    if extremes:
        mo.extremes = (lo, hi)
    return mo


def _from_moments(
    mo: _Moments, counts: NDArray[np.int64], trimmed: NDArray[np.int64] | None, scale: float
) -> SensorStats:
    """Eq. 5 and Eq. 7 from the sums, for readings divided by ``scale`` (a power of two,
    like the sums' unit: rescaling the results is exact)."""
    f = mo.unit / scale
    shifted_means = mo.sums / counts[:, None]
    means = mo.x0 / scale + shifted_means * f  # Eq. 5
    dof = int(counts.sum() - len(counts))
    if dof <= 0:
        return SensorStats(means, counts, None, dof, trimmed=trimmed)
    within = mo.squares - mo.sums * shifted_means  # each pose's centred Σ d², per axis
    per_pose = np.maximum(within.sum(axis=1) / (3.0 * counts), 0.0) * (f * f)
    scatter = np.diag(within.sum(axis=0))
    c = mo.cross - np.array(
        [shifted_means[:, 1] @ mo.sums[:, 0], shifted_means[:, 2] @ mo.sums[:, 0],
         shifted_means[:, 2] @ mo.sums[:, 1]]
    )  # fmt: skip
    scatter[0, 1] = scatter[1, 0] = c[0]
    scatter[0, 2] = scatter[2, 0] = c[1]
    scatter[1, 2] = scatter[2, 1] = c[2]
    cov = scatter / dof * (f * f)  # Eq. 7
    return SensorStats(means, counts, cov, dof, trimmed=trimmed, scatter=per_pose)


def _sensor_summary(
    poses: list[Array], name: str, trim: bool, extremes: bool, scratch: _Scratch
) -> tuple[_Moments, NDArray[np.int64], NDArray[np.int64] | None]:
    """One sensor's sums (after cutting unsteady samples when ``trim``), checked: NaN, inf and
    readings beyond :data:`LARGEST` are refused in one line, naming where."""
    counts = np.array([len(p) for p in poses], dtype=np.int64)
    if trim and (counts >= MIN_SAMPLES).any():
        return _trimmed_summary(poses, name, counts, scratch)
    # no pose with samples enough to trim (e.g. one averaged shot per pose) cuts nothing:
    # no order statistics are needed, the plain sums are the summary
    mo = _moments(poses, counts, extremes or trim, scratch)
    # a NaN or inf reaches the sums; |x| <= |x0| + sqrt(Σ d²) bounds the range, and only
    # when the bound is loose (or something is wrong) are the samples scanned again
    if not (mo.finite and np.isfinite(mo.x0).all()) or mo.bound() > LARGEST:
        _check_values(poses, name)
        if not mo.finite:  # valid readings far larger than their poses' first ones
            unit = power_of_two(max(float(np.abs(p).max()) for p in poses))
            mo = _moments(poses, counts, extremes or trim, scratch, unit)
    return mo, counts, np.zeros_like(counts) if trim else None


def _trimmed_summary(
    poses: list[Array], name: str, counts: NDArray[np.int64], scratch: _Scratch
) -> tuple[_Moments, NDArray[np.int64], NDArray[np.int64]]:
    """One sensor's sums after cutting unsteady samples, checked as :func:`_sensor_summary`
    checks."""
    # trimming selects order statistics of every pose: the samples are copied side by side
    # once, axes as rows, into work space that every later step reuses
    k = int(counts.sum())
    work = scratch.floats(7, k)
    x = np.concatenate([p.T for p in poses], axis=1, out=work[:3])
    low, high = x.min(axis=1), x.max(axis=1)
    lo, hi = float(low.min()), float(high.max())  # NaN propagates through both
    if not (np.isfinite(lo) and np.isfinite(hi)) or max(-lo, hi) > LARGEST:
        _check_values(poses, name)
    unit = power_of_two(max(-lo, hi))
    if unit != 1.0:
        x /= unit  # exact; the trimming's result does not depend on it
        # each axis's extremes divided as its samples were: the same numbers as found again
        low, high = low / unit, high / unit
    found = unsteady(x, counts, work[3:], extremes=(low, high))
    # the deviations from each pose's median are Eq. 5/7's shifted samples, ready-made
    d, d2 = found.deviations, found.squares
    if found.cut is not None:  # the kept ones, into rows of the work space now free
        counts = counts - found.trimmed
        # the kept deviations over the squares (recomputed from them), their squares over
        # the deviations: both are read before they are overwritten
        d = _kept(found.deviations, found.cut, work[:3, : int(counts.sum())])
        d2 = np.multiply(d, d, out=work[3:6, : d.shape[1]])  # as compressing the squares gives
    mo = _Moments.empty(found.medians.T * unit, unit)
    mo.add_deviations(d, d2, np.arange(len(counts)), counts)
    mo.extremes = (lo, hi)
    return mo, counts, found.trimmed


def _kept(x: Array, cut: NDArray[np.bool_], out: Array) -> Array:
    """The columns of ``x`` not ``cut``, in order, into ``out``: the runs between the cut
    columns copied as slices when they are few (a bump cuts a handful of samples), else a
    boolean index per row."""
    where = np.flatnonzero(cut)
    if len(where) > 1000:
        keep = ~cut
        for row, target in zip(x, out, strict=True):
            target[:] = row[keep]
        return out
    done = 0
    for a, b in zip([0, *(where + 1).tolist()], [*where.tolist(), x.shape[1]], strict=True):
        out[:, done : done + b - a] = x[:, a:b]
        done += b - a
    return out


def summarize(accel: object, mag: object = None, *, trim: bool = False) -> PoseStats:
    """Pose statistics of Sec. 3 for one or both sensors.

    Parameters
    ----------
    accel, mag
        Each a sequence of N arrays of shape (n_i, 3): the raw samples of pose i (same N and
        pose order for both sensors; n_i may differ between poses and sensors). Either may be
        ``None`` (single-sensor calibration), not both.
    trim : bool
        Cut samples that are not still (a bump, a tap) before Eq. 5 and 7
        (:func:`fieldcal.stats.trimming.trim_unsteady`); the counts cut are in ``trimmed``.

    Returns
    -------
    PoseStats
        Means (Eq. 5), counts ``Δ_i`` and the pooled covariance with the generalised Bessel
        correction (Eq. 7), per sensor. One pass over the samples, in cache-sized blocks
        (the values are checked in the same pass); without ``trim`` nothing is copied but a
        block at a time.
    """
    return summarize_scaled(accel, mag, trim=trim, scaled=False)[0]


def summarize_scaled(
    accel: object, mag: object = None, *, trim: bool = False, scaled: bool = True
) -> tuple[PoseStats, dict[str, float], dict[str, list[Array] | None]]:
    """:func:`summarize` for readings divided by an exact power of two per sensor.

    ``fieldcal.calibrate`` fits numbers of order one in any unit
    (:mod:`fieldcal.stats.scaling`). The statistics are computed on the readings as given and
    divided afterwards (exact: a power of two changes no digit), so no scaled copy of the
    samples is made. Returns the statistics, the divisors (1 when ``scaled`` is false) and the
    checked per-pose arrays, unscaled.
    """
    if accel is None and mag is None:
        raise ValueError("no data: pass accelerometer poses, magnetometer poses, or both")
    if not isinstance(trim, (bool, np.bool_)):
        raise ValueError(f"trim must be True or False, got {trim!r}")
    out: dict[str, SensorStats | None] = {"accel": None, "mag": None}
    scratch = _Scratch()
    scales = {"accel": 1.0, "mag": 1.0}
    arrays: dict[str, list[Array] | None] = {"accel": None, "mag": None}
    for name, samples in (("accel", accel), ("mag", mag)):
        if samples is None:
            continue
        poses = _pose_arrays(samples, name)
        # a NaN, inf or overflow is found from the sums and named in one line, not warned of
        with np.errstate(all="ignore"):
            mo, counts, trimmed = _sensor_summary(poses, name, bool(trim), scaled, scratch)
        if scaled and mo.extremes is not None:
            scales[name] = power_of_two(max(-mo.extremes[0], mo.extremes[1]))
        out[name] = _from_moments(mo, counts, trimmed, scales[name])
        arrays[name] = poses
    a, m = out["accel"], out["mag"]
    if a is not None and m is not None and a.n_poses != m.n_poses:
        raise ValueError(
            f"accel has {a.n_poses} poses but mag has {m.n_poses}; pass the same poses, in the "
            "same order, for both sensors"
        )
    return PoseStats(a, m), scales, arrays


def stats_from_means(
    accel_means: ArrayLike | None,
    mag_means: ArrayLike | None = None,
    counts: ArrayLike | None = None,
    accel_cov: ArrayLike | None = None,
    mag_cov: ArrayLike | None = None,
) -> PoseStats:
    """Pose statistics from already-averaged readings (one row per pose), e.g. a logger that
    stores one averaged shot per pose. ``counts`` defaults to 1 per pose; a covariance, when
    known, is that of one raw sample."""

    def one(means: ArrayLike | None, cov: ArrayLike | None, name: str) -> SensorStats | None:
        if means is None:
            return None
        m = as_pose_list([as_readings(means, f"{name} means")], name)[0]
        n = np.ones(len(m), dtype=np.int64) if counts is None else _counts(counts, len(m), name)
        c = None
        if cov is not None:
            c = as_readings(cov, f"{name} covariance")
            if c.shape != (3, 3) or not np.all(np.isfinite(c)):
                raise ValueError(f"{name}: the covariance must be a finite 3x3 array")
        return SensorStats(m, n, c, int(n.sum() - len(n)))

    stats = PoseStats(one(accel_means, accel_cov, "accel"), one(mag_means, mag_cov, "mag"))
    a, m = stats.accel, stats.mag
    if a is not None and m is not None and a.n_poses != m.n_poses:
        raise ValueError(
            f"accel has {a.n_poses} poses but mag has {m.n_poses}; "
            "pass the same poses for both sensors"
        )
    return stats


def _counts(counts: object, n_poses: int, name: str) -> NDArray[np.int64]:
    """Samples per pose: whole numbers of at least 1, one per pose."""
    values = as_readings(counts, f"{name}: counts")
    if values.shape != (n_poses,):
        raise ValueError(f"{name}: counts has shape {values.shape} for {n_poses} poses")
    if not (np.all(np.isfinite(values)) and np.all(values >= 1) and np.all(values % 1 == 0)):
        raise ValueError(f"{name}: counts must be whole numbers of at least 1 (samples per pose)")
    return values.astype(np.int64)


#: Smallest singular value of the centred pose means, relative to the largest, below which the
#: poses are taken to lie on a line (second) or in a plane (third).
FLAT = 0.02


def check_spread(stats: PoseStats) -> None:
    """Refuse poses that cannot determine an ellipsoid: all rotations about one axis.

    Then the pose means of each sensor lie on a circle (a plane) or on a point; the plane's
    normal is, up to the small gain errors, the rotation axis, and poses with that axis tilted
    out of the horizontal plane are what is missing. One-line ``ValueError`` naming it.
    """
    sensors = stats.sensors
    means = np.array([stats.sensor(name).means for name in sensors])  # (S, N, 3)
    centred = means - means.mean(axis=1, keepdims=True)
    # the singular values of the centred means are the square roots of the eigenvalues of
    # their scatter matrix: one 3x3 eigen-decomposition per sensor, both sensors in one call
    # (as every step here: the check runs before each fit)
    lam, vectors = np.linalg.eigh(np.swapaxes(centred, 1, 2) @ centred)
    singular = np.sqrt(np.maximum(lam[:, ::-1], 0.0)).tolist()  # largest first
    sizes = np.abs(means).max(axis=(1, 2)).tolist()
    for name, sv, size, V in zip(sensors, singular, sizes, vectors, strict=True):
        if sv[0] <= 1e-12 * size or sv[1] < FLAT * sv[0]:
            raise ValueError(
                f"degenerate poses: the {name} readings barely change from pose to pose or lie "
                "on a line; turn the device so that each of its axes points up and down in turn"
            )
        if sv[2] < FLAT * sv[0]:
            normal = V[:, 0] * np.sign(V[np.argmax(np.abs(V[:, 0])), 0])
            axis = "xyz"[int(np.argmax(np.abs(normal)))]
            raise ValueError(
                f"degenerate poses: the {name} readings lie in one plane (all rotations about "
                f"one axis, normal ({normal[0]:+.2f}, {normal[1]:+.2f}, {normal[2]:+.2f}) in "
                f"sensor axes, near the {axis} axis); add poses with the {axis} axis tilted up "
                "and down, 45° or more"
            )
