"""The one Levenberg–Marquardt loop (fieldcal.likelihood.marquardt): on Rosenbrock's valley
with each estimator's schedule it reaches the known minimum; a schedule's rules are what stop
it; an iteration is a trial or a linearisation as the schedule says; every estimator's
solver runs through it."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from fieldcal.gyro import solver as gyro_solver
from fieldcal.likelihood import levenberg
from fieldcal.likelihood.marquardt import Schedule, minimise
from fieldcal.methods.continuous import solver as continuous_solver


class Rosenbrock:
    """r = (10 (y − x²), 1 − x): the minimum J = 0 at (1, 1), a curved valley."""

    def __init__(self) -> None:
        self.linearisations = 0

    def residual(self, p):
        return np.array([10.0 * (p[1] - p[0] ** 2), 1.0 - p[0]])

    def linearise(self, p):
        self.linearisations += 1
        J = np.array([[-20.0 * p[0], 10.0], [-1.0, 0.0]])
        return p, J.T @ J, J.T @ self.residual(p)

    def level(self, linear):
        return None

    def propose(self, linear, lam):
        p, H, g = linear
        step = np.linalg.solve(H + lam * np.diag(np.diag(H)), -g)
        predicted = float(-(2 * g @ step + step @ H @ step))
        return p + step, predicted

    def cost(self, p):
        r = self.residual(p)
        return float(r @ r)


@pytest.mark.parametrize(
    "schedule",
    [
        levenberg.Nielsen(1e-4, 1e-12, None),
        continuous_solver._Fivefold(1e-14),
        gyro_solver._Tenfold(),
    ],
    ids=["poses", "continuous", "gyro"],
)
def test_every_schedule_reaches_the_minimum_of_a_curved_valley(schedule):
    problem = Rosenbrock()
    start = np.array([-1.2, 1.0])
    out = minimise(problem, start, problem.cost(start), schedule, max_iter=500)
    assert out.converged
    np.testing.assert_allclose(out.point, [1.0, 1.0], atol=1e-3)
    assert out.cost < 1e-6 and out.cost == pytest.approx(problem.cost(out.point))


class Never(Schedule):
    """Takes every step that lowers J and never says converged."""

    def accepts(self, gain, rho, new, cost):
        return new < cost

    def accepted(self, gain, rho, cost):
        self.lam /= 3.0
        return False

    def refused(self, predicted, cost):
        self.lam *= 10.0
        return None


def test_the_iterations_run_out_unconverged_and_count_as_the_schedule_says():
    problem = Rosenbrock()
    start = np.array([-1.2, 1.0])
    out = minimise(problem, start, problem.cost(start), Never(1e-3), max_iter=5)
    assert not out.converged and out.iterations == 5
    assert out.cost < problem.cost(start)
    per_linearisation = Never(1e3)  # large λ: refusals between linearisations
    per_linearisation.count_trials = False
    problem = Rosenbrock()
    out = minimise(problem, start, problem.cost(start), per_linearisation, max_iter=3)
    assert out.iterations == 3 and problem.linearisations == 4  # the start and 3 steps taken


def test_a_schedule_that_gives_up_stops_with_its_verdict():
    class GiveUp(Never):
        def accepts(self, gain, rho, new, cost):
            return False

        def refused(self, predicted, cost):
            return False

    problem = Rosenbrock()
    start = np.array([-1.2, 1.0])
    out = minimise(problem, start, problem.cost(start), GiveUp(1.0), max_iter=50)
    assert not out.converged and out.iterations == 1 and np.array_equal(out.point, start)


def test_every_estimators_solver_runs_through_the_shared_loop():
    for function in (
        levenberg.solve_alone,
        continuous_solver.levenberg_marquardt,
        gyro_solver.gauss_newton,
    ):
        assert "minimise(" in inspect.getsource(function)
