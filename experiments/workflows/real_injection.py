"""Inject known effects into real photodiode sessions, for the blind check of the diagnosis.

The injector shares only the physics library with the diagnoser (times, yaw conventions,
:func:`skysim.geometry.wrap_deg`); it never calls the fitter. Each injection returns the
modified data and its truth record.

- ``clock_offset``: the recorded times become ``t - dt`` (``dt`` = true minus recorded), drawn
  half from whole/half-hour timezone errors (+-1..+-3 h) and half from +-U(10, 40) min.
- ``yaw_scale``: the recorded yaw change within each sweep becomes ``factor`` times the
  recorded one (``factor`` ~ U(0.93, 0.97) or U(1.03, 1.07)), re-wrapped to (-180, 180].
- ``occlusion``: units looking into a sector of azimuth (in each sweep's recorded-yaw frame,
  i.e. about north for a platform set facing north) see foliage light, depolarized and
  darker. Each unit's readings at its nominal polarizer angles give its Stokes vector by
  least squares (Malus's law, ``r_p = (I + Q cos 2a_p + U sin 2a_p) / 2``); in the sector
  the polarized part ``(Q cos 2a_p + U sin 2a_p) / 2`` of every reading is scaled by
  ``1 - k`` (the DoP scales by ``1 - k``, ``k`` ~ U(0.6, 0.9)) and the reading darkened by
  ``1 - k / 2``. What does not follow Malus's law at the nominal angles (the instrument's
  own gain and angle errors) is left as it was.
- ``stuck``: one working photodiode reads a constant (its median) from the first turn on.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sensor.photodiodes_io import PhotodiodeData
from skysim.exceptions import InvalidParameterError
from skysim.geometry import wrap_deg

__all__ = ["INJECTABLE", "inject"]

INJECTABLE = ("clock_offset", "yaw_scale", "occlusion", "stuck")


def _clockwise(table, sidecar):
    yaw = table["yaw_deg"].to_numpy(float)
    return -yaw if sidecar["yaw_sense"] == "counterclockwise" else yaw


def inject(data: PhotodiodeData, effect: str, rng: np.random.Generator):
    """Return ``(PhotodiodeData, truth)`` with ``effect`` injected (see module doc)."""
    table = data.table.copy()
    side = dict(data.sidecar)
    truth = {"effect": effect}
    sweep = table["sweep"].to_numpy() if "sweep" in table.columns else np.zeros(len(table))
    if effect == "clock_offset":
        dt = (rng.choice([-3, -2.5, -2, -1.5, -1, 1, 1.5, 2, 2.5, 3]) * 3600.0
              if rng.random() < 0.5 else rng.choice([-1, 1]) * rng.uniform(600, 2400))
        table["time"] = pd.to_datetime(table["time"]) - pd.to_timedelta(dt, unit="s")
        truth["clock_offset_s"] = float(dt)
    elif effect == "yaw_scale":
        k = float(rng.choice([-1, 1]) * rng.uniform(0.03, 0.07) + 1.0)
        yaw = table["yaw_deg"].to_numpy(float)
        out = np.empty_like(yaw)
        for s in np.unique(sweep):
            m = sweep == s
            u = np.degrees(np.unwrap(np.radians(yaw[m])))
            out[m] = wrap_deg(u[0] + k * (u - u[0]))
        out[out == -180.0] = 180.0
        table["yaw_deg"] = out
        truth["factor"] = k
    elif effect == "occlusion":
        c, w, k = rng.uniform(0, 360), rng.uniform(60, 120), rng.uniform(0.6, 0.9)
        yaw = _clockwise(table, side)
        for i, unit in enumerate(side["units"]):
            cols = [f"u{i}_p{int(a):03d}" for a in unit["photodiodes"]]
            az = yaw + float(unit["azimuth_deg"])
            inside = np.abs(wrap_deg(az - c)) <= 0.5 * w
            R = table[cols].to_numpy(float)
            sat = R >= side["saturation_value"]
            a = np.radians(2.0 * np.asarray(unit["photodiodes"], float))
            A = 0.5 * np.stack([np.ones_like(a), np.cos(a), np.sin(a)], axis=-1)   # (P, 3)
            whole = np.isfinite(R).all(axis=1) & ~sat.any(axis=1)    # rows Malus can invert
            stokes = np.linalg.lstsq(A, np.where(whole[:, None], R, 0.0).T, rcond=None)[0].T
            polarized = stokes[:, 1:] @ A[:, 1:].T                                  # (n, P)
            new = (R - k * polarized) * (1 - 0.5 * k)
            R = np.where((inside & whole)[:, None], np.round(new), R)
            table[cols] = R
        truth.update(center_deg=float(c), width_deg=float(w), depolarization=float(k))
    elif effect == "stuck":
        cols = data.columns
        ok = [c for c in cols if np.mean(table[c] == 0) < 0.05
              and np.mean(table[c] >= side["saturation_value"]) < 0.05]
        col = str(rng.choice(ok))
        start = int(np.argmax(sweep == np.unique(sweep)[0]))
        table.loc[table.index[start:], col] = float(np.median(table[col]))
        truth["channel"] = col
    else:
        raise InvalidParameterError(
            f"cannot inject {effect!r}; injectable: {', '.join(INJECTABLE)}")
    return PhotodiodeData(table, side), truth
