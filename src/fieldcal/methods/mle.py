"""method="mle": joint maximum likelihood (Eq. 8), globally initialised, certified, with errors.

Orchestration only; the pieces live in

- :mod:`.mle_model` — parameters, whitened residuals of Eq. 8 and their analytic Jacobians;
- :mod:`.mle_start` — closed-form starts (ellipsoids, constant gravity-field angle, Wahba);
- :mod:`.mle_lm` — Levenberg-Marquardt on SO(3) with the Schur complement;
- :mod:`.mle_uncertainty` — Cramér-Rao covariance, delta method, degrees-of-freedom split.

``docs/methods/mle.md`` describes the method and its results.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

from ..diagnostics import certify, pose_table
from ..model import Calibration, SensorCalibration
from ..poses import PoseStats
from .mle_lm import Result, levenberg_marquardt, normal_equations
from .mle_model import Problem, State, build_problem, field
from .mle_start import closed_form_start, few_pose_starts, flip_other, min_rotations
from .mle_uncertainty import uncertainty, wishart_std

__all__ = ["fit", "sensor_cost_and_dof"]

DEFAULTS: dict[str, Any] = {
    "max_iter": 200,  # LM iterations per start
    "tol": 1e-10,  # stop when a step lowers J by less than tol·(1 + J)
    "p_min": 1e-4,  # certificate: a p-value below this is implausible
    "mag_mirrored": False,  # the sign twin with det(K_a K_m) < 0 (True) or > 0 (False)
    "initial": None,  # a Calibration to start from instead of the closed-form starts
}
#: Closed-form starts (accelerometer's, magnetometer's ellipsoid family), in order: the first two
#: always run, the others when the poses are few or the certificate is doubtful.
_FAMILIES = ("full", "axes", "sphere")
STARTS = (
    ("full", "full"),
    ("axes", "axes"),
    *((a, m) for a in _FAMILIES for m in _FAMILIES if a != m or a == "sphere"),
)
#: Below this many poses every start runs (the likelihood has more local minima).
FEW_POSES = 12
#: Below this many poses the ellipsoids' pencils are searched jointly for further starts.
PENCIL_POSES = 12
#: Certificate p-value below which every start runs.
P_RETRY = 0.01
#: Jacobi-scaled condition number of the reduced system above which the poses are degenerate.
COND_WARN = 1e10


def _options(options: dict[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(options) - set(DEFAULTS))
    if unknown:
        raise ValueError(
            f"unknown option(s) for method 'mle': {', '.join(unknown)}; "
            f"known: {', '.join(DEFAULTS)}"
        )
    return {**DEFAULTS, **options}


def _axis_name(n: np.ndarray) -> str:
    k = int(np.argmax(np.abs(n)))
    return "xyz"[k]


def check_spread(stats: PoseStats) -> None:
    """Refuse poses that cannot determine an ellipsoid: all rotations about one axis.

    Then the pose means of each sensor lie on a circle (a plane) or on a point; the plane's
    normal is, up to the small gain errors, the rotation axis, and poses with that axis tilted
    out of the horizontal plane are what is missing.
    """
    for name in ("accel", "mag"):
        st = getattr(stats, name)
        if st is None:
            continue
        centred = st.means - st.means.mean(axis=0)
        _, sv, Vt = np.linalg.svd(centred, full_matrices=False)
        if sv[0] <= 1e-12 * max(1.0, float(np.abs(st.means).max())) or sv[1] < 0.02 * sv[0]:
            raise ValueError(
                f"degenerate poses: the {name} readings barely change from pose to pose or lie "
                "on a line; turn the device so that each of its axes points up and down in turn"
            )
        if sv[2] < 0.02 * sv[0]:
            ax = _axis_name(Vt[2])
            raise ValueError(
                f"degenerate poses: the {name} readings lie in one plane (all rotations about "
                f"one axis, near the sensor's {ax} axis); add poses with the {ax} axis pointing "
                f"up and down (tilted 45° or more)"
            )


def _run(problem: Problem, state: State, opts: dict[str, Any], best: float | None) -> Result:
    return levenberg_marquardt(
        problem, state, max_iter=opts["max_iter"], tol=opts["tol"], known_minimum=best
    )


def _state_from_calibration(problem: Problem, cal: Calibration) -> State:
    gains = {s: np.array(getattr(cal, s).gain) for s in problem.sensors}
    biases = {s: np.array(getattr(cal, s).bias) for s in problem.sensors}
    gains[problem.frame] = 0.5 * (gains[problem.frame] + gains[problem.frame].T)
    dip = np.radians(cal.dip_deg) if problem.joint else 0.0
    return State(gains, biases, float(dip), np.array(cal.rotations))


def _canonical(problem: Problem, state: State, mirrored: bool | None) -> State:
    """fieldcal's gauge: ``h_x > 0``, the handedness rule, one-sensor headings."""
    if not problem.joint:
        s = problem.sensors[0]
        f = field(problem, s, 0.0)
        state = state.copy()
        # the rotation about the field is unobservable: take the smallest rotation
        state.rotations = min_rotations(f, state.rotations @ f)
        return state
    if np.cos(state.dip) < 0:  # h = (cos, 0, sin) must point north: R_i ← R_i R_z(π)
        state = state.copy()
        state.dip = float(np.pi - state.dip)
        state.rotations = state.rotations @ np.diag([-1.0, -1.0, 1.0])
    state.dip = float(np.arctan2(np.sin(state.dip), np.cos(state.dip)))
    other = "mag" if problem.frame == "accel" else "accel"
    # K and −K fit equally (see flip_other): the stated handedness decides, as in
    # Calibration.with_mag_handedness, which fieldcal.calibrate applies afterwards
    det = np.linalg.det(state.gains[other]) * np.linalg.det(state.gains[problem.frame])
    flip = bool(det < 0) != bool(mirrored)
    return flip_other(problem, state, other) if flip else state


