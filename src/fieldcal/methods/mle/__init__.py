"""method="mle": joint maximum likelihood (Eq. 8), globally initialised.

Orchestration only; the pieces live in

- :mod:`.model` — parameters, whitened residuals of Eq. 8 and their analytic Jacobians;
- :mod:`.start` — closed-form starts (ellipsoids, constant gravity-field angle, Wahba);
- :mod:`.lm` — Levenberg-Marquardt on SO(3) with the Schur complement;
- :mod:`.uncertainty` — Cramér-Rao covariance, delta method, degrees-of-freedom split.

The certificate, the pose-level noise and the error bars are the shared trust path's
(:mod:`fieldcal.trust`), the same for every method. ``docs/methods/mle.md`` describes the method.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtrc

from ...calibration import Calibration, SensorCalibration
from ...geometry.frames import GRAVITY, HALF_TURN_DOWN
from ...geometry.rotations import wahba_pair
from ...likelihood.levenberg import Result, levenberg_marquardt, many_poses
from ...likelihood.lockstep import Request, lockstep
from ...likelihood.pose_model import (
    Problem,
    State,
    bias_drift,
    build_problem,
    field,
    state_from_calibration,
)
from ...stats.pose_stats import PoseStats, brief, check_spread
from ...thermal import TemperatureModel
from .start import closed_form_start, few_pose_starts, flip_other, min_rotations

__all__ = ["fit", "state_from_calibration"]

Array = NDArray[np.float64]

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
#: Above this many poses (samples and windows modes: thousands of one-sample poses) the further
#: starts run on an evenly spaced subset of this many: whether a start leads to another
#: minimum is a matter of the poses' spread, which the subset keeps; a start that beats the
#: best there is then run on every pose from the subset's optimum.
SUBSET_POSES = 400
#: Above this many poses a cold fit searches its starts on :data:`SUBSET_POSES` evenly spaced
#: poses, then runs on every pose from the subset's best (its globals, each pose's rotation by
#: Wahba): the same minimum, reached in a few iterations of the whole problem instead of fifty.
COLD_SUBSET_POSES = 2000


def _temperature_model(
    problem: Problem, stats: PoseStats, state: State, s: str
) -> TemperatureModel | None:
    """Sensor ``s``'s bias against temperature (None when the poses carry no temperature)."""
    t = stats.temperature
    if t is None:
        return None
    return TemperatureModel(t.reference, state.temp(problem, s), t.span, t.refused)


def _canonical(problem: Problem, state: State) -> State:
    """fieldcal's gauge: ``h_x > 0``, both triads right-handed, one-sensor headings
    (:func:`fieldcal.calibrate` then applies the handedness the user states)."""
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
        state.rotations = state.rotations @ HALF_TURN_DOWN
    state.dip = math.atan2(math.sin(state.dip), math.cos(state.dip))
    other = "mag" if problem.frame == "accel" else "accel"
    # K and −K fit equally (see flip_other): the stated handedness decides, as in
    # Calibration.with_mag_handedness, which fieldcal.calibrate applies afterwards
    det = _det3(state.gains[other]) * _det3(state.gains[problem.frame])
    return flip_other(problem, state, other) if det < 0 else state


def _det3(K: Array) -> float:
    """The determinant of a 3x3 gain (its sign decides the handedness): the cofactor sum in
    Python floats, cheaper than ``np.linalg.det``'s wrapper for one small matrix."""
    (a, b, c), (d, e, f), (g, h, i) = K.tolist()
    return float(a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g))


def _solve_starts(
    problem: Problem, states: list[State], max_iter: int, tol: float, known: float | None
) -> list[Result]:
    """LM from each start, each told ``known`` (the J of a minimum found before them): one at a
    time for one start, else stepped together (:func:`~fieldcal.likelihood.lockstep.
    lockstep`, the same result per start as alone). A singular system raises, as alone."""
    if len(states) < 2 or many_poses(problem):  # thousands: the single solver's own rules
        return [
            levenberg_marquardt(problem, s, max_iter=max_iter, tol=tol, known_minimum=known)
            for s in states
        ]
    requests = [Request(problem, s, max_iter, tol, known_minimum=known) for s in states]
    out = []
    for res in lockstep(requests):
        if isinstance(res, Exception):
            raise res
        out.append(res)
    return out


