"""Build the generated C library and drive it with ctypes (for tests/output/test_c_library.py)."""

from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import fieldcal
from fieldcal.output.exports import export_files

CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-O2"]


def compiler() -> str:
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler (cc) on PATH: the C library's tests need one")
    return cc


class Cal(ctypes.Structure):
    _fields_ = [
        ("sensor_id", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("f", ctypes.c_float * 56),
    ]


class Monitor(ctypes.Structure):
    _fields_ = [
        ("sum_norm", ctypes.c_float),
        ("sum_dip", ctypes.c_float),
        ("n", ctypes.c_uint16),
        ("head", ctypes.c_uint8),
        ("filled", ctypes.c_uint8),
        ("d2", ctypes.c_float * 8),
        ("statistic", ctypes.c_float),
        ("norm", ctypes.c_float),
        ("dip_deg", ctypes.c_float),
        ("blocks", ctypes.c_uint32),
        ("alarms", ctypes.c_uint32),
        ("rejected", ctypes.c_uint32),
    ]


class HardIron(ctypes.Structure):
    _fields_ = [
        ("beta", ctypes.c_float * 3),
        ("P", ctypes.c_float * 9),
        ("last_d", ctypes.c_float * 3),
        ("last_m", ctypes.c_float * 3),
        ("updates", ctypes.c_uint32),
        ("rejected", ctypes.c_uint32),
        ("field_norm", ctypes.c_float),
    ]


V3 = ctypes.c_float * 3


def v3(x: np.ndarray) -> ctypes.Array:
    return V3(*(float(v) for v in x))


class Library:
    """The generated library of one calibration, compiled to a shared object."""

    def __init__(self, cal, folder: Path, **options) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        for name, content in export_files(cal, "c-library", **options).items():
            (folder / name).write_bytes(content)
        self.folder = folder
        so = folder / "libfieldcal.so"
        cmd = [compiler(), *CFLAGS, "-shared", "-fPIC", str(folder / "fieldcal_cal.c")]
        out = subprocess.run([*cmd, "-o", str(so), "-lm"], capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        self.lib = lib = ctypes.CDLL(str(so))
        self.factory = Cal.in_dll(lib, "FIELDCAL_FACTORY")
        P, f = ctypes.POINTER, ctypes.c_float
        lib.fieldcal_tilt.restype = f
        lib.fieldcal_tilt.argtypes = [P(f), P(f), P(f)]
        lib.fieldcal_heading.restype = f
        lib.fieldcal_heading.argtypes = [P(Cal), P(f), P(f)]
        lib.fieldcal_save.argtypes = [P(Cal), ctypes.c_char_p, ctypes.c_size_t]
        lib.fieldcal_load.argtypes = [P(Cal), ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint32]
        lib.fieldcal_monitor_update.argtypes = [P(Monitor), P(Cal), P(f), P(f)]
        lib.fieldcal_hardiron_update.argtypes = [P(HardIron), P(Cal), P(f), P(f)]

    def cal(self) -> Cal:
        """A modifiable copy of the factory calibration."""
        copy = Cal()
        ctypes.memmove(ctypes.byref(copy), ctypes.byref(self.factory), ctypes.sizeof(Cal))
        return copy

    def apply(self, sensor: str, raw: np.ndarray) -> np.ndarray:
        fn = getattr(self.lib, f"fieldcal_{sensor}")
        out, cal = V3(), self.factory
        rows = []
        for r in np.asarray(raw, dtype=float).reshape(-1, 3):
            fn(ctypes.byref(cal), v3(r), out)
            rows.append(list(out))
        return np.array(rows)

    def tilt_heading(self, accel: np.ndarray, mag: np.ndarray) -> np.ndarray:
        """(roll, pitch, tilt, heading) in degrees per sample."""
        roll, pitch = ctypes.c_float(), ctypes.c_float()
        out = []
        for a, m in zip(accel, mag, strict=True):
            tilt = self.lib.fieldcal_tilt(v3(a), ctypes.byref(roll), ctypes.byref(pitch))
            heading = self.lib.fieldcal_heading(ctypes.byref(self.factory), v3(a), v3(m))
            out.append((roll.value, pitch.value, tilt, heading))
        return np.array(out)

    def save(self, cal: Cal) -> bytes:
        buf = ctypes.create_string_buffer(512)
        n = self.lib.fieldcal_save(ctypes.byref(cal), buf, 512)
        assert n > 0
        return buf.raw[:n]

    def load(self, blob: bytes, sensor_id: int, into: Cal | None = None) -> tuple[int, Cal]:
        cal = into if into is not None else Cal()
        return self.lib.fieldcal_load(ctypes.byref(cal), blob, len(blob), sensor_id), cal

    def monitor(self, accel: np.ndarray, mag: np.ndarray, cal: Cal | None = None) -> dict:
        """Feed body-frame samples; the status per sample and the statistic per block."""
        mon = Monitor()
        self.lib.fieldcal_monitor_init(ctypes.byref(mon))
        cal = cal if cal is not None else self.factory
        status, stats = [], []
        for a, m in zip(accel, mag, strict=True):
            s = self.lib.fieldcal_monitor_update(ctypes.byref(mon), ctypes.byref(cal), v3(a), v3(m))
            status.append(s)
            if s in (1, 2):
                stats.append(mon.statistic)
        return {"status": np.array(status), "statistic": np.array(stats), "blocks": mon.blocks}

    def hard_iron(
        self, accel: np.ndarray, mag: np.ndarray, widen: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """Run the recursive hard-iron estimator; (beta, its covariance, updates)."""
        h = HardIron()
        self.lib.fieldcal_hardiron_init(ctypes.byref(h), ctypes.byref(self.factory))
        self.lib.fieldcal_hardiron_widen(ctypes.byref(h), ctypes.c_float(widen))
        for a, m in zip(accel, mag, strict=True):
            self.lib.fieldcal_hardiron_update(
                ctypes.byref(h), ctypes.byref(self.factory), v3(a), v3(m)
            )
        return np.array(h.beta[:]), np.array(h.P[:]).reshape(3, 3), h.updates


# ------------------------------------------- simulated readings (the tests and benchmarks/)
def hand_session(seed: int = 3):
    """A cheap IMU: 20 poses, noise about 0.5 % of the field per sample, a pose-level error,
    dip about 60 degrees."""
    return fieldcal.simulate(
        "paper",
        seed=seed,
        n_poses=20,
        noise_alpha=(5e-5, 5e-5),
        pose_noise=1e-3,
        dip_deg=(58.0, 62.0),
    )


def hand_motion(n: int, rng: np.random.Generator, tilt_deg: float = 30.0) -> Rotation:
    """Ordinary hand motion: roll and pitch within ±tilt_deg, the heading wandering; 100 Hz."""
    t = np.arange(n) / 100.0
    phases = rng.uniform(0, 2 * np.pi, size=4)
    roll = tilt_deg * np.sin(2 * np.pi * 0.05 * t + phases[0]) * np.cos(0.011 * t + phases[1])
    pitch = tilt_deg * np.sin(2 * np.pi * 0.037 * t + phases[2])
    yaw = np.degrees(phases[3]) + 40.0 * t / 10.0 + 60.0 * np.sin(2 * np.pi * 0.013 * t)
    return Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll]), degrees=True)


def hand_stream(session, rot: Rotation, rng, mag_shift=None):
    """Raw readings of the session's true device along ``rot`` (body -> world), with its noise.

    ``mag_shift`` (n, 3): a change of the hard iron in the body frame, calibrated units."""
    truth = session.truth
    body_to_world = rot.as_matrix()
    out = []
    for name, shift in (("accel", None), ("mag", mag_shift)):
        sensor = truth.sensor(name)
        body = np.einsum("nji,j->ni", body_to_world, truth.reference(name))
        if shift is not None:
            body = body + shift
        noise = rng.multivariate_normal(np.zeros(3), np.asarray(sensor.noise_cov), size=len(body))
        out.append(sensor.distort(body) + noise)
    return out[0], out[1]
