"""Noise characterisation: the overlapping Allan deviation, the noise-model fit, the log path
and the Kalibr imu.yaml (fieldcal.stats.allan, fieldcal.noise, fieldcal.output.noise_figures)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import fieldcal
from fieldcal.errors import InputError
from fieldcal.noise import STANDARD_GRAVITY, characterise_noise
from fieldcal.stats.allan import (
    allan_deviation,
    chi2_quantile,
    cluster_sizes,
    correlation,
    equivalent_dof,
    fit_noise_model,
)

RATE = 100.0


def _white(rng: np.random.Generator, n: int, density: float, rate: float = RATE) -> np.ndarray:
    """White rate noise of density ``density`` (unit/√Hz): per-sample σ = N √rate."""
    return rng.normal(0.0, density * math.sqrt(rate), (n, 3))


def _walk(rng: np.random.Generator, n: int, k: float, rate: float = RATE) -> np.ndarray:
    """Rate random walk of strength ``k`` (unit/s/√Hz): steps of σ = K / √rate."""
    return np.cumsum(rng.normal(0.0, k / math.sqrt(rate), (n, 3)), axis=0)


def _slow_avar(records: list[np.ndarray], m: int) -> float:
    """The overlapping Allan variance by its definition, one cluster pair at a time."""
    total, count = 0.0, 0
    for y in records:
        for k in range(len(y) - 2 * m + 1):
            total += (y[k + m : k + 2 * m].mean() - y[k : k + m].mean()) ** 2
            count += 1
    return total / (2 * count)


# ----------------------------------------------------------------------------- estimator
def test_overlapping_estimator_equals_its_definition_across_records_and_nan_breaks():
    rng = np.random.default_rng(3)
    first = rng.integers(-50, 50, 41).astype(float)
    second = rng.integers(-50, 50, 23).astype(float) + 1000.0  # another pose: another mean
    broken = rng.integers(-50, 50, 30).astype(float)
    broken[12] = np.nan  # splits the record into 12 and 17 samples
    curve = allan_deviation([first, second, broken], rate=4.0, per_decade=20)
    runs = [first, second, broken[:12], broken[13:]]
    for m, tau, avar, count in zip(
        curve.m, curve.taus, curve.avar[:, 0], curve.counts, strict=True
    ):
        assert avar == pytest.approx(_slow_avar(runs, int(m)), rel=1e-12)
        assert count == sum(max(0, len(r) - 2 * int(m) + 1) for r in runs)
        assert tau == m / 4.0
    assert curve.m[-1] == (41 - 1) // 2  # the longest record reaches the last cluster size
    assert curve.lengths == (41, 23, 12, 17)


def test_concatenating_stretches_is_not_what_is_computed():
    """Two poses with different means: concatenated, the step reads as noise at long τ."""
    rng = np.random.default_rng(4)
    a, b = rng.normal(0, 1, 400), rng.normal(50, 1, 400)
    apart = allan_deviation([a, b], RATE)
    joined = allan_deviation(np.concatenate([a, b]), RATE)
    assert apart.adev[-1, 0] < 1.0 < joined.adev[-1, 0]


def test_cluster_sizes_log_spaced_and_unique():
    m = cluster_sizes(100001, per_decade=10)
    assert m[0] == 1 and m[-1] == 50000 and np.all(np.diff(m) > 0)
    ratios = m[1:] / m[:-1]
    assert ratios[-10:].max() < 10**0.11 and ratios[-10:].min() > 10**0.09


def test_allan_deviation_scales_with_the_unit():
    rng = np.random.default_rng(5)
    y = _white(rng, 5000, 0.02) + _walk(rng, 5000, 0.01)
    base, scaled = allan_deviation(y, RATE), allan_deviation(y * 57.29578, RATE)
    np.testing.assert_allclose(scaled.adev, base.adev * 57.29578, rtol=1e-10)
    np.testing.assert_allclose(scaled.lower, base.lower * 57.29578, rtol=1e-10)
    fit, fit_scaled = fit_noise_model(base), fit_noise_model(scaled)
    for name in ("noise_density", "random_walk", "noise_density_std", "random_walk_std"):
        np.testing.assert_allclose(
            getattr(fit_scaled, name), getattr(fit, name) * 57.29578, rtol=1e-6, atol=1e-15
        )
    assert fit_scaled.tau_range == fit.tau_range


# ----------------------------------------------------------------------------- χ², EDF, band
@pytest.mark.parametrize("p", [0.025, 0.1585, 0.8415, 0.975])
def test_chi2_quantile_matches_scipy(p):
    from scipy.stats import chi2

    dof = np.array([0.7, 1.0, 2.5, 7.0, 30.0, 99.0, 101.0, 1e3, 1e6])
    np.testing.assert_allclose(chi2_quantile(p, dof), chi2.ppf(p, dof), rtol=2e-4)


def test_correlation_table_matches_the_estimators_frequency_response():
    """The tabulated correlation of estimates k octaves apart, recomputed from
    ∫ S² |H_i|² |H_j|² df (|H_m|² = 4 sin⁴(π m f) / sin²(π f)) at m_i = 16."""
    f = (np.arange(2**18) + 0.5) / 2**19
    sf = np.sin(np.pi * f)
    spectra = {"white": np.ones_like(f), "flicker": 1 / f, "random_walk": 1 / (4 * sf**2)}

    def h2(m: int) -> np.ndarray:
        return 4 * np.sin(np.pi * m * f) ** 4 / sf**2

    for noise, s in spectra.items():
        for k in (1, 2, 3):
            hi, hj = h2(16), h2(16 * 2**k)
            rho = np.sum(s**2 * hi * hj) / np.sqrt(np.sum(s**2 * hi**2) * np.sum(s**2 * hj**2))
            assert correlation(noise, k) == pytest.approx(rho, abs=0.01), (noise, k)


def test_white_noise_band_covers_the_truth_at_its_confidence():
    """400 short white-noise records: the 68.3 % band holds the true σ(τ) = σ/√m about 68 %
    of the time at each τ (binomial sd 2.3 %)."""
    rng = np.random.default_rng(6)
    sigma, hits, total = 1.0, None, 0
    for _ in range(400):
        curve = allan_deviation(rng.normal(0, sigma, 600), RATE)
        truth = sigma / np.sqrt(curve.m.astype(float))
        inside = (curve.lower[:, 0] <= truth) & (truth <= curve.upper[:, 0])
        hits = inside.astype(int) if hits is None else hits + inside
        total += 1
    rate = hits[curve.m <= 60] / total  # τ with at least ten clusters
    assert np.all(np.abs(rate - 0.683) < 0.08), rate


def test_edf_of_several_records_adds_up():
    one = equivalent_dof([1000], [1, 10, 100], "white")
    four = equivalent_dof([1000] * 4, [1, 10, 100], "white")
    np.testing.assert_allclose(four, 4 * one)
    assert equivalent_dof([9], [5], "random_walk")[0] == 0  # no cluster pair fits
    assert equivalent_dof([10], [5], "random_walk")[0] >= 1  # one pair: one squared difference


# ----------------------------------------------------------------------------- the fit
def test_white_noise_gives_its_density_within_its_confidence():
    rng = np.random.default_rng(7)
    density = 0.013  # rad/s/√Hz: per-sample σ = N √f
    fit = fit_noise_model(allan_deviation(_white(rng, 100_000, density), RATE))
    z = (fit.noise_density - density) / fit.noise_density_std
    assert np.all(np.abs(z) < 3.5), z
    # the standard error is the estimator's, not an artefact: about √(3/(4n)) relative
    relative = fit.noise_density_std / density
    assert np.all((relative > 0.5 * math.sqrt(0.75 / 1e5)) & (relative < 2 * math.sqrt(0.75 / 1e5)))
    assert np.all(fit.random_walk < 3 * fit.random_walk_std)  # none there, none found
    assert np.all(fit.bias_instability < 3 * fit.bias_instability_std)
    assert fit.tau_range[0] == pytest.approx(1 / RATE)


def test_random_walk_is_recovered():
    rng = np.random.default_rng(8)
    k = 2e-3
    y = _white(rng, 400_000, 1e-3) + _walk(rng, 400_000, k)
    fit = fit_noise_model(allan_deviation(y, RATE))
    z = (fit.random_walk - k) / fit.random_walk_std
    assert np.all(np.abs(z) < 3.5), (fit.random_walk, fit.random_walk_std)
    assert np.all(fit.random_walk_std < 0.25 * k)  # resolved, not a wide interval
    assert np.all(np.abs(fit.noise_density - 1e-3) < 3.5 * fit.noise_density_std)


def test_white_plus_walk_has_no_bias_instability():
    rng = np.random.default_rng(9)
    n_true, k_true = 0.01, 1e-3
    y = _white(rng, 300_000, n_true) + _walk(rng, 300_000, k_true)
    fit = fit_noise_model(allan_deviation(y, RATE))
    assert np.all(np.abs(fit.noise_density - n_true) < 3.5 * fit.noise_density_std)
    assert np.all(np.abs(fit.random_walk - k_true) < 3.5 * fit.random_walk_std)
    assert np.all(fit.bias_instability < 3 * fit.bias_instability_std), (
        fit.bias_instability,
        fit.bias_instability_std,
    )
    # the flat floor B would be read from lies far above 0.664 B: the floor is N and K's
    crossing = math.sqrt(3) * n_true / k_true
    assert fit.tau_range[0] < crossing < fit.tau_range[1]


def test_low_pass_filtered_white_noise_fits_from_longer_tau():
    """A moving average of 4 samples (a sensor's filter) makes the short τ read low (by a
    share falling as 1/τ): the fit starts later and comes nearer the density than a fit from
    the first τ; what is left is a few per cent (docs/noise.md)."""
    rng = np.random.default_rng(10)
    raw = rng.normal(0.0, 1.0, (200_000, 1))
    filtered = np.convolve(raw[:, 0], np.ones(4) / 4, mode="valid")[:, None]
    curve = allan_deviation(filtered, RATE)
    fit = fit_noise_model(curve)
    naive = fit_noise_model(curve, tau_min=1 / RATE)
    assert fit.low_pass and fit.tau_range[0] > 10 / RATE and not naive.low_pass
    density = 1.0 / math.sqrt(RATE)  # the filter keeps the spectrum at low frequency
    error, naive_error = (
        abs(fit.noise_density[0] / density - 1),
        abs(naive.noise_density[0] / density - 1),
    )
    assert error < 0.05 and error < naive_error


def test_fit_needs_three_taus():
    curve = allan_deviation(np.arange(12.0) % 3, RATE)
    with pytest.raises(InputError, match="too few to fit"):
        fit_noise_model(curve, tau_min=1.0)


# ----------------------------------------------------------------------------- the log path
def _log(rng, seconds=(40.0, 40.0), moving=5.0, gyro_unit_scale=1.0, accel_scale=1.0):
    """A still-move-still log: two rests in different orientations, a turn between."""
    parts_a, parts_g = [], []
    for i, s in enumerate(seconds):
        n = int(s * RATE)
        a = _white(rng, n, 2e-4) + np.array([0.0, 0.0, 1.0] if i == 0 else [0.0, 1.0, 0.0])
        g = _white(rng, n, 0.005)
        parts_a.append(a)
        parts_g.append(g)
        if i < len(seconds) - 1:
            m = int(moving * RATE)
            t = np.arange(m) / RATE
            swing = 0.5 * np.sin(2 * np.pi * 0.4 * t)[:, None] * np.ones((1, 3))
            parts_a.append(_white(rng, m, 2e-4) + swing)
            parts_g.append(_white(rng, m, 0.005) + 30 * swing)
    a, g = np.concatenate(parts_a) * accel_scale, np.concatenate(parts_g) * gyro_unit_scale
    t = np.arange(len(a)) / RATE
    return {
        "t": t,
        "ax": a[:, 0],
        "ay": a[:, 1],
        "az": a[:, 2],
        "gx": g[:, 0],
        "gy": g[:, 1],
        "gz": g[:, 2],
    }


def test_log_still_stretches_leave_the_motion_out():
    report = characterise_noise(_log(np.random.default_rng(11)), gyro_unit="rad/s", accel_unit="g")
    assert report.still == "detect" and len(report.stretches) == 2
    assert report.seconds < 80 and report.longest > 35
    gyro = report.fits["gyro"]
    # the motion (30 rad/s swings) would dominate every τ if it were included
    assert np.all(np.abs(gyro.noise_density - 0.005) < 4 * gyro.noise_density_std)
    accel = report.fits["accel"]
    assert np.all(np.abs(accel.noise_density - 2e-4) < 4 * accel.noise_density_std)
    assert gyro.adev.shape == gyro.lower.shape == (len(gyro.taus), 3)
    assert np.all(gyro.lower <= gyro.adev) and np.all(gyro.adev <= gyro.upper)


def test_one_long_still_recording_is_taken_whole():
    rng = np.random.default_rng(12)
    log = _log(rng, seconds=(120.0,))
    auto = characterise_noise(log, accel_unit="g", gyro_unit="rad/s")
    assert auto.still == "all" and auto.stretches == ((0, 12000),)
    forced = characterise_noise(log, accel_unit="g", gyro_unit="rad/s", still="detect")
    assert forced.still == "detect" and forced.longest < auto.longest


def _parse_yaml(text: str) -> dict[str, float]:
    """Flat ``key: number  # comment`` lines, as Kalibr's imu.yaml holds them (the one text
    value, ``rostopic``, left out)."""
    out: dict[str, float] = {}
    for line in text.splitlines():
        body = line.split("#", 1)[0].strip()
        if body:
            key, value = body.split(":", 1)
            if key.strip() != "rostopic":
                out[key.strip()] = float(value)
    return out


def test_kalibr_yaml_keys_and_unit_conversions():
    rng = np.random.default_rng(13)
    log = _log(rng, seconds=(200.0,))
    si = characterise_noise(log, accel_unit="m/s^2", gyro_unit="rad/s")
    # the same log with the gyroscope in deg/s and the accelerometer in g
    other = dict(log)
    for key in ("gx", "gy", "gz"):
        other[key] = log[key] * 180 / math.pi
    for key in ("ax", "ay", "az"):
        other[key] = log[key] / STANDARD_GRAVITY
    named = {
        f"{k}_dps" if k[0] == "g" else f"{k}_g" if k[0] == "a" else k: v for k, v in other.items()
    }
    converted = characterise_noise(named)  # units from the column names
    assert converted.fits["gyro"].unit == "deg/s" and converted.fits["accel"].unit == "g"
    a, b = _parse_yaml(si.kalibr_yaml()), _parse_yaml(converted.kalibr_yaml())
    assert set(a) == {
        "accelerometer_noise_density",
        "accelerometer_random_walk",
        "gyroscope_noise_density",
        "gyroscope_random_walk",
        "update_rate",
    }
    for key in a:
        assert b[key] == pytest.approx(a[key], rel=1e-5), key
    gyro = si.fits["gyro"]
    assert a["gyroscope_noise_density"] == pytest.approx(gyro.noise_density.max(), rel=1e-6)
    assert a["gyroscope_noise_density"] == pytest.approx(0.005, rel=0.05)
    assert a["accelerometer_noise_density"] == pytest.approx(2e-4, rel=0.05)
    assert a["update_rate"] == pytest.approx(RATE)
    try:
        import yaml  # PyYAML, when installed (not a dependency): Kalibr's own reader
    except ImportError:
        return
    loaded = yaml.safe_load(si.kalibr_yaml())
    assert loaded.pop("rostopic") == "/imu0"
    assert loaded == pytest.approx(a) and all(isinstance(v, float) for v in loaded.values())


def test_unresolved_random_walk_is_written_as_its_upper_bound():
    rng = np.random.default_rng(14)
    report = characterise_noise(_log(rng, seconds=(30.0,)), accel_unit="g", gyro_unit="rad/s")
    text = report.kalibr_yaml()
    gyro = report.fits["gyro"]
    assert not np.all(gyro.random_walk_resolved)
    bound = gyro.random_walk + 2 * gyro.random_walk_std
    written = _parse_yaml(text)["gyroscope_random_walk"]
    assert written == pytest.approx(bound[~gyro.random_walk_resolved].max(), rel=1e-6)
    assert "UPPER BOUND" in text and "does NOT inflate" in text


def test_calibration_gives_the_units():
    session = fieldcal.simulate("paper", seed=1)
    cal = fieldcal.calibrate(session.accel, session.mag, gravity=STANDARD_GRAVITY)
    rng = np.random.default_rng(15)
    log = _log(rng, seconds=(60.0,))
    report = characterise_noise(log, cal=cal, gyro_unit="deg/s")
    assert report.fits["accel"].unit == "m/s^2" and report.fits["accel"].si_scale == 1.0
    assert report.fits["gyro"].unit == "deg/s"
    with pytest.raises(InputError, match="accel_unit='g', but the calibration gives"):
        characterise_noise(log, cal=cal, accel_unit="g")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"gyro_unit": "rad/s"}, "accelerometer's unit is unknown; pass accel_unit"),
        ({"accel_unit": "g"}, "gyroscope's unit is unknown; pass gyro_unit"),
    ],
)
def test_unknown_units_refuse_the_yaml_in_one_line(options, message):
    report = characterise_noise(_log(np.random.default_rng(16), seconds=(20.0,)), **options)
    with pytest.raises(InputError, match=message) as error:
        report.kalibr_yaml()
    assert "\n" not in str(error.value)


def test_no_still_part_long_enough_for_one_second():
    rng = np.random.default_rng(17)
    log = _log(rng, seconds=(1.6, 1.6), moving=3.0)
    with pytest.raises(InputError, match="no still part long enough for τ = 1 s") as error:
        characterise_noise(log, still="detect")
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"still": "some"}, "still must be one of auto, detect, all"),
        ({"accel_unit": "furlong"}, "accel_unit must be one of g, mg, m/s"),
        ({"gyro_unit": -1.0}, "gyro_unit must be a unit name or a positive number"),
        ({"sensors": ("mag",)}, "no magnetometer columns found"),
        ({"rate": 0.0}, "rate must be a positive number"),
    ],
)
def test_option_errors_are_one_line(options, message):
    with pytest.raises(InputError, match=message) as error:
        characterise_noise(_log(np.random.default_rng(18), seconds=(5.0,)), **options)
    assert "\n" not in str(error.value)


def test_dropped_rows_and_pauses_end_a_stretch():
    log = _log(np.random.default_rng(21), seconds=(30.0,))
    log["gx"] = log["gx"].copy()
    log["gx"][1000] = np.nan  # dropped with drop_nan: no difference may span it
    log["t"] = log["t"].copy()
    log["t"][2000:] += 1.0  # a pause of the logger (100 periods)
    report = characterise_noise(log, still="all", drop_nan=True, accel_unit="g", gyro_unit="rad/s")
    assert report.stretches == ((0, 1000), (1001, 2000), (2000, 3000))
    assert report.fits["gyro"].curve.lengths == (1000, 999, 1000)


def test_no_rate_without_a_time_column():
    log = _log(np.random.default_rng(19), seconds=(5.0,))
    del log["t"]
    with pytest.raises(InputError, match=r"pass rate= \(--rate\)"):
        characterise_noise(log)
    assert characterise_noise(log, rate=RATE).rate == RATE


def test_report_to_dict_and_figure_files(tmp_path):
    pytest.importorskip("matplotlib", reason="matplotlib (the plot extra) not installed")
    from fieldcal.output.noise_figures import noise_figure, write_noise_figure

    report = characterise_noise(
        _log(np.random.default_rng(20), seconds=(20.0,)), accel_unit="g", gyro_unit="deg/s"
    )
    data = report.to_dict()
    json.dumps(data, allow_nan=False)  # plain JSON, as `fieldcal noise --json` prints it
    assert set(data["sensors"]) == {"accel", "gyro"}
    assert len(data["sensors"]["gyro"]["curve"]["taus"]) == len(report.fits["gyro"].taus)
    fig = noise_figure(report)
    assert len(fig.axes) == 2
    write_noise_figure(report, tmp_path / "allan.png")
    assert (tmp_path / "allan.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    write_noise_figure(report, tmp_path / "allan.html")
    page = (tmp_path / "allan.html").read_text()
    assert "gyroscope_noise_density" in page and "data:image/png;base64" in page
    assert sorted(p.name for p in tmp_path.iterdir()) == ["allan.html", "allan.png"]
    with pytest.raises(InputError, match=r"give a \.png or \.html file"):
        write_noise_figure(report, tmp_path / "allan.pdf")
