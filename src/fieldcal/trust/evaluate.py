"""Eq. 8's model evaluated at any method's calibration: residuals, leverage and error bars.

Every method's result goes through here, so the certificate, the pose tests and the Cramér-Rao
error bars are computed one way whichever method produced the parameters. The residuals are
whitened by each pose mean's covariance ``C_si = Σ_s/Δ_si + Q_s`` (the stats' noise model).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..likelihood.cramer_rao import Uncertainty, uncertainty
from ..likelihood.levenberg import normal_equations
from ..likelihood.pose_model import (
    Problem,
    build_problem,
    model_readings,
    raw_residuals,
    rotated_fields,
    whiten,
)
from ..methods.mle import state_from_calibration
from ..stats.pose_stats import PoseStats

__all__ = ["Evaluation", "evaluate"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Evaluation:
    """The model at one calibration and noise model.

    Attributes
    ----------
    problem : Problem
        The whitened problem (parameter layout, degrees of freedom).
    whitened : (N, 3·#sensors) array
        Whitened residuals ``L_si⁻¹ (K_s R_i f_s + b_s − μ̂_si)``, accelerometer block first.
    raw : dict of (N, 3) arrays
        The same residuals in raw units, per sensor.
    uncertainty : Uncertainty
        Cramér-Rao covariance of the named parameters, condition number, leverage blocks.
    directions : dict of (N, 3) arrays
        Unit direction of each sensor's field in raw coordinates, ``K_s R_i f_s``, per pose.
    """

    problem: Problem
    whitened: Array
    raw: dict[str, Array]
    uncertainty: Uncertainty
    directions: dict[str, Array]

    @property
    def dof(self) -> int:
        return self.problem.dof

    def block(self, sensor: str) -> slice:
        k = self.problem.sensors.index(sensor)
        return slice(3 * k, 3 * k + 3)

    @functools.cached_property
    def pose_cost(self) -> Array:
        """Each pose's term of Eq. 8 (both sensors); computed once, read-only."""
        cost = np.asarray(np.einsum("ni,ni->n", self.whitened, self.whitened))
        cost.setflags(write=False)
        return cost

    def sensor_cost(self, sensor: str) -> float:
        """Sensor ``sensor``'s part of Eq. 8's J."""
        e = self.whitened[:, self.block(sensor)]
        return float(np.sum(e * e))

    def dof_share(self) -> dict[str, float]:
        """Each sensor's expected part of J, ``3N − tr(H_ss)`` (computed once)."""
        return dict(self._dof_share)

    @functools.cached_property
    def _dof_share(self) -> dict[str, float]:
        return self.uncertainty.dof_share(self.problem)


def evaluate(cal: Calibration, stats: PoseStats, body_frame: str) -> Evaluation:
    """Residuals, leverage and the Cramér-Rao covariance of ``cal`` on ``stats``.

    ``cal`` must have unit fields (the methods' own output) and the poses of ``stats``.
    """
    problem = build_problem(stats, body_frame)
    state = state_from_calibration(problem, cal)
    VV = rotated_fields(problem, state)  # R_i f_s: the readings' and the Jacobian's
    readings = model_readings(problem, state, VV)  # K_s R_i f_s, both sensors
    norms = np.sqrt(np.vecdot(readings, readings))[..., None]
    unit = readings / norms
    raw_all = raw_residuals(problem, state, readings)  # the readings become the residuals
    e = whiten(problem, raw_all)
    ne = normal_equations(problem, state, e, VV)
    raw = {s: raw_all[k] for k, s in enumerate(problem.sensors)}
    directions = {s: unit[k] for k, s in enumerate(problem.sensors)}
    return Evaluation(problem, e, raw, uncertainty(problem, ne), directions)
