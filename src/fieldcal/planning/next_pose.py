"""Experiment design: which orientation to record next, chosen from hand-reproducible candidates.

A new still pose at rotation ``R`` adds, at the current estimate, the Fisher information of its
whitened residuals (``docs/methods/planning.md``)::

    J_p = ∂e/∂ω  (m × 3: its own rotation),   J_g = ∂e/∂θ  (m × G: the globals)
    S_c = J_gᵀ J_g − J_gᵀ J_p (J_pᵀ J_p)⁻¹ J_pᵀ J_g          (the rotation eliminated)

with ``e`` whitened by the pose mean's covariance ``Σ_s/Δ + q_s² I``. Each pose's information
about the globals is additive once its own rotation is eliminated (Schur complement, as
:func:`fieldcal.likelihood.levenberg.reduce` does for all poses at once), so the current information
is the sum over the calibration's poses and a candidate's prediction is ``(S + S_c)⁻¹``.

The criterion is the worst ratio of predicted error to the user's target over heading, tilt
and (when a target is set) the dip's standard error, with the predicted errors of
:mod:`fieldcal.trust.accuracy` evaluated for every candidate at once (they are linear in the
parameter covariance); ties go to the larger log-determinant. ``k`` poses are planned greedily.
Before a calibration exists, :func:`first_poses` picks the candidates farthest from what has
been captured.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..calibration import Accuracy, Calibration, ParameterCovariance
from ..errors import InputError
from ..geometry.frames import orthogonal_polar_factor
from ..geometry.orientations import (
    CANDIDATES,
    DOWN_CANDIDATES,
    Orientation,
)
from ..likelihood.cramer_rao import named_map
from ..likelihood.pose_model import Problem, State, build_problem, jacobians, rotation_basis
from ..limits import MOST_PLANNED
from ..stats.pose_stats import PoseStats, SensorStats
from ..trust.accuracy import predict_accuracy
from ..trust.targets import Targets
from .more_motion import more_motion_advice

__all__ = [
    "FIRST_POSE_MINIMUM",
    "PlannedPose",
    "Targets",
    "first_poses",
    "floor",
    "plan_poses",
    "predict_covariance",
    "predicted_line",
    "targets_met",
    "unreachable",
]

Array = NDArray[np.float64]

#: Poses the joint fit needs (``"joint"``), and one sensor alone (``"single"``): below these,
#: :func:`first_poses` suggests what to capture.
FIRST_POSE_MINIMUM = {"joint": 8, "single": 10}
#: Two scores closer than this (relative) are a tie, broken by the log-determinant.
TIE = 1e-6
#: A reduced information matrix whose Jacobi-scaled eigenvalues spread more than this leaves
#: some parameter undetermined: the prediction is infinite.
SINGULAR = 1e-12
#: :func:`first_poses` centres raw means on a fitted sphere only when the fit's design has
#: singular values no more spread than this.
CENTRE_CONDITION = 1e-3


@dataclass(frozen=True)
class PlannedPose:
    """One suggested pose and what the calibration is predicted to reach with it.

    Attributes
    ----------
    orientation : Orientation
        The candidate: its rotation (world → body) and the words for the user.
    predicted : Accuracy
        :func:`fieldcal.trust.accuracy.predict_accuracy` with this pose and the plan's earlier
        ones added to the calibration's (same noise model, same widening).
    dip_std_deg : float or None
        Predicted standard error of the dip (degrees); ``None`` without a magnetometer.
    score : float
        The criterion: the worst ratio of predicted error to target (below 1: every target
        predicted to be met).
    """

    orientation: Orientation
    predicted: Accuracy
    dip_std_deg: float | None
    score: float

    @property
    def rotation(self) -> Array:
        """World (NED) → body rotation of the pose."""
        return self.orientation.rotation

    @property
    def words(self) -> str:
        """How to hold the device."""
        return self.orientation.words

    def to_dict(self) -> dict[str, object]:
        """Plain Python values for JSON: the words, the orientation and the prediction."""
        o = self.orientation
        return {
            "words": o.words,
            "kind": o.kind,
            "down": [float(x) for x in o.down],
            "heading_deg": o.heading_deg,
            "heading_axis": o.heading_axis,
            "rotation": [[float(x) for x in row] for row in o.rotation],
            "predicted": {
                f.name: getattr(self.predicted, f.name) for f in dataclasses.fields(self.predicted)
            },
            "dip_std_deg": self.dip_std_deg,
            "score": self.score,
        }


# --------------------------------------------------------------------------- the model
@dataclass(frozen=True)
class _Setup:
    """The calibration as the optimiser sees it, and how to go back to its units.

    Work units: unit fields, each sensor's readings divided by a power of two near its gain
    (numbers of order one, as :func:`fieldcal.calibrate` fits them) and, for the sensor that
    fixes the body frame, turned by the orthogonal polar factor ``U`` of its gain so the gain is
    symmetric (a folded axis map or accelerometer sign, ``fieldcal.pipeline.fold_axes``)."""

    cal: Calibration
    sensors: tuple[str, ...]
    frame: str
    state: State
    cov: dict[str, Array]  # per-sample covariance, work units
    pose_var: dict[str, float]  # q², work units
    samples: dict[str, int]  # Δ of a new pose
    information: Array  # (G, G): the current poses' reduced information
    back: Array  # (P, G): globals (work) -> named parameters (the calibration's units)
    names: tuple[str, ...]
    widening: float
    weights: _Weights


def _problem(
    setup_cov: dict[str, Array],
    pose_var: dict[str, float],
    counts: dict[str, NDArray[np.int64]],
    frame: str,
) -> Problem:
    sensors = {
        s: SensorStats(
            means=np.zeros((len(counts[s]), 3)),
            counts=np.asarray(counts[s], dtype=np.int64),
            cov=setup_cov[s],
            dof=max(int(np.sum(counts[s])) - len(counts[s]), 1),
            pose_var=pose_var[s],
        )
        for s in setup_cov
    }
    stats = PoseStats(sensors.get("accel"), sensors.get("mag"))
    try:
        return build_problem(stats, frame)
    except np.linalg.LinAlgError:
        raise InputError(
            "the calibration's noise model is singular (noise_cov with a zero variance and no "
            "pose-level noise); recalibrate so both are estimated"
        ) from None


def _reduced(problem: Problem, state: State) -> Array:
    """(N, G, G): each pose's information about the globals with its rotation eliminated."""
    basis = rotation_basis(problem, state)
    Jp, Jg = jacobians(problem, state, basis)
    JpT = Jp.transpose(0, 2, 1)
    U = JpT @ Jp
    W = JpT @ Jg
    V = Jg.transpose(0, 2, 1) @ Jg
    return np.asarray(V - W.transpose(0, 2, 1) @ np.linalg.solve(U, W))


