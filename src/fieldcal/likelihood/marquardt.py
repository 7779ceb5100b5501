"""One Levenberg–Marquardt loop for every estimator: the pose methods' reduced system
(:mod:`.levenberg`), the continuous-motion estimator's banded trajectory
(:mod:`fieldcal.methods.continuous.solver`) and the gyroscope stage's segments
(:mod:`fieldcal.gyro.solver`).

Each estimator supplies a :class:`Problem` — its normal equations at a point, the damped step
they give and the cost of a trial point, in whatever structure it has (dense with the poses
eliminated by a Schur complement, block-banded) — and a :class:`Schedule`: how the damping λ
moves after a step that was taken or refused, and when the loop stops. :func:`minimise` is the
loop they share: linearise, propose, try, accept or refuse, until a schedule says the minimum
is reached or the iterations run out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

__all__ = ["Outcome", "Problem", "Schedule", "minimise"]

P = TypeVar("P")  # a point: the estimator's state (with what its cost computed there)
L = TypeVar("L")  # its linearisation: the normal equations at a point


class Problem(Protocol[P, L]):
    """What the loop needs of an estimator."""

    def linearise(self, point: P) -> L:
        """The normal equations (Gauss–Newton matrix and gradient) at ``point``."""
        ...

    def level(self, linear: L) -> float | None:
        """The cost at the linearised point as the normal equations computed it (the one a
        trial is then compared with), or ``None``: the cost the loop holds."""
        ...

    def propose(self, linear: L, lam: float) -> tuple[P, float] | None:
        """The point the step damped by ``lam`` reaches and the decrease of the cost the
        linear model predicts for it; ``None`` when this λ gives no usable step."""
        ...

    def cost(self, point: P) -> float:
        """The cost at a proposed point (``inf`` or NaN when it cannot be evaluated)."""
        ...


class Schedule:
    """How λ moves and when the loop stops; an estimator's rules subclass it.

    Attributes
    ----------
    lam : float
        The damping.
    count_trials : bool
        Whether an iteration is a trial step (otherwise a linearisation, its refused trials
        included).
    """

    count_trials = True

    def __init__(self, lam: float) -> None:
        self.lam = lam

    def ratio(self, gain: float, predicted: float) -> float:
        """The gain ratio ρ: the decrease achieved over the one predicted."""
        return gain / predicted if predicted > 0 else -1.0

    def done_before_trying(self, cost: float, predicted: float) -> bool:
        """Whether the step's prediction alone says the minimum is reached."""
        return False

    def unusable(self) -> bool | None:
        """No usable step at this λ: raise it. ``None`` goes on, a bool stops (converged)."""
        self.lam *= 10.0
        return None

    def accepts(self, gain: float, rho: float, new: float, cost: float) -> bool:
        """Whether the trial point (cost ``new``, from ``cost``) is taken."""
        return rho > 0 and math.isfinite(new)

    def accepted(self, gain: float, rho: float, cost: float) -> bool:
        """λ after a step taken; whether the loop stops, converged."""
        raise NotImplementedError

    def refused(self, predicted: float, cost: float) -> bool | None:
        """λ after a step refused. ``None`` goes on, a bool stops (converged or not)."""
        raise NotImplementedError


@dataclass
class Outcome(Generic[P]):
    """Where the loop stopped: the point, its cost, the iterations and convergence."""

    point: P
    cost: float
    iterations: int
    converged: bool


def minimise(
    problem: Problem[P, L], point: P, cost: float, schedule: Schedule, max_iter: int
) -> Outcome[P]:
    """Levenberg–Marquardt from ``point`` (cost ``cost``) under ``schedule``'s rules.

    Parameters
    ----------
    problem : Problem
        The estimator's normal equations, steps and cost.
    point : P
        The start.
    cost : float
        Its cost.
    schedule : Schedule
        λ's start and moves, the acceptance and stopping rules.
    max_iter : int
        Iterations (:attr:`Schedule.count_trials` says what one is).

    Returns
    -------
    Outcome
    """
    linear = problem.linearise(point)
    cost = _level(problem, linear, cost)
    iterations = 0
    fresh = True
    while True:
        if schedule.count_trials or fresh:
            if iterations >= max_iter:
                return Outcome(point, cost, iterations, False)
            iterations += 1
            fresh = False
        proposal = problem.propose(linear, schedule.lam)
        if proposal is None:
            stop = schedule.unusable()
            if stop is not None:
                return Outcome(point, cost, iterations, stop)
            continue
        trial, predicted = proposal
        if schedule.done_before_trying(cost, predicted):
            return Outcome(point, cost, iterations, True)
        new = problem.cost(trial)
        gain = cost - new
        rho = schedule.ratio(gain, predicted)
        if schedule.accepts(gain, rho, new, cost):
            point, cost = trial, new
            if schedule.accepted(gain, rho, cost):
                return Outcome(point, cost, iterations, True)
            linear = problem.linearise(point)
            cost = _level(problem, linear, cost)
            fresh = True
        else:
            stop = schedule.refused(predicted, cost)
            if stop is not None:
                return Outcome(point, cost, iterations, stop)


def _level(problem: Problem[P, L], linear: L, cost: float) -> float:
    level = problem.level(linear)
    return cost if level is None else level
