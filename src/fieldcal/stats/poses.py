"""Pose statistics of Sec. 3: per-pose means (Eq. 5), counts Δ_i and pooled covariance (Eq. 7).

Also the input checks every method shares: what a "sequence of N pose arrays" may be and the
one-line errors for what it may not.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._frozen import ArrayDataclass
from .trimming import trim_unsteady

__all__ = [
    "LARGEST",
    "PoseStats",
    "Samples",
    "SensorStats",
    "as_pose_list",
    "as_readings",
    "brief",
    "check_spread",
    "stats_from_means",
    "summarize",
]

Array = NDArray[np.float64]

#: Largest reading accepted: its square (a covariance entry, Eq. 7) must stay a finite float64.
LARGEST = 1e150

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
        total = np.broadcast_to(self.pose_var * np.eye(3), (n, 3, 3)).copy()
        if self.cov is not None:
            total += self.cov[None, :, :] / self.counts[:, None, None]
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
    """Both sensors' summaries; either may be ``None`` for single-sensor calibration."""

    accel: SensorStats | None
    mag: SensorStats | None

    @property
    def n_poses(self) -> int:
        sensor = self.accel if self.accel is not None else self.mag
        return 0 if sensor is None else sensor.n_poses

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensors present, accelerometer first."""
        return tuple(s for s in ("accel", "mag") if getattr(self, s) is not None)

    def sensor(self, name: str) -> SensorStats:
        value: SensorStats | None = getattr(self, name)
        if value is None:
            raise ValueError(f"no {name} poses")
        return value

    def replace(self, **sensors: SensorStats | None) -> PoseStats:
        """The same statistics with some sensors replaced."""
        return dataclasses.replace(self, **sensors)

    def subset(self, index: ArrayLike) -> PoseStats:
        return PoseStats(
            None if self.accel is None else self.accel.subset(index),
            None if self.mag is None else self.mag.subset(index),
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
    return _validated(samples, name)[0]


def _validated(samples: object, name: str) -> tuple[list[Array], Array, NDArray[np.int64]]:
    """The checked poses, their concatenation (a fresh array) and the counts Δ_i."""
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
    stacked = np.concatenate(out, axis=0)
    counts = np.array([len(a) for a in out], dtype=np.int64)
    _check_finite(stacked, counts, name)
    _check_range(stacked, counts, name)
    return out, stacked, counts


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


def _sensor_stats(stacked: Array, counts: NDArray[np.int64], trim: bool) -> SensorStats:
    """Eq. 5 and Eq. 7 in one pass over the concatenated samples (shifted in place), after
    cutting unsteady samples when ``trim``."""
    trimmed = None
    if trim:
        stacked, counts, trimmed = trim_unsteady(stacked, counts)
    # Shift by one reading so the scatter below is computed on numbers of the size of the
    # signal, not of the offset: XᵀX − Σ Δ_i μ_i μ_iᵀ then loses no precision to cancellation.
    shift = stacked[0].copy()
    stacked -= shift
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    sums = np.add.reduceat(stacked, starts, axis=0)
    shifted_means = sums / counts[:, None]
    means = shifted_means + shift  # Eq. 5
    dof = int(counts.sum() - len(counts))
    if dof <= 0:
        return SensorStats(means, counts, None, dof, trimmed=trimmed)
    squares = np.add.reduceat(np.einsum("ij,ij->i", stacked, stacked), starts)
    per_pose = (squares - counts * np.einsum("ij,ij->i", shifted_means, shifted_means)) / (
        3.0 * counts
    )
    scatter = stacked.T @ stacked - sums.T @ shifted_means
    cov = scatter / dof  # Eq. 7
    return SensorStats(
        means, counts, 0.5 * (cov + cov.T), dof, trimmed=trimmed, scatter=np.maximum(per_pose, 0)
    )


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
        correction (Eq. 7), per sensor. Vectorised: the poses are concatenated once and reduced
        with ``np.add.reduceat``.
    """
    if accel is None and mag is None:
        raise ValueError("no data: pass accelerometer poses, magnetometer poses, or both")
    if not isinstance(trim, (bool, np.bool_)):
        raise ValueError(f"trim must be True or False, got {trim!r}")
    a = None if accel is None else _validated(accel, "accel")
    m = None if mag is None else _validated(mag, "mag")
    if a is not None and m is not None and len(a[2]) != len(m[2]):
        raise ValueError(
            f"accel has {len(a[2])} poses but mag has {len(m[2])}; pass the same poses, in the "
            "same order, for both sensors"
        )
    return PoseStats(
        None if a is None else _sensor_stats(*a[1:], trim),
        None if m is None else _sensor_stats(*m[1:], trim),
    )


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
    for name in stats.sensors:
        means = stats.sensor(name).means
        centred = means - means.mean(axis=0)
        _, sv, Vt = np.linalg.svd(centred, full_matrices=False)
        if sv[0] <= 1e-12 * float(np.abs(means).max()) or sv[1] < FLAT * sv[0]:
            raise ValueError(
                f"degenerate poses: the {name} readings barely change from pose to pose or lie "
                "on a line; turn the device so that each of its axes points up and down in turn"
            )
        if sv[2] < FLAT * sv[0]:
            normal = Vt[2] * np.sign(Vt[2][np.argmax(np.abs(Vt[2]))])
            axis = "xyz"[int(np.argmax(np.abs(normal)))]
            raise ValueError(
                f"degenerate poses: the {name} readings lie in one plane (all rotations about "
                f"one axis, normal ({normal[0]:+.2f}, {normal[1]:+.2f}, {normal[2]:+.2f}) in "
                f"sensor axes, near the {axis} axis); add poses with the {axis} axis tilted up "
                "and down, 45° or more"
            )