def _pose_counts(cal: Calibration, sensors: Sequence[str]) -> dict[str, NDArray[np.int64]] | None:
    """Samples per fitted pose and sensor from ``cal.poses`` (rows of rejected poses, which a
    log's calibration lists too, left out); ``None`` when the rows do not say."""
    dropped = {r.index for r in cal.rejected}
    rows = [r for r in cal.poses if "rejected" not in r and r.get("index") not in dropped]
    if len(rows) != cal.n_poses:
        return None
    out = {}
    for s in sensors:
        values = [r.get(f"{s}_samples", r.get("samples")) for r in rows]
        if not all(isinstance(v, numbers.Integral) and int(v) > 0 for v in values):
            return None
        out[s] = np.array(values, dtype=np.int64)
    return out


def _whole(value: object, name: str) -> int:
    """A whole number of at least 1 (not a bool), or a one-line InputError."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or int(value) < 1:
        raise InputError(f"{name} must be a whole number of at least 1, got {value!r}"[:120])
    return int(value)


def _samples(value: object) -> int | None:
    return None if value is None else _whole(value, "samples")


def _setup(cal: object, samples: object) -> _Setup:
    if not isinstance(cal, Calibration):
        raise InputError(
            f"plan_poses needs a fieldcal.Calibration (Calibration.from_json(text)), "
            f"got {type(cal).__name__}"
        )
    if cal.accel is None or cal.gravity is None:
        raise InputError(
            "cannot plan for a magnetometer-only calibration: without an accelerometer no pose "
            "says which way is down, so no orientation can be put in words; calibrate with both"
        )
    if cal.method == "continuous" or "trajectory" in cal.options:
        raise InputError(more_motion_advice(cal))
    if cal.n_poses == 0:
        raise InputError("the calibration has no poses; capture poses with first_poses first")
    given = _samples(samples)
    sensors = ("accel", "mag") if cal.mag is not None and cal.magnetic is not None else ("accel",)
    frame = str(cal.options.get("body_frame", "accel"))
    frame = frame if frame in sensors else "accel"
    counts = _pose_counts(cal, sensors)
    if counts is None:
        if given is None:
            raise InputError(
                "the calibration does not list samples per pose (cal.poses); give the samples "
                "each pose will average (samples=; fieldcal plan needs a calibration JSON "
                "fieldcal calibrate wrote, which lists them)"
            )
        counts = {s: np.full(cal.n_poses, given, dtype=np.int64) for s in sensors}
    new = {s: given if given is not None else int(np.median(counts[s])) for s in sensors}

    gains, biases, cov, pose_var = {}, {}, {}, {}
    rows: list[Array] = []  # per named block: the map from work to the calibration's units
    for s in sensors:
        sc = cal.sensor(s)
        ref = float(np.linalg.norm(cal.reference(s)))
        U = orthogonal_polar_factor(sc.gain) if s == frame else np.eye(3)
        scale = 2.0 ** round(math.log2(float(np.linalg.norm(sc.gain, 2)) * ref))
        K = U.T @ sc.gain * (ref / scale)
        gains[s] = 0.5 * (K + K.T) if s == frame else K
        biases[s] = U.T @ sc.bias / scale
        cov[s] = U.T @ sc.noise_cov @ U / scale**2
        pose_var[s] = (sc.pose_noise_std / scale) ** 2
        # vec(δK) row-major: δK_cal = U δK_work · scale/ref, δb_cal = U δb_work · scale
        rows.append(np.asarray(np.kron(U, np.eye(3)) * (scale / ref), dtype=float))
        rows.append(np.asarray(U * scale, dtype=float))
    dip = math.radians(cal.dip_deg or 0.0) if len(sensors) == 2 else 0.0
    state = State(gains, biases, dip, np.array(cal.rotations))
    problem = _problem(cov, pose_var, counts, frame)
    information = _reduced(problem, state).sum(axis=0)
    names, T = named_map(problem)
    if problem.joint:
        rows.append(np.ones((1, 1)))
    B = _block_diag(rows)
    back = B @ T
    widening = _widening(cal, names, back, information)
    return _Setup(
        cal, sensors, frame, state, cov, pose_var, new, information, back, tuple(names),
        widening, _weights(cal, sensors),
    )  # fmt: skip


def _block_diag(blocks: list[Array]) -> Array:
    n = sum(b.shape[0] for b in blocks)
    out = np.zeros((n, n))
    i = 0
    for b in blocks:
        out[i : i + b.shape[0], i : i + b.shape[1]] = b
        i += b.shape[0]
    return out


def _widening(cal: Calibration, names: list[str], back: Array, information: Array) -> float:
    """The factor the calibration's reported covariance carries over the Cramér-Rao bound (the
    trust path widens it for an estimated pose-level noise): the median ratio of variances."""
    cov = cal.covariance
    if cov is None or not all(n in cov.names for n in names):
        return 1.0
    crb = np.diag(back @ _inverse(information[None])[0][0] @ back.T)
    reported = np.array([cov.matrix[cov.index(n), cov.index(n)] for n in names])
    ok = crb > 0
    if not np.any(ok) or not np.all(np.isfinite(crb)):
        return 1.0
    return max(1.0, float(np.median(reported[ok] / crb[ok])))


def _inverse(M: Array) -> tuple[Array, Array]:
    """Inverses of symmetric matrices (n, G, G) after Jacobi scaling, and their log-determinants;
    NaN entries (and a ``-inf`` log-determinant) where the matrix is numerically singular."""
    d = np.sqrt(np.maximum(np.einsum("nii->ni", M), 1e-300))
    Mn = M / (d[:, :, None] * d[:, None, :])
    lam, V = np.linalg.eigh(Mn)
    bad = lam[:, 0] <= SINGULAR * lam[:, -1]
    lam = np.where(lam > 0, lam, 1.0)
    inv = (V / lam[:, None, :]) @ V.transpose(0, 2, 1)
    inv = inv / (d[:, :, None] * d[:, None, :])
    logdet = np.log(lam).sum(axis=1) + 2.0 * np.log(d).sum(axis=1)
    inv[bad] = np.nan  # NaN, not inf: it propagates through products without warnings
    logdet[bad] = -np.inf
    return inv, logdet


# --------------------------------------------------------------------------- accuracy, batched
@dataclass(frozen=True)
class _Weights:
    """:mod:`fieldcal.trust.accuracy`'s squared errors as linear functions of the parameter
    covariance: ``error² = ⟨W, C⟩ + c`` (the pose-level noise's part in ``c``)."""

    tilt: Array  # (12, 12) on the accelerometer's gain and bias block
    tilt_noise: float
    heading: Array | None  # (24, 24) on both sensors' gains and biases
    heading_noise: float
    size: float  # |K_a| |g|: relative errors of the accelerometer's gain and bias


def _field_jacobian(u: Array) -> Array:
    """(M, 3, 12): ``d(K u + b)/d[vec K, b]`` for body vectors ``u`` (M, 3)."""
    G = np.zeros((len(u), 3, 12))
    for j in range(3):
        G[:, j, 3 * j : 3 * j + 3] = u
        G[:, j, 9 + j] = 1.0
    return G


def _sphere(n: int) -> Array:
    """The Fibonacci lattice :mod:`fieldcal.trust.accuracy` averages over (the same points:
    ``tests/test_planning.py`` checks the batched errors against ``predict_accuracy``)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5**0.5) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _heading_gradient(a: Array, m: Array) -> tuple[Array, Array]:
    """∂ψ/∂a and ∂ψ/∂m (H, 3) of the heading ``ψ = atan2(Y, X)`` of accuracy's formula
    (``Y = d₁(d·m) − m₁|d|²``, ``X = m₀|d|² − d₀(d·m)``, ``d = −a``)."""
    d = -a
    dd = np.einsum("hi,hi->h", d, d)
    dm = np.einsum("hi,hi->h", d, m)
    Y = d[:, 1] * dm - m[:, 1] * dd
    X = m[:, 0] * dd - d[:, 0] * dm
    e0, e1 = np.eye(3)[0], np.eye(3)[1]
    dY_dd = dm[:, None] * e1 + d[:, 1:2] * m - 2.0 * m[:, 1:2] * d
    dY_dm = d[:, 1:2] * d - dd[:, None] * e1
    dX_dd = 2.0 * m[:, 0:1] * d - dm[:, None] * e0 - d[:, 0:1] * m
    dX_dm = dd[:, None] * e0 - d[:, 0:1] * d
    r2 = (X * X + Y * Y)[:, None]
    dpsi_dd = (X[:, None] * dY_dd - Y[:, None] * dX_dd) / r2
    dpsi_dm = (X[:, None] * dY_dm - Y[:, None] * dX_dm) / r2
    return -dpsi_dd, dpsi_dm


def _weights(cal: Calibration, sensors: Sequence[str]) -> _Weights:
    acc = cal.sensor("accel")
    g = float(np.linalg.norm(cal.reference("accel")))
    Kinv = np.linalg.inv(acc.gain)
    v = _sphere(128)
    M = Kinv @ _field_jacobian(v * g) / g  # (M, 3, 12): δv per parameter, relative
    P = np.eye(3) - v[:, :, None] * v[:, None, :]
    tilt = np.einsum("nai,nab,nbj->ij", M, P, M) / len(v)
    noise = Kinv @ Kinv.T / g**2
    tilt_noise = acc.pose_noise_std**2 * float(np.mean(np.einsum("nab,ba->n", P, noise)))
    deg2 = np.degrees(1.0) ** 2
    heading, heading_noise = None, 0.0
    if "mag" in sensors:
        H = 36
        psi = np.linspace(0.0, 2 * np.pi, H, endpoint=False)
        c, s = np.cos(psi), np.sin(psi)
        R = np.zeros((H, 3, 3))
        R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, s, -s, c, 1.0
        a = R @ cal.reference("accel")
        m = R @ cal.reference("mag")
        ga, gm = _heading_gradient(a, m)
        # δv = K⁻¹ (n − δK u − δb): parameters enter with a minus sign, noise with a plus
        Ka_inv, Km_inv = Kinv, np.linalg.inv(cal.sensor("mag").gain)
        Ja = -np.einsum("hi,hij->hj", ga @ Ka_inv, _field_jacobian(a))
        Jm = -np.einsum("hi,hij->hj", gm @ Km_inv, _field_jacobian(m))
        J = np.concatenate([Ja, Jm], axis=1)  # (H, 24)
        heading = J.T @ J / H * deg2
        qa, qm = acc.pose_noise_std, cal.sensor("mag").pose_noise_std
        na, nm = ga @ Ka_inv, gm @ Km_inv
        heading_noise = float(np.mean(qa**2 * (na * na).sum(1) + qm**2 * (nm * nm).sum(1))) * deg2
    size = float(np.linalg.norm(acc.gain, 2)) * g
    return _Weights(tilt * deg2, tilt_noise * deg2, heading, heading_noise, size)


@dataclass(frozen=True)
class _Scores:
    score: Array  # (n,)
    logdet: Array  # (n,)
    covariance: Array  # (n, P, P), the calibration's units, widened


def _evaluate(setup: _Setup, targets: Targets, information: Array) -> _Scores:
    """The criterion for the reduced information matrices ``information`` (n, G, G)."""
    inv, logdet = _inverse(information)
    C = setup.widening * (setup.back @ inv @ setup.back.T)
    w = setup.weights
    tilt2 = np.einsum("ij,nij->n", w.tilt, C[:, :12, :12]) + w.tilt_noise
    tilt = np.sqrt(np.maximum(tilt2, 0.0))
    if w.heading is None:
        stds = np.sqrt(np.maximum(np.einsum("nii->ni", C[:, :12, :12]), 0.0))
        # relative errors: the gain's against its norm, the bias's against the reading's size
        gain_norm = w.size / float(np.linalg.norm(setup.cal.reference("accel")))
        rel = np.maximum(stds[:, :9].max(axis=1) / gain_norm, stds[:, 9:].max(axis=1) / w.size)
        worst = np.maximum(tilt, np.degrees(rel)) / targets.tilt_deg
    else:
        heading2 = np.einsum("ij,nij->n", w.heading, C[:, :24, :24]) + w.heading_noise
        ratios = [np.sqrt(np.maximum(heading2, 0.0)) / targets.heading_deg, tilt / targets.tilt_deg]
        if targets.dip_deg is not None:
            ratios.append(np.sqrt(np.maximum(C[:, 24, 24], 0.0)) / targets.dip_deg)
        worst = np.max(np.stack(ratios), axis=0)
    worst = np.where(np.isfinite(logdet), worst, np.inf)
    return _Scores(worst, logdet, C)


def _pick(scores: _Scores, allowed: Array) -> int:
    """The allowed candidate of smallest score; near-ties (``TIE``) to the largest
    log-determinant, then to the first."""
    score = np.where(allowed, scores.score, np.inf)
    best = float(score.min())
    if not np.isfinite(best):  # singular with any one pose more: the poses miss whole axes
        raise InputError(
            "no single pose makes this calibration determined; recapture poses with each axis "
            "pointing up and down (first_poses suggests them)"
        )
    tied = score <= best * (1.0 + TIE)
    return int(np.argmax(np.where(tied, scores.logdet, -np.inf)))


def _accuracy(cal: Calibration, covariance: ParameterCovariance | None) -> Accuracy:
    """:func:`predict_accuracy` of ``cal`` with ``covariance``, evaluated with unit fields and
    gains of order one: its errors are angles and ratios, the same in any units, but its finite
    differences step by one size for both sensors' gains, which in raw units can differ by
    10⁴ (as :func:`fieldcal.calibrate`, which predicts in its own scaled units, avoids)."""
    given = dataclasses.replace(cal, covariance=covariance).with_field_magnitudes(1.0, 1.0)
    scales = {
        s: 2.0 ** -round(math.log2(float(np.linalg.norm(given.sensor(s).gain, 2))))
        for s in ("accel", "mag")
        if getattr(given, s) is not None
    }
    return predict_accuracy(given.with_raw_scale(scales))


def _covariance(setup: _Setup, C: Array) -> ParameterCovariance:
    return ParameterCovariance(setup.names, 0.5 * (C + C.T))


def _candidate_information(setup: _Setup, rotations: Array) -> Array:
    """(n, G, G): the reduced information of new poses at ``rotations`` (n, 3, 3)."""
    n = len(rotations)
    counts = {s: np.full(n, setup.samples[s], dtype=np.int64) for s in setup.sensors}
    problem = _problem(setup.cov, setup.pose_var, counts, setup.frame)
    st = setup.state
    state = State(st.gains, st.biases, st.dip, np.asarray(rotations, dtype=float))
    return _reduced(problem, state)


def _targets(targets: object) -> Targets:
    if targets is None:
        return Targets()
    if not isinstance(targets, Targets):
        raise InputError(f"targets must be a fieldcal.Targets, got {type(targets).__name__}")
    return targets


def plan_poses(
    cal: Calibration,
    k: int = 1,
    *,
    targets: Targets | None = None,
    samples: int | None = None,
) -> tuple[PlannedPose, ...]:
    """The next ``k`` poses to record, chosen greedily from the fixed candidates.

    Parameters
    ----------
    cal : Calibration
        The current calibration (joint, or accelerometer alone); its poses, noise model
        (``noise_cov``, ``pose_noise_std``) and samples per pose (``cal.poses``) are used.
    k : int
        How many poses to plan (each chosen with the earlier ones added), at most
        :data:`~fieldcal.limits.MOST_PLANNED` (100).
    targets : Targets, optional
        The errors to reach; default :class:`Targets` ().
    samples : int, optional
        Samples each new pose will average; default the median of the calibration's poses.

    Returns
    -------
    tuple of PlannedPose
        In the order to record them. A candidate is not proposed twice in one plan unless
        every candidate has been (``k`` above 104, or 26 for an accelerometer alone).

    Raises
    ------
    InputError
        A magnetometer-only calibration (no down direction to plan with), a bad ``k``,
        ``samples`` or ``targets``, or poses so degenerate that no single candidate makes the
        calibration determined (then :func:`first_poses`).

    See Also
    --------
    floor, unreachable : what no number of poses can beat.
    """
    count = _whole(k, "k")
    if count > MOST_PLANNED:
        raise InputError(
            f"k must be at most {MOST_PLANNED} (poses per plan), got {count}; plan "
            f"{MOST_PLANNED} or fewer, record them, then plan again"
        )
    goal = _targets(targets)
    setup = _setup(cal, samples)
    pool = CANDIDATES if len(setup.sensors) == 2 else DOWN_CANDIDATES
    rotations = np.stack([c.rotation for c in pool])
    extra = _candidate_information(setup, rotations)
    current = setup.information
    chosen = np.zeros(len(pool), dtype=bool)
    plan = []
    for _ in range(count):
        scores = _evaluate(setup, goal, current[None] + extra)
        allowed = ~chosen if not chosen.all() else np.ones_like(chosen)
        best = _pick(scores, allowed)
        chosen[best] = True
        current = current + extra[best]
        cov = _covariance(setup, scores.covariance[best])
        predicted = _accuracy(setup.cal, cov)
        dip = float(np.sqrt(cov.matrix[-1, -1])) if "dip_deg" in cov.names else None
        plan.append(PlannedPose(pool[best], predicted, dip, float(scores.score[best])))
    return tuple(plan)


def predict_covariance(
    cal: Calibration, rotations: ArrayLike, *, samples: int | None = None
) -> ParameterCovariance:
    """The covariance ``cal`` is predicted to report with still poses added at ``rotations``.

    ``(S + Σ_c S_c)⁻¹`` mapped to the named parameters in the calibration's units, times the
    widening the calibration's covariance carries over its Cramér-Rao bound. ``rotations``
    (n, 3, 3) are world → body in the calibration's body frame (n may be 0: the current
    covariance from the poses alone); ``samples`` as in :func:`plan_poses`.
    """
    setup = _setup(cal, samples)
    R = np.asarray(rotations, dtype=float)
    if R.ndim == 2:
        R = R[None]
    if R.ndim != 3 or R.shape[1:] != (3, 3) or not np.all(np.isfinite(R)):
        raise InputError(f"rotations must be finite (n, 3, 3) rotation matrices, got {R.shape}")
    total = setup.information
    if len(R):
        total = total + _candidate_information(setup, R).sum(axis=0)
    inv, logdet = _inverse(total[None])
    if not np.isfinite(logdet[0]):
        raise InputError(
            "these poses do not determine the calibration; add poses with each axis up and down"
        )
    return _covariance(setup, setup.widening * (setup.back @ inv[0] @ setup.back.T))


def floor(cal: Calibration) -> Accuracy:
    """The accuracy no number of poses can beat: the pose-level noise alone (``cal.<sensor>.
    pose_noise_std``), as :func:`fieldcal.trust.accuracy.predict_accuracy` gives it with an
    exact calibration. A target below this is unreachable by recording more poses; the dip's
    floor is 0."""
    if not isinstance(cal, Calibration):
        raise InputError(f"floor needs a fieldcal.Calibration, got {type(cal).__name__}")
    return _accuracy(cal, None)


def unreachable(cal: Calibration, targets: Targets | None = None) -> str | None:
    """One line when :func:`floor` alone exceeds a target (more poses cannot reach it), else
    ``None``; e.g. ``"heading target unreachable: pose-level noise alone gives 0.62° (target
    0.5°); calibrate where the field is steadier, or hold the device on a firm support"``."""
    goal = _targets(targets)
    low = floor(cal)
    for name, value, target in (
        ("heading", low.heading_deg, goal.heading_deg),
        ("tilt", low.tilt_deg, goal.tilt_deg),
    ):
        if value is not None and value > target:
            return (
                f"{name} target unreachable: pose-level noise alone gives {value:.2g}° "
                f"(target {target:g}°); hold the device on a firm support, away from iron"
            )
    return None


