"""The magnetometer's handedness (fieldcal.trust.handedness): decided by the World Magnetic
Model's dip when both dips have a sign, the same whichever twin is passed, else as stated."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _known import DIP_DEG, known_calibration

from fieldcal.reference import FieldReference
from fieldcal.trust.handedness import SIGNIFICANT, Handedness, decide, reference_mirrored


def _reference(dip: float, std: float = 0.3) -> FieldReference:
    return FieldReference(
        model="WMM2025",
        date="2026-01-01",
        latitude_deg=45.0,
        longitude_deg=7.0,
        altitude_m=0.0,
        dip_deg=dip,
        dip_std_deg=std,
        intensity=48500.0,
        intensity_std=150.0,
        declination_deg=2.0,
        declination_std_deg=0.4,
    )


@pytest.mark.parametrize(("dip", "mirrored"), [(DIP_DEG, False), (-DIP_DEG, True), (20.0, False)])
def test_the_models_dip_decides_for_either_twin(dip, mirrored):
    cal = known_calibration()
    assert cal.dip_deg == pytest.approx(DIP_DEG)
    for twin in (cal, cal.with_mag_handedness(True)):
        assert reference_mirrored(twin, _reference(dip), 0.0) is mirrored
        decision = decide(twin, not mirrored, _reference(dip), 0.0)
        assert decision == Handedness(mirrored, mirrored)
        assert decision.options == {"mag_mirrored": mirrored, "mag_handedness": "reference"}


@pytest.mark.parametrize(
    ("dip", "std", "allowance"),
    [(0.5, 0.3, 0.0), (-1.0, 0.5, 0.0), (4.0, 0.3, 3.5)],  # within 3σ (+ allowance) of zero
)
def test_a_model_dip_near_zero_cannot_decide(dip, std, allowance):
    assert abs(dip) <= SIGNIFICANT * std + allowance
    cal = known_calibration()
    assert reference_mirrored(cal, _reference(dip, std), allowance) is None
    for stated in (False, True):
        decision = decide(cal, stated, _reference(dip, std), allowance)
        assert decision == Handedness(stated, None)
        assert decision.options["mag_handedness"] == "stated"


def test_without_a_reference_the_statement_holds():
    assert decide(known_calibration(), True, None, 0.0) == Handedness(True, None)


def test_a_fitted_dip_near_zero_cannot_decide():
    cal = known_calibration()
    flat = dataclasses.replace(cal, magnetic=np.array([48.5, 0.0, 0.0]))
    assert flat.dip_deg == pytest.approx(0.0, abs=1e-12)
    # no covariance: a fitted dip has a sign when it is nonzero; exactly zero has none
    assert reference_mirrored(flat, _reference(60.0), 0.0) is None
