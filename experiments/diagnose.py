"""`skysim diagnose` and `skysim gap-benchmark`: sim-to-real gap diagnosis, checked blind.

``skysim diagnose DATA`` reads a measurement table ("skysim.measurement/1") or raw photodiode
data ("skysim.photodiodes/1") with its sidecar, runs :func:`calibration.diagnosis.diagnose`
and writes ``diagnosis.json``, ``report.md`` and figures.

``skysim gap-benchmark`` generates data sets with one hidden effect (or none) at a magnitude
drawn from the effect's documented range, diagnoses each without the label, and scores the
verdicts. The generator (this module's :func:`simulate_session`) and the diagnoser share only
:mod:`calibration.effects`; the label and the true parameters go to a separate truth record
the diagnoser never reads.

Benchmark session (a documented choice; the issue leaves it open): the Xi'an rooftop of Yang
et al. (2014) on 2013-05-22, six turntable sweeps of 121 stops over 180 deg, 600 s each,
starting every 30 min from 16:30 to 19:00 local time (sun elevation ~37 -> ~6 deg, so the
illuminance falls ~10x and the sensor cools by a few kelvin: the slow effects have something
to act on). Sensor errors, noise, DAQ and ``d_max`` follow :data:`experiments.yang2014.ERROR_MODEL`.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from calibration.diagnosis import DiagnosisData, Thresholds, diagnose
from calibration.effects import EFFECT_NAMES, Context, base_vector, forward, get_effect
from calibration.effects.dark_current import clear_sky_illuminance_lx
from sensor.daq import Daq
from sensor.errors import OpponentErrors
from sensor.measurement import MEASUREMENT_SCHEMA, Measurement
from sensor.opponent import OpponentSensor
from skysim import __version__
from skysim.io import atomic_write, write_json_atomic

from .yang2014 import ERROR_MODEL, SITE

__all__ = ["Session", "SESSION", "simulate_session", "run_benchmark", "score_benchmark",
           "register"]


@dataclass(frozen=True)
class Session:
    """Acquisition plan of a benchmark data set (see module docstring)."""

    date: str = "2013-05-22"
    utc_offset: str = "+08:00"
    first_start: str = "16:30"
    sweep_spacing_min: float = 30.0
    n_sweeps: int = 6
    n_stops: int = 121
    sweep_duration_s: float = 600.0
    temperature_start_C: tuple = (28.0, 36.0)
    cooling_K_per_h: tuple = (1.0, 4.0)
    illuminance_factor: tuple = (0.8, 1.1)

    def starts(self) -> pd.DatetimeIndex:
        t0 = pd.Timestamp(f"{self.date}T{self.first_start}:00{self.utc_offset}")
        return pd.DatetimeIndex([t0 + pd.Timedelta(minutes=self.sweep_spacing_min * k)
                                 for k in range(self.n_sweeps)])


SESSION = Session()


def _to_times(t_s, tz_offset: str) -> pd.Series:
    idx = pd.to_datetime(np.round(np.asarray(t_s) * 1e9).astype(np.int64), unit="ns", utc=True)
    return pd.Series(idx).dt.tz_convert(pd.Timestamp(f"2000-01-01T00:00{tz_offset}").tz)


def simulate_session(effect: str | None, rng: np.random.Generator, *, params=None,
                     session: Session = SESSION, model=ERROR_MODEL, seed=None) -> dict:
    """One data set with a hidden effect (or none) and its effect-free twin.

    Returns a dict with ``measurement`` (the recorded table, as a real instrument would
    write it), ``clean`` (the same noise and sensor regenerated without the effect, and with
    correct timestamps), ``truth`` (label and parameters, never given to the diagnoser) and
    ``data``/``clean_data`` (:class:`DiagnosisData` built from the tables alone).
    """
    errors = OpponentErrors.draw(rng, misalignment_max_deg=model.misalignment_max_deg,
                                 transmittance_sd=model.transmittance_sd,
                                 noise_range_V=model.noise_range_V,
                                 turntable_error_deg=model.turntable_error_deg)
    dmax = rng.uniform(*model.dmax_range)
    eff = None if effect is None else get_effect(effect)
    p = None if eff is None else (eff.draw(rng) if params is None else np.asarray(params, float))
    starts = session.starts()
    n = session.n_sweeps * session.n_stops
    sweep = np.repeat(np.arange(session.n_sweeps), session.n_stops)
    frac = np.tile(np.linspace(0.0, 1.0, session.n_stops), session.n_sweeps)
    t0 = starts.tz_convert("UTC").as_unit("ns").asi8 / 1e9
    duration = float(p[0]) if effect == "sun_motion" else session.sweep_duration_s
    t_true = t0[sweep] + frac * duration
    track = Context.from_arrays(SITE, _to_times(t_true, session.utc_offset), np.zeros(n)).sun
    sun_el0, sun_az0 = track(t0)
    heading = (sun_az0[sweep] - 90.0 + frac * 179.9) % 360.0
    sun_el, _ = track(t_true)
    temp = (rng.uniform(*session.temperature_start_C)
            - rng.uniform(*session.cooling_K_per_h) * (t_true - t_true[0]) / 3600.0)
    lux = rng.uniform(*session.illuminance_factor) * clear_sky_illuminance_lx(sun_el)
    t_rec = t_true.copy()
    if effect == "sun_motion":
        t_rec = t0[sweep]
    elif effect == "clock_offset":
        t_rec = t_true - float(p[0])
    base = base_vector(errors.misalignment_deg, errors.transmittance, dmax)
    heading_true = heading + model.turntable_error_deg * rng.standard_normal(n)
    noise = rng.standard_normal((n, 3)) * np.asarray(errors.noise_V)
    daq = Daq(model.daq_bits, model.daq_range_V)

    def make_ctx(t, h):
        return Context(SITE, t, h, sweep, frac, lux, temp, track, float(t_true[0]))

    U = daq.acquire(forward(make_ctx(t_rec, heading_true), base, eff, p) + noise)[0]
    U_clean = daq.acquire(forward(make_ctx(t_true, heading_true), base) + noise)[0]
    sensor = OpponentSensor(errors, daq=daq)

    def table(t, u):
        return Measurement(pd.DataFrame({
            "time": _to_times(t, session.utc_offset), "heading_deg": heading,
            "U1_V": u[:, 0], "U2_V": u[:, 1], "U3_V": u[:, 2], "sweep": sweep,
            "illuminance_lx": lux, "temperature_C": temp}),
            {"schema": MEASUREMENT_SCHEMA, "site": SITE.to_dict(), "sensor": sensor.describe(),
             "generator": {"package": "skysim", "version": __version__,
                           "command": "skysim gap-benchmark", "seed": seed,
                           "session": session.__dict__, "truth": "withheld (truth.json)"}})

    meas, clean = table(t_rec, U), table(t_true, U_clean)
    truth = {"effect": effect or "none", "params": None if eff is None else eff.describe(p),
             "dmax": dmax, "errors": errors.to_dict(), "seed": seed}
    return {"measurement": meas, "clean": clean, "truth": truth,
            "data": measurement_data(meas), "clean_data": measurement_data(clean)}


def measurement_data(m: Measurement, source=None) -> DiagnosisData:
    """:class:`DiagnosisData` from a measurement table: its columns and sidecar only."""
    t = m.table
    ctx = Context.from_arrays(
        m.site, t["time"], t["heading_deg"].to_numpy(float),
        block=t["sweep"].to_numpy() if "sweep" in t.columns else None,
        illuminance_lx=t["illuminance_lx"].to_numpy(float) if "illuminance_lx" in t else None,
        temperature_C=t["temperature_C"].to_numpy(float) if "temperature_C" in t else None)
    daq = (m.sidecar.get("sensor") or {}).get("daq") or {}
    sat = None
    if daq.get("bits"):
        sat = float(daq.get("range_V", 10.0)) - 2.0 * float(daq["range_V"]) / 2 ** daq["bits"]
    U = t[["U1_V", "U2_V", "U3_V"]].to_numpy(float)
    return DiagnosisData.from_arrays(ctx, U, saturation_V=sat,
                                     source=source or {"schema": MEASUREMENT_SCHEMA})
