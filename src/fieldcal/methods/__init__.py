"""Estimators: one registry that validates and dispatches, one module per estimator.

Three kinds of estimator share it (:attr:`Method.takes`): the pose methods (``mle``, ``greedy``,
``ellipsoid``: pose statistics in, :data:`METHODS`), the continuous-motion estimator
(``continuous``: a log's time, field sensors and gyroscope) and the gyroscope stage (``gyro``:
the motion between a pose calibration's poses). Each returns a
:class:`~fieldcal.calibration.Calibration` with its typed findings
(:attr:`~fieldcal.calibration.Calibration.findings`); the verdict's rules
(:mod:`fieldcal.trust.verdict`) judge them, the same for all. :data:`ESTIMATORS` holds every
one; :func:`estimator` finds one by name, whatever its kind.

A method is a function
``fit(stats, *, raw_accel, raw_mag, body_frame, progress, <options>) -> Calibration`` from pose
statistics (:mod:`fieldcal.stats.pose_stats`) to a calibration in fieldcal's gauge with unit fields;
``progress`` (``None`` or a callable taking one line of text) hears about long work. Its
options are keyword-only parameters with defaults, so its signature documents them and
:meth:`Method.check_options` rejects unknown ones. The shared path (:mod:`fieldcal.trust`)
then adds the noise model, the certificate, the error bars and the verdict, the same for every
method.

To add a method: write ``fieldcal/methods/<name>.py`` with ``fit`` and add one :class:`Method`
to :data:`METHODS`. The CLI's ``--method`` choices, :func:`fieldcal.calibrate`'s validation
and ``docs/architecture.md``'s table come from here.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from ..settings import OPTIONS
from ..stats.pose_stats import brief

if TYPE_CHECKING:
    from ..calibration import Calibration

__all__ = ["ESTIMATORS", "METHODS", "Method", "Takes", "estimator", "get"]

#: What an estimator takes: pose statistics, a log's continuous motion (time, accelerometer,
#: magnetometer, gyroscope), or a pose calibration and the motion between its poses.
Takes = Literal["poses", "motion", "poses and motion"]

#: Parameters of every ``fit`` that are the shared path's, not user options.
PROTOCOL = ("stats", "raw_accel", "raw_mag", "body_frame", "progress")


@dataclass(frozen=True)
class Method:
    """What callers need to know of a method, without importing it.

    Attributes
    ----------
    name : str
        The registry name (``method=`` in :func:`fieldcal.calibrate`).
    module : str
        The module that defines ``fit``, imported on first use.
    summary : str
        One line for help texts and docs.
    min_poses : int
        Fewest poses for a joint (two-sensor) calibration.
    min_poses_single : int or None
        Fewest poses with one sensor; ``None`` when the method needs both sensors.
    continuous : bool
        Whether it also takes continuous (n, 3) samples instead of poses.
    warm_start : bool
        Whether ``fit`` takes ``initial=`` (a Calibration to start from).
    pose_weights : bool
        Whether the fit weighs each pose mean by its own covariance ``Σ/Δ_i + Q`` (then the
        pose-level noise is estimated jointly, refitting; otherwise it is estimated at the
        method's result).
    raw_samples : bool
        Whether ``fit`` reads the raw samples (``raw_accel``, ``raw_mag``); when not, they
        are passed as ``None`` and :func:`fieldcal.calibrate` makes no scaled copy of them.
    temperature : bool
        Whether ``fit`` estimates the temperature terms ``stats.temperature`` asks for (each
        sensor's bias polynomial in ``T − T_ref``, :mod:`fieldcal.likelihood.temperature`).
    takes : {"poses", "motion", "poses and motion"}
        What it takes (:data:`Takes`).
    entry : str
        The name of its function in ``module`` (``fit`` for the pose methods).
    path : str
        The estimation path whose options it reads (``Option.paths`` in
        :mod:`fieldcal.settings`: ``"poses"`` or ``"continuous"``).
    """

    name: str
    module: str
    summary: str
    min_poses: int
    min_poses_single: int | None
    continuous: bool = False
    warm_start: bool = False
    pose_weights: bool = False
    raw_samples: bool = True
    temperature: bool = False
    takes: Takes = "poses"
    entry: str = "fit"
    path: str = "poses"

    def load(self) -> Callable[..., Calibration]:
        """The estimator's function (imports its module)."""
        fit: Callable[..., Calibration] = getattr(importlib.import_module(self.module), self.entry)
        return fit

    def fit(self, *args: object, **kwargs: object) -> Calibration:
        """Call the estimator (``estimator("continuous").fit(time, accel, mag, gyro)``): its
        function's parameters, documented there."""
        return self.load()(*args, **kwargs)

    def settings(self) -> tuple[str, ...]:
        """The options of :mod:`fieldcal.settings` it reads (their ``paths`` name its path),
        by library keyword."""
        return tuple(name for name, option in OPTIONS.items() if self.path in option.paths)

    def options(self) -> dict[str, object]:
        """The method's options and their defaults, from ``fit``'s signature."""
        params = inspect.signature(self.load()).parameters.values()
        return {
            p.name: p.default
            for p in params
            if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name not in PROTOCOL
        }

    def check_options(self, options: Mapping[str, object]) -> None:
        """One-line ``ValueError`` for an option ``fit`` does not take."""
        known = self.options()
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise ValueError(
                f"unknown option(s) {', '.join(map(repr, unknown))} for method {self.name!r}; "
                f"known: {', '.join(known) or 'none'}"
            )

    def min_poses_for(self, n_sensors: int) -> int:
        if n_sensors == 1 and self.min_poses_single is not None:
            return self.min_poses_single
        return self.min_poses


ESTIMATORS: dict[str, Method] = {
    m.name: m
    for m in (
        Method(
            "mle",
            "fieldcal.methods.mle",
            "joint maximum likelihood from a closed-form global start (default)",
            min_poses=8,
            min_poses_single=10,
            warm_start=True,
            pose_weights=True,
            raw_samples=False,
            temperature=True,
        ),
        Method(
            "greedy",
            "fieldcal.methods.greedy",
            "the seed paper's greedy algorithm (Miranda & Ferreira, Sec. 5), as published",
            min_poses=8,
            min_poses_single=None,
            raw_samples=False,
        ),
        Method(
            "ellipsoid",
            "fieldcal.methods.ellipsoid",
            "per-sensor ellipsoid fits and dot-product alignment (CK-Explorer)",
            min_poses=9,
            min_poses_single=9,
            continuous=True,
        ),
        Method(
            "continuous",
            "fieldcal.methods.continuous",
            "every sample of a log in continuous motion, the gyroscope tying the orientations "
            "together (--poses continuous)",
            min_poses=0,
            min_poses_single=None,
            temperature=True,
            takes="motion",
            entry="fit_continuous",
            path="continuous",
        ),
        Method(
            "gyro",
            "fieldcal.gyro.stage",
            "the gyroscope's gain and bias from the motion between a pose calibration's poses",
            min_poses=2,
            min_poses_single=2,
            takes="poses and motion",
            entry="gyro_stage",
        ),
    )
}
#: The pose methods (``method=``, ``--method``): the estimators that take pose statistics.
METHODS: dict[str, Method] = {n: m for n, m in ESTIMATORS.items() if m.takes == "poses"}


def get(name: object) -> Method:
    """The registered pose method called ``name``; a one-line error listing the names
    otherwise."""
    if not isinstance(name, str) or name not in METHODS:
        raise ValueError(f"unknown method {brief(name)}; choose one of {', '.join(METHODS)}")
    return METHODS[name]


def estimator(name: object) -> Method:
    """The registered estimator called ``name``, of any kind (:data:`ESTIMATORS`); a one-line
    error listing the names otherwise.

    Examples
    --------
    >>> import fieldcal
    >>> fieldcal.estimator("continuous").takes
    'motion'
    """
    if not isinstance(name, str) or name not in ESTIMATORS:
        raise ValueError(f"unknown estimator {brief(name)}; choose one of {', '.join(ESTIMATORS)}")
    return ESTIMATORS[name]