def predicted_line(pose: PlannedPose) -> str:
    """The prediction of a planned pose on one line, e.g. ``"heading 0.42°, tilt 0.12°, dip
    ±0.081° (worst error/target 0.84)"``."""
    acc = pose.predicted
    parts = []
    if acc.heading_deg is not None:
        parts.append(f"heading {acc.heading_deg:.2g}°")
    if acc.tilt_deg is not None:
        parts.append(f"tilt {acc.tilt_deg:.2g}°")
    if pose.dip_std_deg is not None:
        parts.append(f"dip ±{pose.dip_std_deg:.2g}°")
    # a target far below what any pose gives makes a ratio of hundreds of digits: the exponent
    ratio = f"{pose.score:.2f}" if pose.score < 1e4 else f"{pose.score:.1e}"
    return ", ".join(parts) + f" (worst error/target {ratio})"


def targets_met(cal: Calibration, targets: Targets | None = None) -> bool:
    """Whether ``cal`` passes its verdict and its predicted errors are within ``targets``.

    ``cal.verdict.level`` must be ``"pass"``, ``cal.accuracy.tilt_deg`` and (with a
    magnetometer) ``heading_deg`` at most their targets, and ``cal.dip_std_deg`` at most
    ``targets.dip_deg`` when that is set (ignored without a magnetometer).
    """
    if not isinstance(cal, Calibration):
        raise InputError(f"targets_met needs a fieldcal.Calibration, got {type(cal).__name__}")
    goal = _targets(targets)
    if cal.verdict is None or cal.verdict.level != "pass" or cal.accuracy is None:
        return False
    acc = cal.accuracy
    checks = [(acc.tilt_deg, goal.tilt_deg)]
    if cal.mag is not None:
        checks.append((acc.heading_deg, goal.heading_deg))
        if goal.dip_deg is not None:
            checks.append((cal.dip_std_deg, goal.dip_deg))
    return all(value is not None and value <= target for value, target in checks)


