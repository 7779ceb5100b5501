"""The Earth's magnetic field where the user is: the World Magnetic Model.

The expected dip, total intensity and declination at a place and date come from the World
Magnetic Model (WMM) of NOAA's National Centers for Environmental Information and the
British Geological Survey, evaluated by pygeomag, whose version is pinned in ``pyproject.toml``
(``pygeomag==1.1.0``) so that a new model or coefficient file is a deliberate upgrade. The model
used is the one whose five-year span holds the date: WMM2015 (the out-of-cycle ``WMM2015v2``
release) for 2015–2019, WMM2020 for 2020–2024, WMM2025 for 2025–2029.

References: Chulliat, A. et al., *The US/UK World Magnetic Model for 2025-2030: Technical
Report*, NOAA NCEI and BGS (2025); the same report for 2020-2025 and 2015-2020 (its error
model, Section 4, gives the standard uncertainties stored here as ``*_std``: they include the
crustal field a global model cannot hold, averaged over the Earth, but not a building's steel).

Conventions (``docs/conventions.md``): the dip (inclination) is positive when the field points
below the horizon, as :func:`fieldcal.geometry.frames.magnetic_reference`; the declination is
positive east of true north; intensities are in nanotesla; the altitude is in metres above the
WGS 84 ellipsoid.
"""

from __future__ import annotations

import datetime as _dt
import functools
import importlib
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ._frozen import ArrayDataclass
from .errors import InputError

if TYPE_CHECKING:
    import pygeomag

__all__ = [
    "DIP_ALLOWANCE_DEG",
    "FieldReference",
    "expected_field",
    "parse_date",
    "parse_location",
]

#: Allowance (degrees) for a site's local anomaly in the dip, beyond the model's uncertainty:
#: indoor sites and vehicles shift the field's direction by a degree or two without being
#: "disturbed" enough to spoil a calibration; beyond it the site is suspect.
DIP_ALLOWANCE_DEG = 2.0

#: (first year, last year, pygeomag coefficient file, model name)
_MODELS = (
    (2015, 2019, "wmm/WMM_2015v2.COF", "WMM2015v2"),
    (2020, 2024, "wmm/WMM_2020.COF", "WMM2020"),
    (2025, 2029, "wmm/WMM_2025.COF", "WMM2025"),
)
_PINNED = "1.1.0"
#: pygeomag's altitude range (km above the ellipsoid), as the WMM's.
_ALTITUDE_KM = (-1.0, 850.0)


@dataclass(frozen=True, eq=False)
class FieldReference(ArrayDataclass):
    """The field the World Magnetic Model expects at a place and date.

    Attributes
    ----------
    model : str
        The model, e.g. ``"WMM2025"``.
    date : str
        The date evaluated, ISO ``YYYY-MM-DD``.
    latitude_deg, longitude_deg, altitude_m : float
        The place: geodetic latitude (north positive), longitude (east positive), altitude above
        the WGS 84 ellipsoid in metres.
    dip_deg, dip_std_deg : float
        The inclination (positive below the horizon) and its standard uncertainty.
    intensity, intensity_std : float
        The total intensity and its standard uncertainty, in nanotesla.
    declination_deg, declination_std_deg : float
        The declination (positive east of true north) and its standard uncertainty; the latter
        grows without bound near the magnetic poles, where the horizontal field vanishes.
    """

    model: str
    date: str
    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    dip_deg: float
    dip_std_deg: float
    intensity: float
    intensity_std: float
    declination_deg: float
    declination_std_deg: float

    @property
    def place(self) -> str:
        """The place in words, e.g. ``"52.00° N, 4.37° E"``."""
        lat, lon = self.latitude_deg, self.longitude_deg
        north, east = "N" if lat >= 0 else "S", "E" if lon >= 0 else "W"
        return f"{abs(lat):.2f}° {north}, {abs(lon):.2f}° {east}"

    def intensity_in(self, unit: str) -> float:
        """The total intensity in ``"uT"`` (microtesla), ``"nT"``, ``"G"`` (gauss, a PX4
        log's unit) or ``"mG"`` (milligauss, an ArduPilot log's)."""
        return self.intensity / _UNITS[unit]


_UNITS = {"nT": 1.0, "uT": 1000.0, "G": 1e5, "mG": 100.0}


