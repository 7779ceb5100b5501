"""Synthetic calibration sessions drawn as in the seed paper's Table 1 and Eq. 18.

``simulate(preset="paper")`` reproduces Sec. 6.2: N = 15 poses with uniformly random rotations
(Kuffner 2004), ``Δ_i ~ U{400..600}`` samples per pose (the same for both sensors),
``g_z ~ U[−1.5, −0.5]``, ``h_x ~ U[0.5, 1.5]``, ``h_z ~ U[−1.5, 1.5]``, biases ``U[−1, 1]``,
gains ``I + δK`` with ``δK_ij ~ U[−0.1, 0.1]``, and covariances ``α (…)`` of Eq. 18 with
``α ~ U[1e-4, 1e-2]``. Other presets stress what the paper does not.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TypedDict, Unpack, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._frozen import ArrayDataclass
from ..calibration import Calibration, SensorCalibration
from ..geometry.gauge import canonical_gauge
from ..geometry.rotations import exp_so3, random_rotations

__all__ = ["PRESETS", "Drawn", "Preset", "Session", "SimulateOptions", "simulate"]

Array = NDArray[np.float64]


class SimulateOptions(TypedDict, total=False):
    """The drawing ranges :func:`simulate` takes as keywords (described there)."""

    samples: tuple[int, int]
    gravity_z: tuple[float, float]
    field_x: tuple[float, float]
    field_z: tuple[float, float]
    dip_deg: tuple[float, float] | None
    bias: float
    gain_spread: float
    noise_alpha: tuple[float, float]
    pose_distribution: str
    mag_axes: ArrayLike | None
    pose_noise: float | tuple[float, float]


class Preset(SimulateOptions, total=False):
    """A preset: the number of poses and every drawing range."""

    n_poses: int


class Drawn(TypedDict, total=False):
    """The parameters of a :class:`Session` exactly as drawn (the paper's gauge)."""

    accel_gain: Array
    mag_gain: Array
    accel_bias: Array
    mag_bias: Array
    gravity: Array
    magnetic: Array
    rotations: Array
    accel_cov: Array
    mag_cov: Array
    counts: NDArray[np.int64]
    seed: int | None
    preset: str


#: Drawing ranges per preset. Every key can be overridden by a keyword of :func:`simulate`.
PRESETS: dict[str, Preset] = {
    "paper": {
        "n_poses": 15,
        "samples": (400, 600),
        "gravity_z": (-1.5, -0.5),
        "field_x": (0.5, 1.5),
        "field_z": (-1.5, 1.5),
        "dip_deg": None,
        "bias": 1.0,
        "gain_spread": 0.1,
        "noise_alpha": (1e-4, 1e-2),
        "pose_distribution": "uniform",
        "mag_axes": None,
        "pose_noise": (0.0, 0.0),
    },
}
# Harder settings than Table 1 (the mle benchmark): each changes one thing, "hard" all at once.
_PAPER = PRESETS["paper"]
PRESETS["few_poses"] = {**_PAPER, "n_poses": 8, "samples": (30, 60)}
PRESETS["soft_iron"] = {**_PAPER, "gain_spread": 0.35, "bias": 3.0}
PRESETS["steep_dip"] = {**_PAPER, "dip_deg": (75.0, 85.0)}
PRESETS["handheld"] = {**_PAPER, "pose_distribution": "handheld"}
PRESETS["noisy"] = {**_PAPER, "noise_alpha": (1e-2, 5e-2)}
PRESETS["hard"] = {
    **_PAPER,
    "n_poses": 10,
    "samples": (30, 60),
    "gain_spread": 0.35,
    "bias": 3.0,
    "dip_deg": (75.0, 85.0),
    "pose_distribution": "handheld",
    "noise_alpha": (1e-2, 5e-2),
}


@dataclass(frozen=True, eq=False)
class Session(ArrayDataclass):
    """A simulated session.

    Attributes
    ----------
    accel, mag : list of (n_i, 3) arrays
        Raw samples per pose, ready for :func:`fieldcal.calibrate`.
    truth : Calibration
        The true parameters, re-expressed in fieldcal's gauge (unit fields, NED world frame,
        symmetric accelerometer gain) so they compare directly with an estimate;
        ``truth.noise_cov`` holds the true ``Σ_s``. ``truth.predicted_means()`` gives ``μ_s[i]``.
    drawn : dict
        The parameters exactly as drawn (``accel_gain``, ``mag_gain``, ``accel_bias``,
        ``mag_bias``, ``gravity``, ``magnetic``, ``rotations``, ``accel_cov``, ``mag_cov``,
        ``counts``, ``seed``, ``preset``).
    """

    accel: list[Array]
    mag: list[Array]
    truth: Calibration
    drawn: Drawn = field(default_factory=lambda: Drawn())

    @property
    def counts(self) -> NDArray[np.int64]:
        return np.asarray(self.drawn["counts"])

    def write_csv(self, path: str | os.PathLike[str], preamble: str = "") -> None:
        """The session as ``fieldcal simulate`` writes it: a ``pose`` column and one block of
        rows per pose (``pose,ax,ay,az,mx,my,mz``), with ``preamble`` (whole lines, each ending
        in a newline, such as a ``# device: IMU-7`` line) above the header."""
        data = np.column_stack(
            [
                np.repeat(np.arange(len(self.counts)), self.counts),
                *map(np.concatenate, (self.accel, self.mag)),
            ]
        )
        header = preamble + "pose,ax,ay,az,mx,my,mz"
        fmt = ["%d"] + ["%.9g"] * 6
        np.savetxt(path, data, delimiter=",", header=header, comments="", fmt=fmt)


def _covariance(rng: np.random.Generator, alpha_range: tuple[float, float]) -> Array:
    """Eq. 18: diagonal ~ U[0.5, 2], off-diagonal ~ U[−0.2, 0.2] (symmetric), times α."""
    cov = np.diag(rng.uniform(0.5, 2.0, 3))
    off = rng.uniform(-0.2, 0.2, 3)
    cov[0, 1] = cov[1, 0] = off[0]
    cov[0, 2] = cov[2, 0] = off[1]
    cov[1, 2] = cov[2, 1] = off[2]
    return rng.uniform(*alpha_range) * cov


def _handheld_rotations(n: int, rng: np.random.Generator) -> Array:
    """Hand-held poses: tilt mostly under 60° (any heading), two roughly upside down."""
    n_flip = min(2, max(n - 6, 0))
    tilt = np.radians(rng.uniform(0.0, 60.0, n))
    tilt[:n_flip] = np.radians(rng.uniform(150.0, 180.0, n_flip))
    azimuth = rng.uniform(0.0, 2.0 * np.pi, n)
    heading = rng.uniform(0.0, 2.0 * np.pi, n)
    tilt_axis = np.stack([np.cos(azimuth), np.sin(azimuth), np.zeros(n)], axis=-1)
    yaw = np.stack([np.zeros(n), np.zeros(n), heading], axis=-1)
    R = exp_so3(tilt_axis * tilt[:, None]) @ exp_so3(yaw)
    return R[rng.permutation(n)]


def simulate(
    preset: str = "paper",
    *,
    seed: int | None = None,
    n_poses: int | None = None,
    **overrides: Unpack[SimulateOptions],
) -> Session:
    """Draw a synthetic session.

    Parameters
    ----------
    preset : str
        A key of :data:`PRESETS` (``"paper"``: Table 1 of the seed paper).
    seed : int
        Seed of the ``numpy.random.default_rng`` that draws everything.
    n_poses : int, optional
        Number of poses N (Table 1: 15).
    **overrides
        Every other key of the preset: ``samples`` (min, max) per pose, ``gravity_z``,
        ``field_x``, ``field_z`` ranges, ``dip_deg`` (min, max) to draw the field from a dip
        instead, ``bias`` half-range, ``gain_spread`` half-range of δK, ``noise_alpha`` range,
        ``pose_distribution`` ("uniform" or "handheld"), ``mag_axes`` (3x3 signed permutation
        applied to the magnetometer's axes, e.g. to mirror it), ``pose_noise`` (accelerometer,
        magnetometer): the standard deviation per axis, raw units, of an offset shared by all
        samples of a pose (the pose-level noise ``Q = q² I``; drawn after everything else, so
        a seed gives the same session with or without it).
    """
    if not isinstance(preset, str) or preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}")
    known = PRESETS[preset]
    unknown = set(overrides) - set(known)
    if unknown:
        raise ValueError(f"unknown simulate option(s) {sorted(unknown)}; known: {sorted(known)}")
    params: Preset = {**known, **overrides}
    if n_poses is not None:
        params["n_poses"] = n_poses
    _check(params, seed)
    n = int(params["n_poses"])
    rng = np.random.default_rng(seed)

    # Table 1, in the paper's order of description.
    counts = rng.integers(params["samples"][0], params["samples"][1] + 1, n)
    if params["pose_distribution"] == "uniform":
        rotations = random_rotations(n, rng)
    elif params["pose_distribution"] == "handheld":
        rotations = _handheld_rotations(n, rng)
    else:
        raise ValueError("pose_distribution must be 'uniform' or 'handheld'")
    gravity, magnetic = _fields(rng, params)

    def sensor() -> tuple[Array, Array, Array]:
        bias = rng.uniform(-params["bias"], params["bias"], 3)
        gain = np.eye(3) + rng.uniform(-params["gain_spread"], params["gain_spread"], (3, 3))
        return gain, bias, _covariance(rng, params["noise_alpha"])

    Ka, ba, Sa = sensor()
    Km, bm, Sm = sensor()
    if params["mag_axes"] is not None:
        Km = np.asarray(params["mag_axes"], dtype=float) @ Km

    def draw(gain: Array, bias: Array, cov: Array, reference: Array) -> list[Array]:
        means = np.einsum("ij,njk,k->ni", gain, rotations, reference) + bias
        noise = rng.standard_normal((int(counts.sum()), 3))
        samples = np.repeat(means, counts, axis=0)
        if np.any(cov):  # noise_alpha = (0, 0) gives noise-free samples
            samples = samples + noise @ np.linalg.cholesky(cov).T
        return np.split(samples, np.cumsum(counts)[:-1])

    accel = draw(Ka, ba, Sa, gravity)
    mag = draw(Km, bm, Sm, magnetic)
    q_a, q_m = _add_pose_noise(rng, accel, mag, params)

    R, Ka_c, Km_c, g_c, h_c = canonical_gauge(rotations, Ka, Km, gravity, magnetic)
    truth = Calibration(
        accel=SensorCalibration(gain=Ka_c, bias=ba, noise_cov=Sa, pose_noise_std=q_a),
        mag=SensorCalibration(gain=Km_c, bias=bm, noise_cov=Sm, pose_noise_std=q_m),
        gravity=g_c,
        magnetic=h_c,
        rotations=R,
        method="truth",
        options={"preset": preset, "seed": seed, **_jsonable(params)},
    )
    drawn: Drawn = {
        "accel_gain": Ka,
        "mag_gain": Km,
        "accel_bias": ba,
        "mag_bias": bm,
        "gravity": gravity,
        "magnetic": magnetic,
        "rotations": rotations,
        "accel_cov": Sa,
        "mag_cov": Sm,
        "counts": counts,
        "seed": seed,
        "preset": preset,
    }
    return Session(accel=accel, mag=mag, truth=truth, drawn=drawn)