# --------------------------------------------------------------------------- first poses
def _starter_order() -> tuple[Array, Array]:
    """The 26 down directions in the order :func:`first_poses` asks for them, and the heading
    (degrees) of each on its first visit.

    Faces first (+Z up, +Z down, then X, then Y), then the corners as two tetrahedra (any four
    of the first spread evenly over the sphere), then the edges; within each kind the heading
    turns a quarter at each pose so the first poses already vary the field's direction. Six
    faces and two corners in this order make a well-determined joint fit at 8 poses (six faces
    with two opposite corners, or every face at one heading, leave parameters undetermined)."""
    faces = [(0, 0, -1), (0, 0, 1), (-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0)]
    corners = [(1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)]
    corners += [(-x, -y, -z) for x, y, z in corners]
    edges = [tuple(c.down * np.sqrt(2.0)) for c in DOWN_CANDIDATES if c.kind == "edge"]
    downs, headings = [], []
    for group in (faces, corners, edges):
        for turn, v in enumerate(group):
            d = np.array(v, dtype=float)
            downs.append(d / np.linalg.norm(d))
            headings.append(90.0 * (turn % 4))
    return np.stack(downs), np.array(headings)


_START_DOWNS, _START_HEADINGS = _starter_order()


def _candidate(down: Array, heading: float | None) -> Orientation:
    """The candidate with this down direction and heading (``None``: heading free)."""
    pool = DOWN_CANDIDATES if heading is None else CANDIDATES
    return next(
        c
        for c in pool
        if np.abs(c.down - down).max() < 1e-9 and (heading is None or c.heading_deg == heading)
    )


