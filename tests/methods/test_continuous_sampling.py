"""The gyroscope's sampling convention told from the data (issue 33 item 5), on the
independent hand-held simulator's two conventions."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.methods.continuous.preintegration import sampling_evidence
from fieldcal.simulation.handheld import simulate_handheld


@pytest.mark.parametrize(("convention", "share"), [("instant", 1.0), ("mean", 0.0)])
def test_sampling_share_tells_the_conventions_apart(convention, share):
    for seed in (1, 2):
        log = simulate_handheld(seed, seconds=30.0, rate=80.0, gyro_sampling=convention)
        c = log.columns
        m = np.column_stack([c["mx"], c["my"], c["mz"]])
        g = np.column_stack([c["gx"], c["gy"], c["gz"]])
        field = np.linalg.solve(log.truth.mag.gain, (m - log.truth.mag.bias).T).T
        field /= np.linalg.norm(field, axis=1)[:, None]
        lam, std = sampling_evidence(c["t"], g, field)
        assert abs(lam - share) < 3 * std + 0.25
        assert abs(lam - (1.0 - share)) > 3 * std + 0.25