def _fields(rng: np.random.Generator, params: Preset) -> tuple[Array, Array]:
    """Gravity and the magnetic field in the world frame (Table 1: ``gravity_z``, ``field_x``,
    ``field_z``; or a field of strength ``field_x`` at a dip drawn from ``dip_deg``)."""
    g_z = rng.uniform(*params["gravity_z"])
    if params["dip_deg"] is None:
        h_x, h_z = rng.uniform(*params["field_x"]), rng.uniform(*params["field_z"])
    else:
        dip = np.radians(rng.uniform(*params["dip_deg"]))
        strength = rng.uniform(*params["field_x"])
        h_x, h_z = strength * np.cos(dip), strength * np.sin(dip)
    gravity = np.array([0.0, 0.0, g_z])
    magnetic = np.array([h_x, 0.0, h_z])
    return gravity, magnetic


def _add_pose_noise(
    rng: np.random.Generator, accel: list[Array], mag: list[Array], params: Preset
) -> tuple[float, float]:
    """Add each pose's shared offset (``pose_noise``: the standard deviations per axis of the
    accelerometer's and the magnetometer's) to its samples, in place; the two deviations."""
    n = len(accel)
    q_a, q_m = (float(q) for q in np.broadcast_to(params["pose_noise"], (2,)))
    for samples, q in ((accel, q_a), (mag, q_m)):
        if q > 0:
            offsets = rng.normal(0.0, q, (n, 3))
            for pose, offset in zip(samples, offsets, strict=True):
                pose += offset
    return q_a, q_m


