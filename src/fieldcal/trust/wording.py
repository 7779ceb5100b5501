"""One vocabulary for the verdict, the fit certificate and the report's banner: each says what
the others say, and what the certificate means for the kind of fit it is.

The χ² certificate (``J``, ``dof``, ``p``) is a test of the model only for poses whose noise was
measured independently (within-pose scatter) and whose means are independent. For a
continuous fit the residuals are correlated along the motion and the noise is estimated from
them (the quietest tenth): ``J``/``p`` then describe that noise model, not a test; the verdict
rests on the motion's checks (coverage, rigidity, convergence) and the predicted accuracy. For
poses cut from one motion (windows, samples) the error bars are widened for the correlation
and the χ² is no test either. The verdict's ``implausible`` rule fires below ``p = 1e-4``; the
certificate then says so instead of its ``status: ok``.
"""

from __future__ import annotations

import math

from ..calibration import Calibration

__all__ = [
    "CONTINUOUS_CERTIFICATE",
    "banner_headline",
    "certificate_reading",
    "is_continuous",
    "status_shown",
]

#: What the certificate of a continuous fit means (the summary, the report, docs/trust.md).
CONTINUOUS_CERTIFICATE = (
    "not a χ² test for a continuous fit: the residuals are correlated along the motion and "
    "the noise was estimated from them; the verdict rests on the motion's checks and the "
    "predicted accuracy"
)


def _codes(cal: Calibration) -> set[str]:
    return set() if cal.verdict is None else {r.code for r in cal.verdict.reasons}


def is_continuous(cal: Calibration) -> bool:
    """Whether ``cal`` was fitted to continuous motion (no poses)."""
    return cal.method == "continuous" or "trajectory" in cal.options


def certificate_reading(cal: Calibration) -> str:
    """The certificate's meaning, in words the verdict does not contradict."""
    diag = cal.diagnostics
    if is_continuous(cal):
        return CONTINUOUS_CERTIFICATE
    if any(s is not None and s.noise_source == "residuals" for s in (cal.accel, cal.mag)):
        return "not a test: the noise was estimated from these residuals"
    if "pose_correlation" in cal.options:
        return "not a χ² test: the poses were cut from one motion and are correlated"
    if diag is None or not math.isfinite(diag.p_value):
        return "no degrees of freedom left for a test"
    if "implausible" in _codes(cal):
        return "the model does not explain the data to within the stated noise (see the verdict)"
    if diag.p_value > 0.01:
        return "consistent with the noise"
    return (
        "the residuals are somewhat beyond the noise (the verdict warns below p = 1e-4; the "
        "predicted accuracy includes them)"
    )


def status_shown(cal: Calibration) -> str:
    """The certificate's status word: never ``ok`` beside an ``implausible`` verdict."""
    diag = cal.diagnostics
    status = "" if diag is None else diag.status
    if "implausible" in _codes(cal) and status in ("", "ok"):
        return "implausible"
    return status


def banner_headline(cal: Calibration) -> str:
    """The report's headline for the verdict's level, true for the kind of fit."""
    level = "none" if cal.verdict is None else cal.verdict.level
    if level == "pass":
        if is_continuous(cal):
            return "PASS: the motion determines the calibration within the accuracy targets"
        if "consistent with the noise" == certificate_reading(cal):
            return "PASS: consistent with its noise and within the accuracy targets"
        return "PASS: within the accuracy targets; no rule found a reason for doubt"
    if level == "warn":
        return "WARN: usable, but look at the reasons"
    return "FAIL: do not use this calibration"
