"""Noise from the fit's residuals, for poses without within-pose scatter (one sample each).

Eq. 7 needs several samples per pose. Without them each sensor's noise is taken isotropic,
``Σ_s = σ_s² I``, and ``σ_s²`` is the fixed point of

    σ_s² ← σ_s² · J_s / ν_s

where ``J_s`` is sensor s's part of Eq. 8 at the fit made with the current ``σ²`` and
``ν_s = 3N − tr(H_ss)`` its expected value (the hat-matrix diagonal of the whitened problem
splits the ``3N − 22`` degrees of freedom between the sensors). At the fixed point the
certificate's statistic equals its degrees of freedom, so the χ² test carries no information:
the diagnostics say so. The standard errors come from the Cramér-Rao bound with the estimated
``σ²`` and are widened by ``ν/(ν − 2)`` (variance of Student's t) for the uncertainty of
``σ²`` itself; ``noise_cov_std`` is ``σ² sqrt(2/ν_s)`` (χ²).

Generic over methods: ``fit`` is any ``fieldcal.methods.*.fit``; the per-sensor costs and
degrees of freedom are evaluated at its result with the joint model's Jacobians.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from .model import Calibration
from .poses import PoseStats

__all__ = ["fit_with_residual_noise"]


def _initial_variance(means: np.ndarray) -> float:
    # only the ratio between sensors matters for the first fit; 1e-3 of the spread is a
    # typical MEMS noise-to-range ratio and the fixed point corrects it
    spread = float(np.sqrt(np.mean(np.sum((means - means.mean(axis=0)) ** 2, axis=1))))
    return (1e-3 * max(spread, 1e-12)) ** 2


def _with_cov(stats: PoseStats, variances: dict[str, float]) -> PoseStats:
    out = {}
    for s in ("accel", "mag"):
        st = getattr(stats, s)
        if st is not None and s in variances:
            st = dataclasses.replace(st, cov=np.eye(3) * variances[s])
        out[s] = st
    return PoseStats(out["accel"], out["mag"])


def _widen(cal: Calibration, factor: float) -> Calibration:
    """Scale every variance by ``factor`` (standard errors by its square root)."""
    r = float(np.sqrt(factor))

    def sensor(sc):
        if sc is None:
            return None
        return dataclasses.replace(
            sc,
            gain_std=None if sc.gain_std is None else sc.gain_std * r,
            bias_std=None if sc.bias_std is None else sc.bias_std * r,
        )

    cov = cal.covariance
    if cov is not None:
        cov = dataclasses.replace(cov, matrix=cov.matrix * factor)
    return dataclasses.replace(
        cal,
        accel=sensor(cal.accel),
        mag=sensor(cal.mag),
        covariance=cov,
        dip_std_deg=None if cal.dip_std_deg is None else cal.dip_std_deg * r,
        misalignment_std_deg=None
        if cal.misalignment_std_deg is None
        else cal.misalignment_std_deg * r,
    )


def fit_with_residual_noise(
    fit: Callable[..., Calibration],
    stats: PoseStats,
    sources: dict[str, str],
    *,
    warm_start: bool = False,
    max_iter: int = 50,
    rtol: float = 1e-6,
    **fit_kwargs: Any,
) -> Calibration:
    """Calibrate with ``fit``, estimating the noise of every sensor whose source is
    ``"residuals"`` by the fixed point above. ``warm_start`` passes the previous result as
    ``initial=`` (methods that accept it converge in one or two iterations per round)."""
    from .methods.mle import sensor_cost_and_dof

    residual = [s for s in ("accel", "mag") if sources.get(s) == "residuals"]
    for s in residual:
        if getattr(stats, s) is None:
            raise ValueError(f"noise source 'residuals' given for {s}, which has no data")
    if not residual:
        return fit(stats, noise_sources=sources, **fit_kwargs)
    variances = {s: _initial_variance(getattr(stats, s).means) for s in residual}
    cal: Calibration | None = None
    rounds = 0
    for _ in range(max_iter):
        rounds += 1
        current = _with_cov(stats, variances)
        kwargs = dict(fit_kwargs)
        if warm_start and cal is not None:
            kwargs["initial"] = cal
        cal = fit(current, noise_sources=sources, **kwargs)
        parts = sensor_cost_and_dof(cal, current)
        new = {s: variances[s] * parts[s][0] / max(parts[s][1], 1e-9) for s in residual}
        change = max(abs(new[s] / variances[s] - 1.0) for s in residual)
        variances = new
        if change < rtol:
            break
    current = _with_cov(stats, variances)
    kwargs = dict(fit_kwargs)
    if warm_start:
        kwargs["initial"] = cal
    cal = fit(current, noise_sources=sources, **kwargs)
    parts = sensor_cost_and_dof(cal, current)
    nu = sum(parts[s][1] for s in residual)
    if nu > 2:
        cal = _widen(cal, nu / (nu - 2.0))
    note = (
        f"noise of {' and '.join(residual)} estimated from the residuals "
        f"({rounds} rounds); the χ² statistic equals its degrees of freedom by "
        "construction and does not test the fit"
    )
    diag = cal.diagnostics
    if diag is not None:
        status = note if not diag.status or diag.status == "ok" else f"{diag.status}; {note}"
        diag = dataclasses.replace(diag, status=status)
    return dataclasses.replace(cal, diagnostics=diag)
