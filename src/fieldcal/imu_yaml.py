"""The ``imu.yaml`` of Kalibr and OpenVINS: the figures it holds (:class:`ImuNoise`, SI
units) and the one writer of both formats (:func:`imu_yaml`), for ``fieldcal noise`` and
``fieldcal export`` (:mod:`fieldcal.noise` exports these names as before)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .errors import InputError

__all__ = ["IMU_YAML_FORMATS", "ImuNoise", "imu_yaml"]

Array = NDArray[np.float64]


#: The formats :func:`imu_yaml` writes.
IMU_YAML_FORMATS = ("kalibr", "openvins")


@dataclass(frozen=True)
class ImuNoise:
    """The figures an ``imu.yaml`` holds, SI units; ``None`` where the source cannot give one.

    Attributes
    ----------
    rate : float or None
        ``update_rate`` (Hz).
    accel_density, gyro_density : float or None
        White-noise densities (m/s²/√Hz, rad/s/√Hz).
    accel_walk, gyro_walk : float or None
        Bias random walks (m/s³/√Hz, rad/s²/√Hz).
    notes : dict
        Key -> the comment written after its value.
    why : dict
        Key -> why the figure is unknown (for the refusal), for keys whose value is ``None``.
    """

    rate: float | None
    accel_density: float | None
    accel_walk: float | None
    gyro_density: float | None
    gyro_walk: float | None
    notes: dict[str, str] = field(default_factory=dict)
    why: dict[str, str] = field(default_factory=dict)

    def figures(self) -> dict[str, float | None]:
        """The yaml keys and their values, in Kalibr's order."""
        return {
            "accelerometer_noise_density": self.accel_density,
            "accelerometer_random_walk": self.accel_walk,
            "gyroscope_noise_density": self.gyro_density,
            "gyroscope_random_walk": self.gyro_walk,
            "update_rate": self.rate,
        }


def imu_yaml(
    noise: ImuNoise, fmt: str = "kalibr", *, header: Sequence[str] = (), rostopic: str = "/imu0"
) -> str:
    """The ``imu.yaml`` of Kalibr or OpenVINS: the one writer of both, for ``fieldcal noise``
    and ``fieldcal export``.

    ``kalibr``: Kalibr's flat ``imu.yaml`` (its wiki, "IMU Noise Model" and the example
    ``imu_adis16448.yaml``). ``openvins``: OpenVINS' ``kalibr_imu_chain.yaml``: a
    ``%YAML:1.0`` line (OpenCV's ``FileStorage``, which OpenVINS reads it with, needs it) and the
    ``imu0`` block with the same keys plus ``T_i_b``, ``time_offset``, ``model`` and the
    intrinsics ``Tw``, ``R_IMUtoGYRO``, ``Ta``, ``R_IMUtoACC`` (identity) and ``Tg`` (zero): the
    readings reach OpenVINS already corrected (``fieldcal apply``).

    Parameters
    ----------
    noise : ImuNoise
    fmt : {"kalibr", "openvins"}
    header : sequence of str
        Comment lines written at the top.
    rostopic : str
        The IMU's topic (``/imu0``, Kalibr's and OpenVINS' default; edit it to yours).

    Returns
    -------
    str

    Raises
    ------
    InputError
        A figure is unknown: one line naming it and ``fieldcal noise``, which measures all four
        (never written commented out, never guessed).
    """
    if fmt not in IMU_YAML_FORMATS:
        raise ValueError(f"unknown imu.yaml format {fmt!r}; choose one of {IMU_YAML_FORMATS}")
    figures = noise.figures()
    missing = [key for key, value in figures.items() if value is None]
    if missing:
        why = noise.why.get(missing[0], "the source does not measure it")
        raise InputError(
            f"cannot write the {fmt} imu.yaml: {', '.join(missing)} unknown ({why}); "
            f"fieldcal noise LOG --export {fmt} -o imu.yaml measures all four figures from a "
            "still recording"
        )
    for key, value in figures.items():
        if value is None or not (math.isfinite(value) and value > 0):
            raise InputError(f"cannot write the {fmt} imu.yaml: {key} = {value!r} is not positive")
    lines = ["%YAML:1.0", ""] if fmt == "openvins" else []
    lines += [f"# {text}" for text in header]
    indent = "  " if fmt == "openvins" else ""
    if fmt == "openvins":
        lines += ["", "imu0:", "  T_i_b:  # IMU to body: identity (the IMU is the body)"]
        lines += [
            f"    - [{', '.join('1.0' if i == j else '0.0' for j in range(4))}]" for i in range(4)
        ]

    def entry(key: str, value: str) -> str:
        note = noise.notes.get(key)
        return f"{indent}{key}: {value}" + (f"  # {note}" if note else "")

    for key, value in figures.items():
        if key != "update_rate":
            lines.append(entry(key, f"{value:.6e}"))
    # no comment after a text value: OpenCV's FileStorage would read it as part of the text
    lines.append(f"{indent}# rostopic: the IMU's topic; edit it to yours")
    lines.append(f"{indent}rostopic: {rostopic}")
    if fmt == "openvins":
        lines.append(f"{indent}time_offset: 0.0")
    lines.append(entry("update_rate", f"{figures['update_rate']!r}"))
    if fmt == "openvins":
        lines.append(f'{indent}model: "kalibr"')
        lines.append(
            f"{indent}# intrinsics: identity: give OpenVINS the corrected columns `fieldcal apply` "
            "writes (a*_cal, and g*_cal in rad/s)"
        )
        for name, diagonal in (
            ("Tw", 1.0),
            ("R_IMUtoGYRO", 1.0),
            ("Ta", 1.0),
            ("R_IMUtoACC", 1.0),
            ("Tg", 0.0),
        ):
            lines.append(f"{indent}{name}:")
            lines += [
                f"{indent}  - [{', '.join(repr(diagonal) if i == j else '0.0' for j in range(3))}]"
                for i in range(3)
            ]
    return "\n".join(lines) + "\n"
