"""The real recordings of ``../shared/data`` as per-pose sample lists, and the split-half check.

Each loader returns a :class:`RealSet`: one ``(n_i, 3)`` array of raw samples per pose for each
sensor it has (``None`` for the other), ready for :func:`fieldcal.calibrate`. The recordings are
read in place (``root`` is the ``shared/data`` folder; never copy them).

- ``icm20948-s3``: icm20948-deadtomgc session 3, still detection at 27 Hz with a 0.3 s window
  and 0.3 s minimum stillness (23 poses); magnetometer axes mapped ``+x-y-z`` onto the
  accelerometer's.
- ``imu_tk``: the Xsens log of IMU-TK (raw counts, 100 Hz), still detection with the gyroscope;
  accelerometer only.
- ``ck-acc_log``: CK-Explorer's ``acc_log.csv`` (no time column), accelerometer only.
- ``sap6-<run>``: a cave-survey instrument's 24 calibration shots (one averaged reading per
  shot, so the noise comes from the residuals). Both sensors in the instrument's frame through
  the axis strings of its ``.cfg``; SAP6's ``grav`` is the gravity vector (down), negated here
  into the specific force (up) the model reads.

Split-half check (:func:`split_half`): calibrate the interleaved halves (poses 0, 2, 4, … and
1, 3, 5, …) separately; for the dip and every bias, ``z = (a − b) / sqrt(σ_a² + σ_b²)`` with
each half's own standard errors. When the error bars are right, z is standard normal and its RMS
over the parameters is about 1.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

import fieldcal
from fieldcal.geometry.frames import parse_axes
from fieldcal.gyro import GyroFit, fit_gyro
from fieldcal.logs import Log, load_log, poses_from_log

__all__ = [
    "DATA",
    "LOADERS",
    "SAP6_RUNS",
    "ImucalTurns",
    "RealSet",
    "SplitHalf",
    "ck_acc_log",
    "icm20948_session3",
    "imu_tk",
    "imucal_turns",
    "load",
    "sap6",
    "split_half",
    "split_half_names",
]

Array = NDArray[np.float64]

#: ``../shared/data`` beside the project checkout (as in tests/conftest.py).
DATA = Path(__file__).resolve().parents[2] / "shared" / "data"

#: The sap6 runs of the benchmark (``HC_improved`` is a re-shot HC and left out).
SAP6_RUNS = ("BB", "CF", "FG", "HC", "IB", "JG")


@dataclass(frozen=True)
class RealSet:
    """One real recording cut into poses: raw samples per pose for each sensor it has."""

    name: str
    description: str
    accel: list[Array] | None
    mag: list[Array] | None

    @property
    def n_poses(self) -> int:
        return len(self.accel if self.accel is not None else self.mag)

    @property
    def sensors(self) -> tuple[str, ...]:
        return tuple(s for s in ("accel", "mag") if getattr(self, s) is not None)

    def subset(self, index: Sequence[int]) -> RealSet:
        """The same recording restricted to the poses ``index`` (in that order)."""

        def pick(samples: list[Array] | None) -> list[Array] | None:
            return None if samples is None else [samples[int(i)] for i in index]

        return RealSet(self.name, self.description, pick(self.accel), pick(self.mag))


def icm20948_session3(root: Path = DATA) -> RealSet:
    log = load_log(root / "icm20948-deadtomgc" / "derived" / "session3.csv")
    log.mag = log.mag @ parse_axes("+x-y-z").T
    poses = poses_from_log(log, rate=27, min_still=0.3, window=0.3)
    return RealSet(
        "icm20948-s3",
        "ICM-20948 session 3, still detection (27 Hz, 0.3 s window and stillness)",
        poses.accel,
        poses.mag,
    )


def imu_tk(root: Path = DATA) -> RealSet:
    folder = root / "imu_tk"
    acc = np.loadtxt(folder / "xsens_acc.mat")  # columns: time [s], x, y, z (raw counts)
    gyro = np.loadtxt(folder / "xsens_gyro.mat")
    log = Log(
        path=str(folder / "xsens_acc.mat"),
        accel=acc[:, 1:],
        mag=None,
        gyro=gyro[:, 1:],
        time=acc[:, 0] - acc[0, 0],
        pose=None,
        index=np.arange(len(acc)),
        used={},
        names=[],
    )
    poses = poses_from_log(log)
    return RealSet("imu_tk", "IMU-TK Xsens log, still detection at 100 Hz", poses.accel, None)


def ck_acc_log(root: Path = DATA) -> RealSet:
    poses = poses_from_log(load_log(root / "ck-explorer" / "acc_log.csv"))
    return RealSet("ck-acc_log", "CK-Explorer acc_log.csv, still detection", poses.accel, None)


def sap6(run: str, root: Path = DATA) -> RealSet:
    fixtures = root / "sap6" / "orig" / "tests" / "fixtures" / "SAP6"
    shots = json.loads((fixtures / f"{run}.json").read_text())
    cfg = json.loads((fixtures / f"{run.split('_')[0]}.cfg").read_text())
    grav = -np.asarray(shots["grav"], float) @ parse_axes(cfg["grav_axes"]).T
    mag = np.asarray(shots["mag"], float) @ parse_axes(cfg["mag_axes"]).T
    return RealSet(
        f"sap6-{run}",
        f"SAP6 run {run}: 24 shots, one averaged reading each",
        list(grav[:, None, :]),
        list(mag[:, None, :]),
    )


LOADERS: dict[str, Callable[..., RealSet]] = {
    "icm20948-s3": icm20948_session3,
    "imu_tk": imu_tk,
    "ck-acc_log": ck_acc_log,
    **{f"sap6-{run}": (lambda root=DATA, run=run: sap6(run, root)) for run in SAP6_RUNS},
}


@dataclass(frozen=True)
class ImucalTurns:
    """imucal's annotated session for the gyroscope: time (s, at 204.8 Hz), raw rates,
    the rests at both ends of the turns of 360° about x, y and z (row ranges, 6), and imucal's
    own Ferraris calibration (``K_g``, ``R_g``, ``b_g``) from ``reference_outputs``."""

    time: Array
    gyro: Array
    poses: list[tuple[int, int]]
    reference: dict[str, Any]

    def fit(self) -> GyroFit:
        """The gyroscope fit on the three turns: each ends where it began (rotation the
        identity, 0.5° per axis), ±2000 °/s part (16.4 counts per °/s); only the scale along
        each turn's axis is determined (``allow_partial``)."""
        n = len(self.poses)
        return fit_gyro(
            self.time,
            self.gyro,
            self.poses,
            np.broadcast_to(np.eye(3), (n, 3, 3)),
            rotation_cov=np.broadcast_to(np.eye(3) * np.radians(0.5) ** 2, (n, 3, 3)),
            links=[0, 2, 4],
            gain_guess=16.4 * np.degrees(1.0),
            allow_partial=True,
        )


