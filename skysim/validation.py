"""Input checks shared by every layer: one place, one wording for each error."""

from __future__ import annotations

import numpy as np

from .exceptions import InvalidParameterError, SunBelowHorizonError

__all__ = [
    "as_float_array",
    "check_latitude",
    "check_longitude",
    "check_finite",
    "check_dop",
    "check_in_range",
    "check_sun_above_horizon",
    "TWILIGHT_LIMIT_DEG",
]


def _first_bad(values: np.ndarray, bad: np.ndarray) -> str:
    idx = np.flatnonzero(bad)
    flat = np.asarray(values).ravel()
    first = flat[idx[0]].item()
    if flat.size == 1:
        return repr(first)
    more = f" (and {idx.size - 1} more)" if idx.size > 1 else ""
    return f"{first!r} at flat index {idx[0]}{more}"


def as_float_array(name: str, values) -> np.ndarray:
    """``values`` as a float array; :class:`InvalidParameterError` naming ``name`` and the
    value for what is not a number or a (rectangular) array of numbers, such as ``"high"``."""
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"{name} must be a number or an array of numbers; got "
                                    f"{values!r:.80}") from None


def check_finite(name: str, values) -> np.ndarray:
    """Return ``values`` as a float array; raise ``InvalidParameterError`` on NaN or inf."""
    arr = as_float_array(name, values)
    bad = ~np.isfinite(arr)
    if bad.any():
        raise InvalidParameterError(f"{name} must be finite; got {_first_bad(arr, bad)}")
    return arr


def check_in_range(name: str, values, low: float, high: float, *, low_open=False,
                   high_open=False, hint: str = "") -> np.ndarray:
    """Check ``low <= values <= high`` (bounds optionally open); return a float array."""
    arr = as_float_array(name, values)
    ok = arr > low if low_open else arr >= low   # NaN fails both comparisons
    ok &= arr < high if high_open else arr <= high
    if ok.all():
        return arr
    arr = check_finite(name, values)
    too_low = arr <= low if low_open else arr < low
    too_high = arr >= high if high_open else arr > high
    bad = too_low | too_high
    if bad.any():
        lb = "(" if low_open else "["
        hb = ")" if high_open else "]"
        raise InvalidParameterError(
            f"{name} must lie in {lb}{low}, {high}{hb}; got {_first_bad(arr, bad)}"
            + (f". {hint}" if hint else ""))
    return arr


def check_latitude(latitude_deg) -> np.ndarray:
    """Latitude in [-90, 90] degrees."""
    return check_in_range("latitude_deg", latitude_deg, -90.0, 90.0,
                          hint="Latitude is north-positive in degrees; did you swap lat and lon?")


def check_longitude(longitude_deg) -> np.ndarray:
    """Longitude in [-180, 360] degrees (east-positive)."""
    return check_in_range("longitude_deg", longitude_deg, -180.0, 360.0)


def check_dop(name: str, values) -> np.ndarray:
    """A degree of polarization (or d_max) must satisfy 0 < d < 1.

    d = 1 makes the log-ratio of the opponent sensor infinite; d <= 0 carries no heading.
    """
    return check_in_range(name, values, 0.0, 1.0, low_open=True, high_open=True)


TWILIGHT_LIMIT_DEG = -10.0
"""Lowest sun elevation [deg] of the single-scattering sky models: in civil and early nautical
twilight the sky is still lit by singly scattered sunlight from the sunlit upper layers and
stays polarized with the Rayleigh pattern about the (sub-horizon) sun (Cronin et al. 2006,
doi:10.1364/AO.45.005582); below about -10 deg the skylight is too faint for a compass."""


def check_sun_above_horizon(sun_elevation_deg, min_elevation_deg: float = 0.0) -> np.ndarray:
    """Raise :class:`SunBelowHorizonError` when any sun elevation is <= ``min_elevation_deg``.

    ``min_elevation_deg`` is 0 for models that need a sunlit atmosphere (plane-parallel
    radiative transfer, illuminance) and :data:`TWILIGHT_LIMIT_DEG` for the single-scattering
    sky models, which hold in twilight. Above 90 deg: :class:`InvalidParameterError` (no such
    elevation).
    """
    el = check_finite("sun_elevation_deg", sun_elevation_deg)
    if np.any(el > 90.0):
        raise InvalidParameterError(f"sun elevation must be <= 90 deg; got "
                                    f"{_first_bad(el, el > 90.0)} deg")
    bad = el <= min_elevation_deg
    if bad.any():
        where = "above the horizon" if min_elevation_deg == 0.0 else \
            f"above {min_elevation_deg:g} deg (twilight limit of this model)"
        raise SunBelowHorizonError(
            f"sun elevation must be {where}; got {_first_bad(el, bad)} deg. "
            "Choose times between sunrise and sunset at this site (check the timezone).")
    return el