def fit(
    stats: PoseStats,
    *,
    raw_accel: object = None,
    raw_mag: object = None,
    body_frame: str = "accel",
    progress: Callable[[str], None] | None = None,
    max_iter: int = 200,
    tol: float = 1e-10,
    initial: Calibration | None = None,
) -> Calibration:
    """Joint maximum-likelihood calibration (Eq. 8), see ``docs/methods/mle.md``.

    Parameters
    ----------
    stats : PoseStats
        Pose means with their covariances (``Σ/Δ_i + Q``, :class:`~fieldcal.stats.pose_stats.
        SensorStats`).
    raw_accel, raw_mag
        The raw samples (unused: the pose statistics are sufficient).
    body_frame : {"accel", "mag"}
        Which sensor's gain is symmetric, fixing the body frame (Sec. 4.3).
    progress : callable, optional
        Unused: the method takes milliseconds.
    max_iter : int
        Levenberg-Marquardt iterations per start (at least 1).
    tol : float
        Stop when a step lowers J by less than ``tol·(1 + J)`` (positive).
    initial : Calibration, optional
        A calibration to start from instead of the closed-form starts (warm start).

    Returns
    -------
    Calibration
        Parameters in fieldcal's gauge; ``converged`` is the optimiser's own flag; ``options``
        records the starts tried. Uncertainty and certificate are added by the shared path.
    """
    _check_options(max_iter, tol, initial)
    sensors = stats.sensors
    _check_count(stats)
    check_spread(stats)  # refuse rotations about one axis before any fit
    problem = build_problem(stats, body_frame)
    search = _Search(problem, int(max_iter), float(tol), stats)
    best = search.run(stats.n_poses, initial)
    state = _canonical(problem, best.state)
    sensor_cals = {
        s: SensorCalibration(
            gain=state.gains[s],
            bias=state.biases[s],
            noise_cov=np.zeros((3, 3)) if (cov := stats.sensor(s).cov) is None else cov,
            temperature=_temperature_model(problem, stats, state, s),
        )
        for s in sensors
    }
    return Calibration(
        accel=sensor_cals.get("accel"),
        mag=sensor_cals.get("mag"),
        gravity=GRAVITY if "accel" in sensors else None,
        magnetic=field(problem, "mag", state.dip) if "mag" in sensors else None,
        rotations=state.rotations,
        method="mle",
        iterations=search.iterations,
        converged=bool(best.converged),
        options={"max_iter": int(max_iter), "tol": float(tol), "starts": search.tried},
    )


def _check_options(max_iter: object, tol: object, initial: object) -> None:
    """One-line errors for :func:`fit`'s options."""
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ValueError(f"max_iter must be a whole number of at least 1, got {brief(max_iter)}")
    if isinstance(tol, bool) or not (
        isinstance(tol, (int, float)) and np.isfinite(tol) and tol > 0
    ):
        raise ValueError(f"tol must be a positive finite number, got {brief(tol)}")
    if initial is not None and not isinstance(initial, Calibration):
        raise ValueError(
            f"initial must be a fieldcal.Calibration (e.g. Calibration.from_json(text)), "
            f"got {type(initial).__name__}"
        )


def _check_count(stats: PoseStats) -> None:
    """Enough poses for the joint (8) or a single-sensor (10) problem."""
    n = stats.n_poses
    need = 8 if len(stats.sensors) == 2 else 10
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