def sensor_cost_and_dof(cal: Calibration, stats: PoseStats) -> dict[str, tuple[float, float]]:
    """Per sensor: its part of Eq. 8's J at ``cal`` (with ``cal``'s noise covariances) and the
    degrees of freedom it is expected to have, ``3N − tr(H_ss)`` (hat-matrix diagonal).

    Works for any calibration in the model (e.g. the greedy method's); used by
    :mod:`fieldcal.noise` to estimate noise from residuals.
    """
    covs = {s: getattr(cal, s).noise_cov for s in ("accel", "mag") if getattr(stats, s) is not None}
    K = cal.accel.gain if cal.accel is not None else cal.mag.gain
    frame = "accel" if cal.accel is not None and np.allclose(K, K.T) else "mag"
    if cal.mag is not None and frame == "mag" and not np.allclose(cal.mag.gain, cal.mag.gain.T):
        frame = "accel"
    problem = build_problem(stats, covs, frame)
    state = _state_from_calibration(problem, cal)
    from .mle_model import residuals, sensor_costs

    e = residuals(problem, state)
    ne = normal_equations(problem, state, e)
    unc = uncertainty(problem, state, ne)
    costs = sensor_costs(problem, e)
    return {s: (costs[s], unc.dof_share[s]) for s in problem.sensors}