def _number(text: str, what: str, spec: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise InputError(
            f"location {spec!r}: {what} {text.strip()!r} is not a number; give "
            "LAT,LON[,ALT_M] in decimal degrees and metres, e.g. 52.0,4.37,10"
        )
    return value


def parse_location(location: str | Sequence[float]) -> tuple[float, float, float]:
    """``(latitude_deg, longitude_deg, altitude_m)`` from ``"LAT,LON[,ALT_M]"`` or a sequence.

    Latitude in [−90, 90], longitude in [−180, 360) (east positive; 180–360 are folded to west),
    altitude in metres above the WGS 84 ellipsoid (default 0), from −1 km to 850 km.
    """
    sized = hasattr(location, "__len__") and hasattr(location, "__iter__")  # a list, an array
    if not isinstance(location, str) and (not sized or isinstance(location, bytes | dict)):
        raise InputError(
            f"location must be 'LAT,LON[,ALT_M]' or a sequence of 2 or 3 numbers, got "
            f"{type(location).__name__} {location!r}"[:200]
        )
    spec = location if isinstance(location, str) else ",".join(str(v) for v in location)
    parts = spec.split(",") if isinstance(location, str) else [str(v) for v in location]
    if len(parts) not in (2, 3):
        raise InputError(
            f"location {spec!r} must be LAT,LON or LAT,LON,ALT_M (decimal degrees, metres), "
            "e.g. 52.0,4.37 or 52.0,4.37,10"
        )
    names = ("latitude", "longitude", "altitude")
    lat, lon, *rest = (_number(p, n, spec) for p, n in zip(parts, names, strict=False))
    alt = rest[0] if rest else 0.0
    if not -90.0 <= lat <= 90.0:
        raise InputError(
            f"location {spec!r}: latitude {lat:g} is outside -90..90; give LAT first, then LON"
        )
    if not -180.0 <= lon < 360.0:
        raise InputError(f"location {spec!r}: longitude {lon:g} is outside -180..360")
    if lon >= 180.0:
        lon -= 360.0
    if not _ALTITUDE_KM[0] * 1000 <= alt <= _ALTITUDE_KM[1] * 1000:
        raise InputError(
            f"location {spec!r}: altitude {alt:g} m is outside the model's -1000..850000 m "
            "(the third number is metres, not kilometres or feet)"
        )
    return lat, lon, alt


def parse_date(date: str | _dt.date | None) -> _dt.date:
    """A date from ``"YYYY-MM-DD"``, a ``datetime.date`` (or datetime), or today (UTC)."""
    if date is None:
        return _dt.datetime.now(_dt.UTC).date()
    if isinstance(date, _dt.datetime):
        return date.date()
    if isinstance(date, _dt.date):
        return date
    if isinstance(date, str) and re.fullmatch(r"\d{4}-\d{2}-\d{2}", date.strip()):
        try:
            return _dt.date.fromisoformat(date.strip())
        except ValueError:
            pass
    raise InputError(
        f"date {str(date)[:40]!r} is not a date; give it as YYYY-MM-DD, e.g. 2026-11-24"
    )


def _decimal_year(day: _dt.date) -> float:
    start = _dt.date(day.year, 1, 1)
    length = (_dt.date(day.year + 1, 1, 1) - start).days
    return day.year + (day - start).days / length


@functools.lru_cache(maxsize=len(_MODELS))
def _model(coefficients: str) -> pygeomag.GeoMag:
    """pygeomag's model for one coefficient file (parsed once per process)."""
    try:
        pygeomag = importlib.import_module("pygeomag")
    except ImportError:
        raise InputError(
            f"the World Magnetic Model needs pygeomag, which is not installed; pip install "
            f"pygeomag=={_PINNED}"
        ) from None
    return pygeomag.GeoMag(coefficients_file=coefficients)


def expected_field(
    location: str | Sequence[float], date: str | _dt.date | None = None
) -> FieldReference:
    """The field the World Magnetic Model expects at ``location`` on ``date``.

    Parameters
    ----------
    location : str or sequence of float
        ``"LAT,LON[,ALT_M]"`` or ``(lat, lon[, alt_m])``: decimal degrees (north and east
        positive) and metres above the WGS 84 ellipsoid (default 0).
    date : str, datetime.date, optional
        ``"YYYY-MM-DD"``; default today (UTC). The models cover 2015-01-01 to 2029-12-31.

    Returns
    -------
    FieldReference
        Dip, intensity (nT) and declination with the model's standard uncertainties.

    Raises
    ------
    InputError
        A malformed location or date, or a date no model covers.

    Examples
    --------
    >>> ref = expected_field((52.0, 4.37), "2026-06-01")
    >>> ref.model, round(ref.dip_deg)
    ('WMM2025', 67)
    """
    lat, lon, alt = parse_location(location)
    day = parse_date(date)
    chosen = next((m for m in _MODELS if m[0] <= day.year <= m[1]), None)
    if chosen is None:
        raise InputError(
            f"no World Magnetic Model covers {day.isoformat()}: fieldcal has WMM2015 to WMM2025, "
            f"{_MODELS[0][0]}-01-01 to {_MODELS[-1][1]}-12-31; give --date within that span"
        )
    _, _, coefficients, name = chosen
    result = _model(coefficients).calculate(
        glat=lat, glon=lon, alt=alt / 1000.0, time=_decimal_year(day)
    )
    error = result.calculate_uncertainty()
    return FieldReference(
        model=name,
        date=day.isoformat(),
        latitude_deg=lat,
        longitude_deg=lon,
        altitude_m=alt,
        dip_deg=float(result.i),
        dip_std_deg=float(error.i),
        intensity=float(result.f),
        intensity_std=float(error.f),
        declination_deg=float(result.d),
        declination_std_deg=float(error.d),
    )
