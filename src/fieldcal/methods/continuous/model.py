"""The continuous-motion model: parameters, residuals and their analytic Jacobians.

One epoch per sample ``j`` with its rotation ``R_j`` (world NED → body, the body frame fixed by
the accelerometer's symmetric gain, fieldcal's gauge). Readings (``docs/methods/continuous.md``,
Eq. C1–C3)::

    a_j = K_a (R_j g + ℓ_j / g₀) + b_a + ε_a,j   g = GRAVITY = (0, 0, −1)           (C1)
    ℓ_j = ω̇_j × r + ω_j × (ω_j × r)             ω_j = K_g⁻¹ (r_j − b_g)          (C1a)
    m_j = K_m R_j h(δ) + b_m + ε_m,j         h = (cos δ, 0, sin δ)                 (C2)
    Log(R_{j+1} R_jᵀ Exp(ω̄_j Δt_j)) = ε_g,j  ω̄_j = K_g⁻¹ (r̄_j − b_g)              (C3)

``ℓ_j`` (m/s², ``g₀`` = :data:`STANDARD_GRAVITY`) is the acceleration of a sensor at the lever arm
``r`` (metres, body frame) from the point the hand turns about: tangential ``ω̇ × r`` and
centripetal ``ω × (ω × r)``, the rate ``ω_j`` and its derivative ``ω̇_j`` from the calibrated
gyroscope (the derivative a central difference over :data:`SLOPE_SECONDS` either side).
``ε_a`` holds the sensor's noise and the rest of the body's acceleration, the hand's
translation (a per-stretch variance, :mod:`.weights`), ``ε_m`` the magnetometer's noise,
``ε_g`` the gyroscope's noise integrated over the interval (:mod:`.preintegration`).
Rotations are perturbed on the left, in the body frame: ``R ← Exp(δ) R``.

Parameter vector (34): accelerometer gain (6, symmetric: xx, yy, zz, xy, xz, yz), bias (3);
magnetometer gain (9, row-major), bias (3); dip (1, radians); gyroscope gain (9), bias (3);
then the lever arm ``r`` (3, metres, :data:`LEVER`).

Temperature (issue 26, ``docs/methods/temperature.md``): when the log has a temperature, each
sensor's bias may be ``b + Σ_k c_k d_j^k`` with ``d_j = T_j − T_ref`` (``State.temps``, (K, 3)
per sensor, :data:`TEMP_SENSORS` order); the coefficients follow the 34 in the vector, and
``∂f_j/∂c_k = d_j^k I`` (the gyroscope's: its bias column times the held ``d^k``).

The lever arm's Jacobians (analytic, Eq. C1b)::

    ∂ℓ/∂r = [ω̇]× + [ω]×²,   ∂ℓ/∂ω = (ω·r) I + ω rᵀ − 2 r ωᵀ,   ∂ℓ/∂ω̇ = −[r]×
    ∂ω/∂K_g[a,b] = −(K_g⁻¹)[:, a] ω_b,   ∂ω/∂b_g = −K_g⁻¹,   ∂ω̇/∂K_g[a,b] = −(K_g⁻¹)[:, a] ω̇_b

so the accelerometer's residuals reach the gyroscope's gain and bias (:func:`accel_columns`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np
from numpy.typing import NDArray

from ...geometry.frames import GRAVITY, magnetic_derivative, magnetic_reference
from ...geometry.rotations import exp_so3, hat
from .covariates import interference_shift

__all__ = [
    "LEVER",
    "N_PARAMS",
    "SLICES",
    "STANDARD_GRAVITY",
    "TEMP_SENSORS",
    "Blocks",
    "Data",
    "KnotFactors",
    "State",
    "accel_block",
    "accel_columns",
    "accel_of",
    "columns",
    "mag_block",
    "mag_columns",
    "mag_of",
    "powers",
    "residuals",
]

Array = NDArray[np.float64]

#: Where each group of parameters sits in the parameter vector.
SLICES = {
    "accel": slice(0, 9),
    "mag": slice(9, 22),
    "gyro": slice(22, 34),
}
N_PARAMS = 34
#: Where the lever arm (metres) sits: after the 34 named parameters, before any temperature
#: coefficients.
LEVER = slice(34, 37)
#: m/s² per g: the lever arm's acceleration in units of gravity (the accelerometer's gain
#: carries its units).
STANDARD_GRAVITY = 9.80665
#: Seconds either side of a sample over which the rate's derivative is taken (a central
#: difference: a shorter span passes the gyroscope's noise, a longer one smooths a fast turn).
SLOPE_SECONDS = 0.01
#: The sensors whose bias may carry temperature terms, in the parameter vector's order.
TEMP_SENSORS = ("accel", "mag", "gyro")
#: (row, column) of the accelerometer's six symmetric gain parameters.
SYM = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@dataclass
class Data:
    """The readings as logged (raw units), the times (s) and how the gyroscope's rate is
    held over an interval (:mod:`.preintegration`)."""

    time: Array
    accel: Array
    mag: Array
    gyro: Array
    hold: str = "midpoint"
    #: ``T_j − T_ref`` per sample (K), when the log has a temperature.
    temperature: Array | None = None
    #: The raw rate's derivative at each sample (rad/s², :func:`rate_slope`); computed from
    #: the whole log when not given (a chunk of it must carry its slice).
    gyro_slope: Array | None = None
    #: Knots only (:mod:`.knots`): each row the mean over a window of samples, ``M_k`` (n, 3, 3)
    #: the mean turn from the knot to the window's samples (``R_i = ΔR_i R_k``), the raw
    #: rates' mean outer product (n, 3, 3, for the lever arm's mean acceleration) and the
    #: gyroscope pre-integrated between consecutive knots.
    mixing: Array | None = None
    gyro_second: Array | None = None
    #: ``D_c`` (n, 3, 3, 12): ``∂(M_k u)/∂(K_g, b_g) = Σ_c u_c D_c`` (:mod:`.knots`).
    mixing_jacobian: Array | None = None
    factors: KnotFactors | None = None
    #: The interference term's inputs less their means (n, k) (:mod:`.covariates`), or none.
    inputs: Array | None = None

    def __post_init__(self) -> None:
        if self.gyro_slope is None:
            self.gyro_slope = rate_slope(self.time, self.gyro)

    def rows(self, lo: int, stop: int) -> Data:
        """Rows ``lo..stop−1`` (a chunk): every per-row array sliced (covariates included,
        whatever their name), the knots' factors ``lo..stop−2`` (those between the rows)."""
        n = len(self.time)
        changes: dict[str, object] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray) and value.ndim >= 1 and len(value) == n:
                changes[f.name] = value[lo:stop]
        if self.factors is not None:
            changes["factors"] = self.factors.rows(lo, max(lo, stop - 1))
        return replace(self, **changes)  # type: ignore[arg-type]