def imucal_turns(root: Path = DATA) -> ImucalTurns:
    """The rests are found from the gyroscope: the rows at each end of a turn where the rate,
    smoothed over 9 samples, is within 20 counts of the still rate, less 5 rows of margin."""
    import pandas as pd

    folder = root / "imucal"
    d = pd.read_csv(folder / "annotated_session.csv").sort_values("samples")
    ref = json.loads((folder / "reference_outputs" / "example_cal.json").read_text())
    g = d[["gyr_x", "gyr_y", "gyr_z"]].to_numpy(float)
    t = d["samples"].to_numpy(float) / 204.8
    part = d["part"].to_numpy()
    still = np.median(g[d["part"].str.endswith(("_p", "_a")).to_numpy()], axis=0)
    poses = []
    for name in ("x_rot", "y_rot", "z_rot"):
        rows = np.flatnonzero(part == name)
        quiet = np.convolve(np.linalg.norm(g[rows] - still, axis=1), np.ones(9) / 9, "same") < 20
        first, last = int(np.argmin(quiet)), len(rows) - int(np.argmin(quiet[::-1]))
        poses += [(rows[0], rows[0] + first - 5), (rows[0] + last + 5, rows[-1] + 1)]
    return ImucalTurns(t, g, poses, ref)


def load(name: str, root: Path = DATA) -> RealSet:
    """The set ``name`` of :data:`LOADERS`."""
    return LOADERS[name](root)


# --------------------------------------------------------------------------- split half
def split_half_names(cal: fieldcal.Calibration) -> list[str]:
    """The parameters the split-half check compares: the dip (joint fits) and every bias."""
    names = ["dip_deg"] if cal.dip_std_deg is not None else []
    for s in ("accel", "mag"):
        if getattr(cal, s) is not None:
            names += [f"{s}.bias[{j}]" for j in range(3)]
    return names


def parameter(cal: fieldcal.Calibration, name: str) -> float:
    """The value of a named parameter of :class:`fieldcal.ParameterCovariance` in ``cal``."""
    if name == "dip_deg":
        return float(cal.dip_deg)
    sensor, rest = name.split(".", 1)
    part, index = rest.rstrip("]").split("[")
    value = getattr(cal.sensor(sensor), part)
    return float(value[tuple(int(k) for k in index.split(","))])


@dataclass(frozen=True)
class SplitHalf:
    """RMS z over the compared parameters, each parameter's z, and the two halves' fits."""

    rms_z: float
    z: dict[str, float]
    halves: tuple[fieldcal.Calibration, fieldcal.Calibration]


def split_half(data: RealSet, **options: Any) -> SplitHalf:
    """Calibrate poses 0, 2, 4, … and 1, 3, 5, … separately and compare (module docstring).

    ``options`` go to :func:`fieldcal.calibrate` for both halves.
    """
    halves = []
    for start in (0, 1):
        part = data.subset(range(start, data.n_poses, 2))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            halves.append(fieldcal.calibrate(part.accel, part.mag, **options))
    a, b = halves
    z = {
        n: (parameter(a, n) - parameter(b, n))
        / float(np.hypot(a.covariance.std(n), b.covariance.std(n)))
        for n in split_half_names(a)
    }
    rms = float(np.sqrt(np.mean(np.square(list(z.values())))))
    return SplitHalf(rms, z, (a, b))
