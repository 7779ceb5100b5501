"""Calibration methods: one registry that validates and dispatches, one module per method.

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
from typing import TYPE_CHECKING

from ..stats.pose_stats import brief

if TYPE_CHECKING:
    from ..calibration import Calibration

__all__ = ["METHODS", "Method", "get"]

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

    def load(self) -> Callable[..., Calibration]:
        """The method's ``fit`` function (imports its module)."""
        fit: Callable[..., Calibration] = importlib.import_module(self.module).fit
        return fit

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


METHODS: dict[str, Method] = {
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
    )
}


def get(name: object) -> Method:
    """The registered method called ``name``; a one-line error listing the names otherwise."""
    if not isinstance(name, str) or name not in METHODS:
        raise ValueError(f"unknown method {brief(name)}; choose one of {', '.join(METHODS)}")
    return METHODS[name]