def _means(value: object, name: str) -> Array:
    if value is None:
        return np.zeros((0, 3))
    try:
        x = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an (n, 3) array of raw pose means") from None
    if x.size == 0:
        return np.zeros((0, 3))
    if x.ndim != 2 or x.shape[1] != 3 or not np.all(np.isfinite(x)):
        raise InputError(f"{name} must be a finite (n, 3) array of raw pose means, got {x.shape}")
    if np.any(np.linalg.norm(x, axis=1) == 0):
        raise InputError(f"{name} has an all-zero pose mean; check the columns")
    return x


def _unit(x: Array) -> Array:
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _centred(x: Array) -> Array:
    """Raw means minus a sphere's centre fitted to them (``|x|² = 2cᵀx + k``), when at least
    5 poses determine it well; else as given. An offset (accelerometer bias, hard iron) as
    large as the field would otherwise turn every direction."""
    if len(x) < 5:
        return x
    scale = float(np.abs(x).max())
    y = x / scale
    A = np.column_stack([2.0 * y, np.ones(len(y))])
    sv = np.linalg.svd(A, compute_uv=False)
    if sv[-1] < CENTRE_CONDITION * sv[0]:
        return x
    c = np.linalg.lstsq(A, np.einsum("ni,ni->n", y, y), rcond=None)[0]
    centre, radius2 = c[:3], c[3] + c[:3] @ c[:3]
    if not radius2 > 0:
        return x
    out = y - centre
    if np.any(np.linalg.norm(out, axis=1) < 0.1 * np.sqrt(radius2)):
        return x  # a mean at the centre has no direction: the fit is not to be trusted
    return out * scale


