"""The static-pose likelihood every method and stage shares: the model (seed paper Eq. 1, 4, 5,
7), Levenberg–Marquardt on SO(3) with the pose rotations eliminated (Schur complement), and the
Cramér–Rao uncertainty.

Used by the ``mle`` method, the trust path (error bars, certificate), the gyroscope stage and
the planner; the greedy and ellipsoid methods are evaluated in it.
"""