@dataclass
class KnotFactors:
    """The gyroscope pre-integrated between consecutive knots (:mod:`.knots`): at the gyroscope
    parameters ``anchor`` the turn ``Γ̂_k`` (m, 3, 3) from knot ``k`` to ``k + 1`` (body frame,
    ``R_{k+1} = Γ_kᵀ R_k``), its first-order change with those parameters ``Γ(θ) = Γ̂ Exp(G
    (θ − anchor))`` (``G``: (m, 3, 12 + 3 K), gain row-major, bias, then temperature orders),
    and ``Σ Δt²`` over its intervals (m,): its noise is ``σ_ω² Σ Δt²`` per axis."""

    turn: Array
    jacobian: Array
    dt2: Array
    anchor: Array

    def rows(self, lo: int, stop: int) -> KnotFactors:
        return KnotFactors(
            self.turn[lo:stop], self.jacobian[lo:stop], self.dt2[lo:stop], self.anchor
        )


def rate_slope(time: Array, gyro: Array) -> Array:
    """``ṙ_j`` (n, 3): the raw rate's central difference over :data:`SLOPE_SECONDS` either
    side (at least one sample), one-sided at the ends."""
    n = len(time)
    if n < 2:
        return np.zeros_like(gyro)
    rate = 1.0 / float(np.median(np.diff(time)))
    h = max(1, round(SLOPE_SECONDS * rate))
    hi = np.minimum(np.arange(n) + h, n - 1)
    lo = np.maximum(np.arange(n) - h, 0)
    out: Array = (gyro[hi] - gyro[lo]) / (time[hi] - time[lo])[:, None]
    return out