def _whole(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _real(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def _pair(value: object, kind: Callable[[object], bool]) -> bool:
    """A (low, high) pair of ``kind`` with low <= high, both finite."""
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        return False
    low, high = value
    return kind(low) and kind(high) and bool(np.isfinite([low, high]).all()) and low <= high


def _check(params: Preset, seed: object) -> None:
    """Refuse an option :func:`simulate` cannot draw from, in one line naming it and its form."""
    if seed is not None and not (_whole(seed) and int(cast(int, seed)) >= 0):
        raise ValueError(f"seed must be a whole number >= 0 or None, got {seed!r}")
    if not (_whole(params["n_poses"]) and params["n_poses"] >= 1):
        raise ValueError(f"n_poses must be a whole number >= 1, got {params['n_poses']!r}")
    samples = params["samples"]
    if not (_pair(samples, _whole) and samples[0] >= 1):
        raise ValueError(
            f"samples must be (min, max) whole numbers with 1 <= min <= max, got {samples!r}"
        )
    for name in ("gravity_z", "field_x", "field_z", "noise_alpha"):
        if not _pair(params[name], _real):
            raise ValueError(f"{name} must be a (low, high) pair of finite numbers, low <= high")
    if params["noise_alpha"][0] < 0:
        raise ValueError("noise_alpha must be >= 0 (a range of noise variances' scale)")
    dip = params["dip_deg"]
    if dip is not None and not (_pair(dip, _real) and -90.0 <= dip[0] and dip[1] <= 90.0):
        raise ValueError(f"dip_deg must be None or a (low, high) pair in [-90, 90], got {dip!r}")
    for name in ("bias", "gain_spread"):
        value = params[name]  # type: ignore[literal-required]
        if not (_real(value) and np.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    noise = params["pose_noise"]
    pair = noise if isinstance(noise, (tuple, list)) else (noise, noise)
    if len(pair) != 2 or not all(_real(q) and np.isfinite(q) and q >= 0 for q in pair):
        raise ValueError(
            "pose_noise must be a finite number >= 0 or an (accelerometer, magnetometer) pair "
            f"of them, got {noise!r}"
        )
    axes = params["mag_axes"]
    if axes is not None:
        try:
            matrix = np.asarray(axes, dtype=float)
        except (TypeError, ValueError):
            matrix = np.empty(0)
        if matrix.shape != (3, 3) or not np.isfinite(matrix).all():
            raise ValueError("mag_axes must be a 3x3 matrix (a signed permutation) or None")


def _jsonable(params: Mapping[str, object]) -> dict[str, object]:
    return {k: (np.asarray(v).tolist() if v is not None else None) for k, v in params.items()}
