"""The imu.yaml writer: Kalibr's flat keys, OpenVINS' block with its identity intrinsics, every
figure written or the file refused in one line (never commented out, never guessed)."""

from __future__ import annotations

import re

import pytest

from fieldcal.errors import InputError
from fieldcal.imu_yaml import IMU_YAML_FORMATS, ImuNoise, imu_yaml

NOISE = ImuNoise(200.0, 2e-3, 3e-4, 1.7e-4, 2e-5, notes={"update_rate": "the log's rate"})


def _values(text: str) -> dict[str, float]:
    pairs = re.findall(r"^\s*(\w+): ([-+.\de]+)(?:\s|$)", text, re.M)
    return {k: float(v) for k, v in pairs}


@pytest.mark.parametrize("fmt", IMU_YAML_FORMATS)
def test_every_figure_is_written_as_given(fmt):
    text = imu_yaml(NOISE, fmt, header=["from a test"], rostopic="/board/imu")
    values = _values(text)
    for key, value in NOISE.figures().items():
        assert values[key] == pytest.approx(value, rel=1e-6)
    assert "# from a test" in text and "rostopic: /board/imu" in text
    assert "update_rate: 200.0  # the log's rate" in text
    assert text.startswith("%YAML:1.0") == (fmt == "openvins")


def test_an_unknown_or_non_positive_figure_is_refused_in_one_line():
    unknown = ImuNoise(200.0, None, 3e-4, 1.7e-4, 2e-5, why={"accelerometer_noise_density": "no"})
    with pytest.raises(InputError, match="accelerometer_noise_density unknown \\(no\\)") as e:
        imu_yaml(unknown)
    assert "\n" not in str(e.value) and "fieldcal noise" in str(e.value)
    with pytest.raises(InputError, match=r"gyroscope_random_walk = 0\.0 is not positive"):
        imu_yaml(ImuNoise(200.0, 2e-3, 3e-4, 1.7e-4, 0.0))
    with pytest.raises(ValueError, match=r"unknown imu\.yaml format"):
        imu_yaml(NOISE, "rovio")


def test_noise_still_exports_the_writer():
    import fieldcal.noise

    assert fieldcal.noise.imu_yaml is imu_yaml and fieldcal.noise.ImuNoise is ImuNoise