@dataclass
class State:
    """Parameters and trajectory being fitted."""

    accel_gain: Array
    accel_bias: Array
    mag_gain: Array
    mag_bias: Array
    dip: float
    gyro_gain: Array
    gyro_bias: Array
    rotations: Array
    #: Temperature coefficients per sensor, (K, 3) (raw units per K^k); absent: none.
    temps: dict[str, Array] = field(default_factory=dict)
    #: The lever arm ``r`` (metres, body frame, Eq. C1a).
    lever: Array = field(default_factory=lambda: np.zeros(3))
    #: The magnetometer's interference coefficients (k, 3) (:mod:`.covariates`, Eq. C2i).
    interference: Array = field(default_factory=lambda: np.zeros((0, 3)))

    def copy(self) -> State:
        return State(
            self.accel_gain.copy(),
            self.accel_bias.copy(),
            self.mag_gain.copy(),
            self.mag_bias.copy(),
            float(self.dip),
            self.gyro_gain.copy(),
            self.gyro_bias.copy(),
            self.rotations.copy(),
            {s: c.copy() for s, c in self.temps.items()},
            self.lever.copy(),
            self.interference.copy(),
        )

    def vector(self) -> Array:
        """The 34 parameters in the order of :data:`SLICES`, the lever arm (:data:`LEVER`), then
        the temperature coefficients (:data:`TEMP_SENSORS` order, each ``(K, 3)`` row-major)."""
        Ka = self.accel_gain
        return np.concatenate(
            [
                [Ka[r, c] for r, c in SYM],
                self.accel_bias,
                self.mag_gain.ravel(),
                self.mag_bias,
                [self.dip],
                self.gyro_gain.ravel(),
                self.gyro_bias,
                self.lever,
                *(self.temps[s].ravel() for s in TEMP_SENSORS if s in self.temps),
                self.interference.ravel(),  # interference (:mod:`.covariates`)
            ]
        )

    def updated(self, dp: Array, dR: Array) -> State:
        """The state moved by ``dp`` and the rotations by ``Exp(dR_j) R_j``."""
        from_vec = self.vector() + dp
        Ka = np.zeros((3, 3))
        for k, (r, c) in enumerate(SYM):
            Ka[r, c] = Ka[c, r] = from_vec[k]
        temps, at = {}, LEVER.stop
        for s in TEMP_SENSORS:
            if s in self.temps:
                size = self.temps[s].size
                temps[s] = from_vec[at : at + size].reshape(-1, 3)
                at += size
        interference = from_vec[at : at + self.interference.size].reshape(-1, 3)
        return State(
            Ka,
            from_vec[6:9],
            from_vec[9:18].reshape(3, 3),
            from_vec[18:21],
            float(from_vec[21]),
            from_vec[22:31].reshape(3, 3),
            from_vec[31:34],
            exp_so3(dR) @ self.rotations,
            temps,
            from_vec[LEVER],
            interference,
        )


def columns(state: State, sensor: str) -> NDArray[np.intp]:
    """Indices in the parameter vector of ``sensor``'s parameters: its slice of
    :data:`SLICES`, then its temperature coefficients (if any)."""
    sl = SLICES[sensor]
    base = np.arange(sl.start, sl.stop)
    at = LEVER.stop
    for s in TEMP_SENSORS:
        if s not in state.temps:
            continue
        size = state.temps[s].size
        if s == sensor:
            base = np.concatenate([base, np.arange(at, at + size)])
        at += size
    if sensor == "mag" and state.interference.size:  # interference (:mod:`.covariates`)
        base = np.concatenate([base, np.arange(at, at + state.interference.size)])
    return base


def accel_columns(state: State) -> NDArray[np.intp]:
    """The columns :func:`accel_block`'s parameter Jacobian fills: the accelerometer's
    (:func:`columns`), the lever arm's, then the gyroscope's gain and bias (through ``ω``)."""
    return np.concatenate(
        [columns(state, "accel"), np.arange(LEVER.start, LEVER.stop), np.arange(22, 34)]
    )


