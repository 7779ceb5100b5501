"""The gyroscope's calibration as a result: :class:`GyroFit` and its parameters' names."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._frozen import ArrayDataclass, frozen_array
from ..calibration import ParameterCovariance, SensorCalibration
from ..thermal import TemperatureModel

__all__ = ["BIAS_NAMES", "GAIN_NAMES", "GyroFit"]

Array = NDArray[np.float64]

#: Covariance names of the gyroscope's parameters, in the order of :attr:`GyroFit.covariance`.
GAIN_NAMES = tuple(f"gyro.gain[{j},{k}]" for j in range(3) for k in range(3))
BIAS_NAMES = tuple(f"gyro.bias[{j}]" for j in range(3))


@dataclass(frozen=True, eq=False)
class GyroFit(ArrayDataclass):
    """A gyroscope calibration: ``raw = gain @ ω + bias``, ``ω`` in rad/s in the body frame.

    Attributes
    ----------
    gain : (3, 3) array
        ``K_g``, raw units per rad/s: scale, cross-axis coupling and misalignment to the body
        frame of the rotations (or gravity directions) it was fitted to.
    bias : (3,) array
        ``b_g``, raw units: the still poses' biases averaged with their durations as weights.
    noise_cov : (3, 3) array
        Covariance of one raw sample (pooled scatter within the still poses), raw units².
    covariance : ParameterCovariance
        Cramér-Rao covariance of ``gyro.gain[j,k]`` and ``gyro.bias[j]`` (0-based) at the
        optimum, widened by :attr:`widening`; only the :attr:`observable` entries.
    pose_bias : (N, 3) array
        Each still pose's mean raw rate.
    pose_time : (N,) array
        Each still pose's mean time (s).
    pose_duration : (N,) array
        Each still pose's duration (s): its mean's variance is ``rate_noise / duration`` plus
        the wander.
    drift : float or None
        ``|s|`` of the straight line ``p_i ≈ b + s t`` through :attr:`pose_bias`, raw units per
        second (``None`` with fewer than 3 poses); its vector is :attr:`drift_rate`, its
        significance :attr:`drift_p_value`.
    segment_residual_deg : (M,) array
        Per motion segment, after calibration: the angle between the integrated and the
        fitted rotation (``"rotations"``), or between the predicted and the observed gravity
        direction (``"gravity"``), degrees.
    segments : tuple of (int, int)
        Rows ``(first, last)`` of each motion segment used: from the last row of one pose to
        the first row of the next.
    observable : tuple of str
        The parameter names the data determine (all twelve unless ``allow_partial``).
    method : str
        ``"rotations"`` (orientations from the joint fit) or ``"gravity"`` (accelerometer only).
    drift_rate : (3,) array or None
        The drift line's slope per axis, raw units per second.
    drift_p_value : float or None
        Probability of a slope at least this large with a constant bias (small: it drifts).
    bias_wander : float
        Standard deviation per axis of the still poses' biases about the drift line beyond
        their white noise (raw units; 0 when the data show none).
    rate_noise : (3, 3) array
        ``Q``: the rate's noise density, raw units² · s (``Var ∫ε dt = Q T``).
    statistic, dof, p_value : float, int, float
        The segments' χ² at the optimum, its degrees of freedom (residuals − 9) and upper tail.
    widening : float
        Factor the Cramér-Rao covariance was multiplied by (1: not widened).
    iterations : int
        Gauss-Newton iterations, all rounds.
    converged : bool
        Whether the last round converged.
    rejected : tuple of (int, int)
        Rows of the motion segments left out because they fail their test (a residual beyond
        the χ² quantile ``1 − 0.01/M``): a jump in the log, a bump, a pose whose orientation
        the joint fit got wrong. At most half of them; the worst first, refitting each time.
    rejected_residual_deg : (R,) array
        Their residual angles at the final gain, degrees.
    temperature : TemperatureModel or None
        The bias against temperature (:func:`.gyro_temperature.with_bias_temperature`): with
        terms, :attr:`bias` is the bias at its reference temperature and :attr:`covariance`
        holds ``gyro.temp[k,j]``; ``None`` without temperatures.
    temperature_record : dict
        How the order was chosen (``cal.options["gyro"]["temperature"]``); empty without.
    """

    gain: Array
    bias: Array
    noise_cov: Array
    covariance: ParameterCovariance
    pose_bias: Array
    pose_time: Array
    drift: float | None
    segment_residual_deg: Array
    segments: tuple[tuple[int, int], ...]
    observable: tuple[str, ...]
    method: str
    drift_rate: Array | None = None
    drift_p_value: float | None = None
    bias_wander: float = 0.0
    rate_noise: Array = field(default_factory=lambda: np.zeros((3, 3)))
    statistic: float = 0.0
    dof: int = 0
    p_value: float = 1.0
    widening: float = 1.0
    iterations: int = 0
    converged: bool = True
    rejected: tuple[tuple[int, int], ...] = ()
    rejected_residual_deg: Array = field(default_factory=lambda: np.zeros(0))
    pose_duration: Array = field(default_factory=lambda: np.zeros(0))
    temperature: TemperatureModel | None = None
    temperature_record: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        arrays = ("gain", "bias", "noise_cov", "pose_bias", "pose_time", "rate_noise")
        for name in (*arrays, "pose_duration"):
            object.__setattr__(self, name, frozen_array(getattr(self, name)))
        object.__setattr__(self, "segment_residual_deg", frozen_array(self.segment_residual_deg))
        if self.drift_rate is not None:
            object.__setattr__(self, "drift_rate", frozen_array(self.drift_rate))
        object.__setattr__(self, "segments", tuple((int(a), int(b)) for a, b in self.segments))
        object.__setattr__(self, "rejected", tuple((int(a), int(b)) for a, b in self.rejected))
        object.__setattr__(self, "rejected_residual_deg", frozen_array(self.rejected_residual_deg))
        object.__setattr__(self, "observable", tuple(self.observable))

    @property
    def gain_std(self) -> Array:
        """Standard error of each gain entry (NaN where not :attr:`observable`)."""
        return np.array(
            [self.covariance.std(n) if n in self.observable else np.nan for n in GAIN_NAMES]
        ).reshape(3, 3)

    @property
    def bias_std(self) -> Array:
        """Standard error of each bias entry."""
        return np.array([self.covariance.std(n) for n in BIAS_NAMES])

    @property
    def sensor(self) -> SensorCalibration:
        """The gyroscope as a calibration's sensor (``cal.gyro``): gain, bias, noise."""
        return SensorCalibration(
            gain=self.gain, bias=self.bias, noise_cov=self.noise_cov, temperature=self.temperature
        )

    def correct(self, raw: ArrayLike, temperature: ArrayLike | None = None) -> Array:
        """Raw readings (..., 3) → body-frame rate in rad/s, ``gain⁻¹ (raw − bias)``, with
        ``temperature`` (°C) the bias at it (:meth:`SensorCalibration.correct`)."""
        return self.sensor.correct(raw, temperature)
