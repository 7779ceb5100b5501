"""Each pose's mean temperature and the temperature terms a fit carries (orders per sensor).

The pose statistics of Eq. 5 gain one number per pose: the mean of the temperature column
over the pose's samples. :class:`PoseTemperature` holds those means, the reference temperature
(their mean) and the polynomial order of each sensor's bias in ``T − T_ref`` (0: no term), which
:func:`fieldcal.likelihood.pose_model.build_problem` turns into parameters.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._frozen import ArrayDataclass, frozen_array
from ..limits import PLAUSIBLE_C as _PLAUSIBLE_C

__all__ = ["PoseTemperature", "pose_temperatures"]

Array = NDArray[np.float64]

#: The hottest and coldest die temperature taken (°C): beyond is a wrong column or unit.
PLAUSIBLE_C = _PLAUSIBLE_C


@dataclass(frozen=True, eq=False)
class PoseTemperature(ArrayDataclass):
    """The poses' mean temperatures and the fitted temperature terms.

    Attributes
    ----------
    means : (N,) array
        Mean temperature of each pose, °C.
    orders : dict of str to int
        Polynomial order of each sensor's bias in ``T − reference`` (missing: 0).
    refused : bool
        The span was too small to fit any term (:mod:`fieldcal.likelihood.temperature`).
    """

    means: Array
    orders: Mapping[str, int] = field(default_factory=dict)
    refused: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "means", frozen_array(self.means))
        object.__setattr__(self, "orders", {s: int(k) for s, k in self.orders.items() if k})

    @property
    def reference(self) -> float:
        """``T_ref``: the mean of the poses' temperatures."""
        return float(np.mean(self.means))

    @property
    def span(self) -> Array:
        """(lowest, highest) pose temperature."""
        return np.array([self.means.min(), self.means.max()])

    def order(self, sensor: str) -> int:
        return int(self.orders.get(sensor, 0))

    def powers(self, order: int) -> Array:
        """(N, order): ``(T_i − T_ref)^k`` for k = 1..order."""
        d = self.means - self.reference
        return np.asarray(d[:, None] ** np.arange(1, order + 1)[None, :], dtype=float)

    def with_orders(self, orders: Mapping[str, int], refused: bool = False) -> PoseTemperature:
        return PoseTemperature(self.means, dict(orders), refused)

    def subset(self, index: ArrayLike) -> PoseTemperature:
        """The same terms on a subset of the poses (the reference moves with the poses kept)."""
        return dataclasses.replace(self, means=self.means[np.asarray(index)])


def pose_temperatures(temperature: Sequence[ArrayLike], n_poses: int) -> Array:
    """Each pose's mean temperature from its samples (N arrays of (n_i,)), checked: one
    array per pose, finite values in :data:`PLAUSIBLE_C`; one-line ``ValueError`` otherwise."""
    if isinstance(temperature, (str, bytes)) or not isinstance(temperature, Sequence | np.ndarray):
        raise ValueError(
            "temperature must be one array of samples (°C) per pose, like accel and mag"
        )
    if len(temperature) != n_poses:
        raise ValueError(
            f"temperature has {len(temperature)} poses but the readings have {n_poses}; pass "
            "one array of temperatures per pose, in the same order"
        )
    means = np.empty(n_poses)
    for i, pose in enumerate(temperature):
        try:
            values = np.asarray(pose, dtype=float).ravel()
        except (TypeError, ValueError):
            raise ValueError(f"temperature: pose {i} is not an array of numbers") from None
        if values.size == 0 or not np.isfinite(values).all():
            raise ValueError(f"temperature: pose {i} is empty or has NaN/inf values")
        means[i] = float(values.mean())
    low, high = PLAUSIBLE_C
    if means.min() < low or means.max() > high:
        raise ValueError(
            f"temperature: pose means from {means.min():.4g} to {means.max():.4g} are outside "
            f"{low:g}..{high:g} °C; give the temperature column in °C (or leave it out)"
        )
    return means