def lever_terms(
    state: State, raw: Array, slope: Array, second: Array | None = None
) -> tuple[Array, Array, Array]:
    """Eq. C1a–C1b at every sample: ``ℓ`` (n, 3, m/s²), ``∂ℓ/∂r`` (n, 3, 3) and ``∂ℓ/∂(K_g,
    b_g)`` (n, 3, 12), from the raw rates and their derivative ``slope``.

    A knot's (``second``: the raw rates' mean outer product over its window, ``raw`` and
    ``slope`` their means) is the window's mean, exactly: ``ℓ`` is linear in ``ω̇`` and
    ``[ω]×² r = ω (ω·r) − |ω|² r`` is linear in ``Ω = ⟨ω ωᵀ⟩``, so with ``u_a = K_g⁻¹[:, a]``
    the gain's column ``(a, b)`` is ``−u_a (Ω r)_b − (r·u_a) Ω[:, b] + 2 r (Ω u_a)_b
    − (∂ℓ/∂ω̇ K_g⁻¹)[:, a] ω̇_b``; a sample's ``Ω`` is ``ω ωᵀ``."""
    Ginv = np.asarray(np.linalg.inv(state.gyro_gain), dtype=np.float64)
    x = raw - state.gyro_bias
    w = x @ Ginv.T
    wd = slope @ Ginv.T
    Om, d_lever = _lever_matrix(state, raw, wd, second, Ginv)
    r = state.lever
    ell = (d_lever @ r[:, None])[:, :, 0]
    wr = w @ r
    d_w = (
        wr[:, None, None] * np.eye(3)
        + w[:, :, None] * r[None, None, :]
        - 2.0 * r[None, :, None] * w[:, None, :]
    )
    B = -hat(r) @ Ginv  # ∂ℓ/∂ω̇ · K_g⁻¹
    n = len(raw)
    Omr = Om @ r  # (n, 3)
    OmU = Om @ Ginv  # (n, 3, 3): [b, a] = (Ω u_a)_b
    rU = r @ Ginv  # (3,): r · u_a
    d_gyro = np.empty((n, 3, 12))
    # column 3a + b
    # the terms that are outer products, u_a (Ω r)_b and (∂ℓ/∂ω̇ K_g⁻¹)[:, a] ω̇_b, as one
    # matrix product (9 × 2)(2 × 3n); the other two broadcast
    outer = np.stack([Ginv, B]).reshape(2, 9).T @ np.stack([Omr, wd]).reshape(2, 3 * n)
    gain = np.moveaxis(outer.reshape(3, 3, n, 3), 2, 0)
    gain = gain + rU[None, None, :, None] * Om[:, :, None, :]
    gain -= 2.0 * r[None, :, None, None] * np.swapaxes(OmU, 1, 2)[:, None, :, :]
    d_gyro[:, :, :9] = -gain.reshape(n, 3, 9)
    d_gyro[:, :, 9:] = -(d_w @ Ginv)
    return ell, d_lever, d_gyro


def _lever_matrix(
    state: State, raw: Array, wd: Array, second: Array | None, Ginv: Array
) -> tuple[Array, Array]:
    """``Ω`` (n, 3, 3, the calibrated rates' outer product or a knot's mean of it) and
    ``∂ℓ/∂r = [ω̇]× + Ω − tr(Ω) I`` (Eq. C1b)."""
    if second is None:
        w = (raw - state.gyro_bias) @ Ginv.T
        Om = w[:, :, None] * w[:, None, :]
    else:  # ⟨(r − b)(r − b)ᵀ⟩ = ⟨r rᵀ⟩ − b r̄ᵀ − r̄ bᵀ + b bᵀ, mapped by K_g⁻¹
        b = state.gyro_bias
        xx = second - b[None, :, None] * raw[:, None, :] - raw[:, :, None] * b[None, None, :]
        Om = Ginv @ (xx + np.outer(b, b)) @ Ginv.T
    trace = np.trace(Om, axis1=1, axis2=2)
    return Om, hat(wd) + Om - trace[:, None, None] * np.eye(3)


def powers(d: Array, order: int) -> Array:
    """``d^k`` for ``k = 1..order``: (n, order). A knot's ``d`` is already its window's mean
    powers (n, K ≥ order, :mod:`.knots`): their first ``order`` columns."""
    if d.ndim == 2:
        return np.asarray(d[:, :order], dtype=np.float64)
    return np.asarray(d[:, None] ** np.arange(1, order + 1)[None, :], dtype=np.float64)


def _thermal(state: State, sensor: str, reading: Array, d: Array | None) -> tuple[Array, Array]:
    """The reading less its temperature shift ``Σ c_k d^k`` and the shift's Jacobian
    (n, 3, 3K) with respect to the coefficients (``d^k I`` per order)."""
    coef = state.temps.get(sensor)
    n = len(reading)
    if coef is None or d is None or len(coef) == 0:
        return reading, np.zeros((n, 3, 0))
    P = powers(d, len(coef))
    J = (P[:, None, :, None] * np.eye(3)[None, :, None, :]).reshape(n, 3, 3 * len(coef))
    return reading - P @ coef, J