def fit(
    stats: PoseStats,
    *,
    raw_accel: Any = None,
    raw_mag: Any = None,
    body_frame: str = "accel",
    noise_sources: dict | None = None,
    **options: Any,
) -> Calibration:
    """Joint maximum-likelihood calibration (Eq. 8), see ``docs/methods/mle.md``.

    Options: ``max_iter`` (LM iterations per start, 100), ``tol`` (1e-10, relative decrease of
    J that ends LM), ``p_min`` (1e-4, p-value below which the χ² certificate fails and further
    starts are tried), ``mag_mirrored`` (None: pick the sign twin whose magnetometer axes are
    mostly positive; True/False: force ``det(K_a K_m)`` negative/positive), ``initial`` (a
    :class:`Calibration` to start from).
    """
    opts = _options(options)
    sources = dict(noise_sources or {})
    sensors = [s for s in ("accel", "mag") if getattr(stats, s) is not None]
    for s in sensors:
        sources.setdefault(s, "scatter" if getattr(stats, s).cov is not None else "residuals")
    if any(getattr(stats, s).cov is None for s in sensors):
        from ..noise import fit_with_residual_noise

        return fit_with_residual_noise(
            fit,
            stats,
            sources,
            warm_start=True,
            raw_accel=raw_accel,
            raw_mag=raw_mag,
            body_frame=body_frame,
            **options,
        )
    n = stats.n_poses
    need = 8 if len(sensors) == 2 else 10
    if n < need:
        raise ValueError(
            f"{n} poses given; method 'mle' needs at least {need} "
            + (
                "(6N readings must outnumber the 3N rotation angles plus 22 sensor parameters)"
                if need == 8
                else "for one sensor (3N readings must outnumber 2N tilt angles plus 9 "
                "sensor parameters)"
            )
        )
    check_spread(stats)
    covs = {s: getattr(stats, s).cov for s in sensors}
    problem = build_problem(stats, covs, body_frame)

    best: Result | None = None
    tried: list[str] = []
    total_iter = 0

    def consider(state: State | None, label: str) -> None:
        nonlocal best, total_iter
        if state is None:
            return
        res = _run(problem, state, opts, None if best is None else best.cost)
        total_iter += res.iterations
        tried.append(label)
        if best is None or res.cost < best.cost - 1e-9 * (1 + res.cost):
            best = res

    from scipy.special import chdtrc

    def label(model: tuple[str, str]) -> str:
        return model[0] if len(problem.sensors) == 1 or model[0] == model[1] else "/".join(model)

    if opts["initial"] is not None:
        consider(_state_from_calibration(problem, opts["initial"]), "initial")
        starts = STARTS
    else:
        for model in STARTS[:2]:
            consider(closed_form_start(problem, model), label(model))
        starts = STARTS[2:]
    if len(problem.sensors) == 1:
        starts = tuple(m for m in starts if m[0] == m[1])
    few = n < FEW_POSES and opts["initial"] is None
    if few or best is None or chdtrc(problem.dof, best.cost) < max(P_RETRY, opts["p_min"]):
        for model in starts:
            if label(model) not in tried:
                consider(closed_form_start(problem, model), label(model))
        if n < PENCIL_POSES:
            for k, state in enumerate(few_pose_starts(problem)):
                consider(state, f"pencil{k}")
    if best is None:
        raise ValueError(
            "no closed-form start: the pose means do not outline an ellipsoid; "
            "add poses with each axis pointing up and down"
        )
    state = _canonical(problem, best.state, opts["mag_mirrored"])
    from .mle_model import residuals

    e = residuals(problem, state)
    ne = normal_equations(problem, state, e)
    unc = uncertainty(problem, state, ne, shares="residuals" in sources.values())

    sensor_cals = {}
    for s in sensors:
        st = getattr(stats, s)
        src = sources.get(s, "scatter")
        if src == "scatter":
            cov_std = wishart_std(st.cov, st.dof)
        elif src == "residuals":  # isotropic σ² from a χ² with this sensor's share of dof
            nu = max(unc.dof_share[s], 1.0)
            cov_std = np.diag(np.diag(st.cov) * np.sqrt(2.0 / nu))
        else:
            cov_std = np.zeros((3, 3))
        sensor_cals[s] = SensorCalibration(
            gain=state.gains[s],
            bias=state.biases[s],
            noise_cov=st.cov,
            gain_std=unc.gain_std[s],
            bias_std=unc.bias_std[s],
            noise_cov_std=cov_std,
            noise_source=src,
        )
    gravity = np.array([0.0, 0.0, -1.0]) if "accel" in sensors else None
    magnetic = field(problem, "mag", state.dip) if "mag" in sensors else None
    used = {k: v for k, v in opts.items() if k != "initial"}
    used["starts"] = tried
    cal = Calibration(
        accel=sensor_cals.get("accel"),
        mag=sensor_cals.get("mag"),
        gravity=gravity,
        magnetic=magnetic,
        rotations=state.rotations,
        method="mle",
        iterations=total_iter,
        converged=bool(best.converged),
        options=used,
        dip_std_deg=unc.dip_std_deg,
        misalignment_std_deg=unc.misalignment_std_deg,
        covariance=unc.covariance,
    )
    status = "ok"
    diag = certify(cal, stats, problem.dof)
    converged = bool(best.converged)
    if unc.condition > COND_WARN:
        status = "degenerate poses"
        warnings.warn(_degenerate_message(problem, state, unc.condition), stacklevel=3)
    if problem.dof > 0 and diag.p_value < opts["p_min"] and "residuals" not in sources.values():
        converged = False
        status = f"implausible fit (p = {diag.p_value:.2g})"
        share = diag.pose_share
        worst = np.argsort(-share)[:3]
        named = ", ".join(f"pose {i} ({100 * share[i]:.0f} %)" for i in worst)
        warnings.warn(
            f"mle: the fit is implausible (J = {diag.statistic:.4g} for χ²({problem.dof}), "
            f"p = {diag.p_value:.2g}) after starts {', '.join(tried)}; worst poses: {named}. "
            "Check them for motion or disturbance, or the noise covariance",
            stacklevel=3,
        )
    diag = dataclasses.replace(diag, status=status)
    return dataclasses.replace(
        cal,
        cost=diag.statistic,
        converged=converged,
        diagnostics=diag,
        poses=pose_table(diag, stats),
    )


def _degenerate_message(problem: Problem, state: State, cond: float) -> str:
    """Name the body axis the gravity (or field) directions cover least."""
    s = problem.sensors[0]
    u = state.rotations @ field(problem, s, state.dip)
    _, V = np.linalg.eigh(u.T @ u)
    ax = _axis_name(V[:, 0])
    return (
        f"mle: the poses barely determine the calibration (reduced system condition number "
        f"{cond:.2g}); add poses with the body's {ax} axis pointing up and down"
    )