def first_poses(
    accel_means: ArrayLike | None, mag_means: ArrayLike | None = None, k: int = 1
) -> tuple[Orientation, ...]:
    """Poses to capture before a calibration exists: the next down directions not captured.

    The 26 down directions are visited in a fixed starter order (faces, corners as two
    tetrahedra, edges; :func:`_starter_order`), skipping those already captured. Each captured
    pose is matched, in turn, to the nearest down direction among those matched least so far
    (its down is ``−accel``: the raw means' directions, centred on a fitted sphere from 5 poses
    on, since the readings are uncalibrated), so n captured poses account for n directions and
    the suggestion always moves on, whatever the raw offsets. The suggestion is the first
    direction in the order among those matched least; with a magnetometer at the heading of
    the order, turned a further quarter each time the direction comes round again. ``k`` poses
    are chosen one after another, each counted as captured. Only the accelerometer's means
    decide: the magnetometer's raw directions are turned by hard iron as large as the field,
    so the headings follow the order instead.

    Parameters
    ----------
    accel_means : (n, 3) array or None
        Raw accelerometer means of the poses captured so far (``None`` or n = 0: none yet).
    mag_means : (n, 3) array, optional
        Raw magnetometer means of the same poses; given (even empty), the suggestions carry
        headings for a joint calibration.
    k : int
        How many poses to suggest.

    Returns
    -------
    tuple of Orientation
        From :data:`~fieldcal.geometry.orientations.CANDIDATES` (with a magnetometer) or
        :data:`~fieldcal.geometry.orientations.DOWN_CANDIDATES`.
    """
    count = _whole(k, "k")
    a = _means(accel_means, "accel_means")
    joint = mag_means is not None
    if joint:
        m = _means(mag_means, "mag_means")
        if len(m) != len(a):
            raise InputError(
                f"accel_means has {len(a)} poses and mag_means {len(m)}; give both for every pose"
            )
    counts = np.zeros(len(_START_DOWNS), dtype=np.int64)
    for down in -_unit(_centred(a)) if len(a) else ():
        cos = np.where(counts == counts.min(), _START_DOWNS @ down, -np.inf)
        counts[int(np.argmax(cos))] += 1
    out: list[Orientation] = []
    for _ in range(count):
        j = int(np.argmax(counts == counts.min()))  # the first of the least visited
        heading = (_START_HEADINGS[j] + 90.0 * counts[j]) % 360.0 if joint else None
        out.append(_candidate(_START_DOWNS[j], heading))
        counts[j] += 1
    return tuple(out)