@dataclass
class Blocks:
    """One sensor's whitening-free residuals ``r = y − f`` (n, 3), the Jacobian of ``f`` with
    respect to the sample's rotation (n, 3, 3) and to the sensor's parameter slice (n, 3, p)."""

    residual: Array
    rotation: Array
    params: Array


def accel_block(
    state: State,
    accel: Array,
    temperature: Array | None = None,
    gyro: Array | None = None,
    slope: Array | None = None,
    mixing: Array | None = None,
    second: Array | None = None,
    spread: tuple[Array, Array] | None = None,
) -> Blocks:
    """Eq. C1: residuals and Jacobians of the accelerometer at every sample; with
    ``temperature`` (``T_j − T_ref``) and terms in ``state.temps``, the bias follows it. With
    the raw rates ``gyro`` and their derivative ``slope`` the lever arm's acceleration is in
    the prediction and the Jacobian has :func:`accel_columns`' columns; without, only the
    accelerometer's (:func:`columns`). Knots (:mod:`.knots`): ``mixing`` ``M_k`` turns the
    knot's gravity into the window's mean, ``M_k R_k g`` (``∂/∂δ = −K M [R g]×``), and
    ``second`` gives the lever arm's window mean (:func:`lever_terms`); ``spread`` (``D_c``
    and ``θ − θ̂``, :func:`_mixed`) how ``M_k`` follows the gyroscope's gain and bias."""
    accel, Jc = _thermal(state, "accel", accel, temperature)
    u = state.rotations @ GRAVITY  # (n, 3) body-frame "up"
    Ka = state.accel_gain
    Jt = -Ka @ hat(u)  # d(K R g)/dδ = −K [R g]×
    d_mix = None
    if mixing is not None:
        Jt = -Ka @ (mixing @ hat(u))
        u, d_mix = _mixed(u, mixing, spread)
    lever = None
    if gyro is not None and slope is not None:
        lever = lever_terms(state, gyro, slope, second)
        u = u + lever[0] / STANDARD_GRAVITY
    pred = u @ Ka.T + state.accel_bias
    n = len(u)
    Jp = np.zeros((n, 3, 9))
    for k, (r, c) in enumerate(SYM):
        Jp[:, r, k] = u[:, c]
        if r != c:
            Jp[:, c, k] = u[:, r]
    Jp[:, :, 6:9] = np.eye(3)
    if Jc.shape[2]:
        Jp = np.concatenate([Jp, Jc], axis=2)
    if lever is not None:
        K = Ka / STANDARD_GRAVITY
        d_gyro = K @ lever[2]
        if d_mix is not None:
            d_gyro = d_gyro + Ka @ d_mix
        Jp = np.concatenate([Jp, K @ lever[1], d_gyro], axis=2)
    return Blocks(accel - pred, Jt, Jp)


def _mixed(
    u: Array, mixing: Array, spread: tuple[Array, Array] | None
) -> tuple[Array, Array | None]:
    """``M_k u`` (n, 3) for a knot's direction ``u = R_k g`` or ``R_k h`` and its Jacobian with
    respect to the gyroscope's gain and bias (n, 3, 12): ``M`` computed at the anchor ``θ̂``
    and moved to first order, ``M(θ) u = M̂ u + Σ_c u_c D_c (θ − θ̂)`` (:mod:`.knots`)."""
    out = (mixing @ u[:, :, None])[:, :, 0]
    if spread is None:
        return out, None
    D, moved = spread
    J = np.einsum("nc,ncij->nij", u, D)
    return out + J @ moved, J


def _spread(state: State, data: Data) -> tuple[Array, Array] | None:
    """``(D_c, θ − θ̂)`` of knots (:func:`_mixed`); ``None`` for samples."""
    if data.mixing_jacobian is None or data.factors is None:
        return None
    theta = np.concatenate([state.gyro_gain.ravel(), state.gyro_bias])
    return data.mixing_jacobian, theta - data.factors.anchor[:12]