class _Search:
    """The starts tried (closed-form, then more when the poses are few or the certificate
    doubtful) and the first to reach the lowest J."""

    def __init__(
        self, problem: Problem, max_iter: int, tol: float, stats: PoseStats | None = None
    ) -> None:
        self.problem, self.max_iter, self.tol, self.stats = problem, max_iter, tol, stats
        self.best: Result | None = None
        self.tried: list[str] = []
        self.iterations = 0

    def consider(self, candidates: list[tuple[State | None, str]]) -> None:
        """Run the starts (together when several: :func:`_solve_starts`) and keep the first
        to reach the lowest J."""
        todo = [(state, name) for state, name in candidates if state is not None]
        known = None if self.best is None else self.best.cost
        states = [s for s, _ in todo]
        results = _solve_starts(self.problem, states, self.max_iter, self.tol, known)
        for (_, name), res in zip(todo, results, strict=True):
            self.iterations += res.iterations
            self.tried.append(name)
            if self.best is None or res.cost < self.best.cost - 1e-9 * (1 + res.cost):
                self.best = res

    def _screened(
        self, candidates: list[tuple[State | None, str]], best: Result
    ) -> list[tuple[State | None, str]]:
        """The ``candidates`` run on :data:`SUBSET_POSES` evenly spaced poses beside the best
        result so far; those that reach a lower J there come back, with the subset's globals
        (their rotations from the start), to run on every pose. The others count as tried."""
        index, stats = self._subset()
        sub = build_problem(stats, self.problem.frame)
        todo = [(state, name) for state, name in candidates if state is not None]
        base = levenberg_marquardt(
            sub, _restricted(best.state, index), max_iter=self.max_iter, tol=self.tol
        )
        states = [_restricted(state, index) for state, _ in todo]
        results = _solve_starts(sub, states, self.max_iter, self.tol, base.cost)
        back: list[tuple[State | None, str]] = []
        for (state, name), res in zip(todo, results, strict=True):
            self.iterations += res.iterations
            if res.cost < base.cost - 1e-9 * (1.0 + base.cost):
                back.append((_with_globals(state, res.state), name))
            else:
                self.tried.append(name)
        return back

    def _subset(self) -> tuple[NDArray[np.intp], PoseStats]:
        assert self.stats is not None
        index = np.unique(np.linspace(0, self.problem.n - 1, SUBSET_POSES).round().astype(int))
        return index, self.stats.subset(index)

    def _from_subset(self) -> Result:
        """A cold fit of many poses (:data:`COLD_SUBSET_POSES`): every start searched on the
        subset, the best run on all the poses."""
        _, stats = self._subset()
        sub = _Search(build_problem(stats, self.problem.frame), self.max_iter, self.tol, stats)
        found = sub.run(stats.n_poses, None)
        self.iterations += sub.iterations
        state = found.state.copy()
        state.rotations = rotations_for(self.problem, state)
        self.consider([(state, "subset")])
        self.tried = [*sub.tried, "subset"]
        assert self.best is not None
        return self.best

    def label(self, model: tuple[str, str]) -> str:
        """A start's name: its sensors' models (one when they agree)."""
        one = len(self.problem.sensors) == 1 or model[0] == model[1]
        return model[0] if one else "/".join(model)

    def run(self, n: int, initial: Calibration | None) -> Result:
        """The best result over the starts for ``n`` poses (``initial``: a warm start)."""
        problem = self.problem
        if initial is None and n >= COLD_SUBSET_POSES and self.stats is not None:
            return self._from_subset()
        if initial is not None:
            self.consider([(state_from_calibration(problem, initial), "initial")])
            starts = STARTS
        else:
            for model in STARTS[:2]:
                self.consider([(closed_form_start(problem, model), self.label(model))])
            starts = STARTS[2:]
        if len(problem.sensors) == 1:
            starts = tuple(m for m in starts if m[0] == m[1])
        few = n < FEW_POSES and initial is None
        # a doubtful certificate may mean a local minimum; a warm start (the trust path
        # refitting with new weights) stays in the basin it was given
        best = self.best
        doubtful = initial is None and chdtrc(problem.dof, best.cost if best else np.inf) < P_RETRY
        if few or best is None or doubtful:
            more = [
                (closed_form_start(problem, model), self.label(model))
                for model in starts
                if self.label(model) not in self.tried
            ]
            if n < PENCIL_POSES:
                more += [(state, f"pencil{k}") for k, state in enumerate(few_pose_starts(problem))]
            if n > SUBSET_POSES and self.stats is not None and best is not None:
                self.consider(self._screened(more, best))
            else:
                self.consider(more)
        if self.best is None:
            raise ValueError(
                "no closed-form start: the pose means do not outline an ellipsoid; "
                "add poses with each axis pointing up and down"
            )
        return self.best


def _restricted(state: State, index: NDArray[np.intp]) -> State:
    """``state`` on the poses ``index`` (their rotations)."""
    out = state.copy()
    out.rotations = out.rotations[index]
    return out


def _with_globals(state: State, source: State) -> State:
    """``state``'s rotations with ``source``'s gains, biases, dip and temperature terms."""
    out = source.copy()
    out.rotations = state.rotations.copy()
    return out


def rotations_for(problem: Problem, state: State) -> Array:
    """Every pose's rotation for ``state``'s gains, biases and dip: each sensor's direction
    ``K⁻¹(μ − b)`` (Eq. 2), the pair's rotation by Wahba in closed form (one sensor: the
    smallest rotation onto its field)."""
    dirs = []
    for s in problem.sensors:
        drift = bias_drift(problem, state, s)
        offset = problem.means[s] - state.biases[s] - (0.0 if drift is None else drift)
        u = np.linalg.solve(state.gains[s], offset.T).T
        dirs.append(u / np.linalg.norm(u, axis=1, keepdims=True))
    if not problem.joint:
        return min_rotations(field(problem, problem.sensors[0], 0.0), dirs[0])
    fields = [field(problem, s, state.dip) for s in problem.sensors]
    return wahba_pair(dirs[0], dirs[1], fields[0], fields[1])