def mag_columns(state: State, data: Data) -> NDArray[np.intp]:
    """The columns :func:`mag_of`'s parameter Jacobian fills: the magnetometer's
    (:func:`columns`), then for knots the gyroscope's gain and bias (through ``M_k``)."""
    own = columns(state, "mag")
    return own if data.mixing_jacobian is None else np.concatenate([own, np.arange(22, 34)])


def accel_of(state: State, data: Data) -> Blocks:
    """:func:`accel_block` of a whole log (or chunk, or knots) with its lever arm (Eq. C1–C1b)."""
    return accel_block(
        state,
        data.accel,
        data.temperature,
        data.gyro,
        data.gyro_slope,
        data.mixing,
        data.gyro_second,
        _spread(state, data),
    )


def mag_of(state: State, data: Data) -> Blocks:
    """:func:`mag_block` of a whole log (or chunk, or knots: :func:`mag_columns`)."""
    return mag_block(
        state, data.mag, data.temperature, data.mixing, _spread(state, data), data.inputs
    )


def mag_block(
    state: State,
    mag: Array,
    temperature: Array | None = None,
    mixing: Array | None = None,
    spread: tuple[Array, Array] | None = None,
    inputs: Array | None = None,
) -> Blocks:
    """Eq. C2: residuals and Jacobians of the magnetometer at every sample (temperature and
    a knot's ``mixing`` as in :func:`accel_block`; the interference term in ``inputs``,
    Eq. C2i)."""
    mag, Jc = _thermal(state, "mag", mag, temperature)
    mag, Ji = interference_shift(state.interference, mag, inputs)
    Jc = np.concatenate([Jc, Ji], axis=2)
    v = state.rotations @ magnetic_reference(state.dip)
    dv = state.rotations @ magnetic_derivative(state.dip)
    Km = state.mag_gain
    Jt = -Km @ hat(v)
    d_mix = None
    if mixing is not None:
        Jt = -Km @ (mixing @ hat(v))
        v, d_mix = _mixed(v, mixing, spread)
        dv = (mixing @ dv[:, :, None])[:, :, 0]
    pred = v @ Km.T + state.mag_bias
    n = len(v)
    Jp = np.zeros((n, 3, 13))
    for r in range(3):
        Jp[:, r, 3 * r : 3 * r + 3] = v
    Jp[:, :, 9:12] = np.eye(3)
    Jp[:, :, 12] = dv @ Km.T
    if Jc.shape[2]:
        Jp = np.concatenate([Jp, Jc], axis=2)
    if d_mix is not None:
        Jp = np.concatenate([Jp, Km @ d_mix], axis=2)
    return Blocks(mag - pred, Jt, Jp)


def residuals(state: State, data: Data) -> tuple[Array, Array]:
    """The accelerometer's and magnetometer's residuals (n, 3) of samples or knots (Eq.
    C1–C2), without the Jacobians :func:`accel_of` and :func:`mag_of` also form (for the
    cost): ``ℓ = ω̇ × r + Ω r − tr(Ω) r`` with ``Ω = ω ωᵀ`` or a knot's mean."""
    Ginv = np.asarray(np.linalg.inv(state.gyro_gain), dtype=np.float64)
    w = (data.gyro - state.gyro_bias) @ Ginv.T
    assert data.gyro_slope is not None  # Data computes it
    wd = data.gyro_slope @ Ginv.T
    r = state.lever
    if data.gyro_second is None:
        ell = np.cross(wd, r) + w * (w @ r)[:, None] - np.sum(w * w, axis=1)[:, None] * r
    else:
        _, d_lever = _lever_matrix(state, data.gyro, wd, data.gyro_second, Ginv)
        ell = (d_lever @ r[:, None])[:, :, 0]
    accel = _thermal(state, "accel", data.accel, data.temperature)[0]
    mag = _thermal(state, "mag", data.mag, data.temperature)[0]
    mag = interference_shift(state.interference, mag, data.inputs)[0]
    up = state.rotations @ GRAVITY
    field = state.rotations @ magnetic_reference(state.dip)
    if data.mixing is not None:
        spread = _spread(state, data)
        up, field = _mixed(up, data.mixing, spread)[0], _mixed(field, data.mixing, spread)[0]
    up = up + ell / STANDARD_GRAVITY
    ra: Array = accel - (up @ state.accel_gain.T + state.accel_bias)
    rm: Array = mag - (field @ state.mag_gain.T + state.mag_bias)
    return ra, rm
