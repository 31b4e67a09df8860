"""Simulated ring-compass sessions for the ring diagnosis tests (the sensor simulator shares
only the physics library with the fitter)."""

import numpy as np
import pandas as pd

from sensor.compound_eye import PhotodiodeModel, ring_configuration
from sensor.photodiodes_io import PhotodiodeData
from skysim.sky import RayleighSky
from skysim.sun import Site

SITE = Site(39.258648, 8.440184, 0.0)


def ring_session(n_sweeps=3, per_sweep=90, start="2022-05-12T10:00:00+02:00", seed=1,
                 dmax=0.6, sky=None, counts_per_radiance=None):
    """A relative-yaw, counter-clockwise ring session: each sweep one full turn, under
    ``sky`` (default the Rayleigh sky of ``dmax``); ``counts_per_radiance`` sets the ADC
    gain (default :class:`sensor.compound_eye.PhotodiodeModel`'s, for clear skies)."""
    rng = np.random.default_rng(seed)
    model = PhotodiodeModel() if counts_per_radiance is None else PhotodiodeModel(
        counts_per_radiance=counts_per_radiance)
    sensor = ring_configuration(8, 45.0, photodiode=model)
    t0 = pd.Timestamp(start)
    times = pd.DatetimeIndex([t0 + pd.Timedelta(seconds=60 * s + 0.1 * k)
                              for s in range(n_sweeps) for k in range(per_sweep)])
    yaw = np.tile(np.linspace(0.0, 360.0, per_sweep, endpoint=False), n_sweeps) + 20.0
    sweep = np.repeat(np.arange(n_sweeps), per_sweep)
    data = sensor.sample(RayleighSky(dmax) if sky is None else sky, SITE, times, yaw, 0.0,
                         0.0, rng, yaw_reference="relative", yaw_offset_deg=35.0,
                         include_truth=False, sweep=sweep)
    t = data.table.drop(columns=["pitch_deg", "roll_deg"])
    t["yaw_deg"] = -(((t["yaw_deg"] + 180.0) % 360.0) - 180.0)      # ccw, wrapped
    side = dict(data.sidecar, yaw_sense="counterclockwise")
    return PhotodiodeData(t, side)


def base_fit_and_effect(inst, effect: str):
    """The diagnosis's base fit of ``inst`` (screen, pinned fit, noise: ``run._fit_session``
    with 25 iterations) and the forward model of the candidate ``effect`` on the instrument
    it kept: ``(session, Forward, effect, sun track)``."""
    from calibration.photodiode_diagnosis.effects import get_ring_effect
    from calibration.photodiode_diagnosis.forward import Forward
    from calibration.photodiode_diagnosis.run import _fit_session, light_track
    sun = light_track(inst)
    s, _ = _fit_session(inst, sun, 25)
    e = get_ring_effect(effect)
    return s, Forward(s.base.inst, e, sun=sun, polarizer_sign=s.sign), e, sun


def fitted_on_whole_session(effect: str, truth: dict, seed: int):
    """``(value, SE, mean elevation offset of the units)`` of a one-parameter candidate
    ``effect`` fitted on a whole simulated ring of twelve sweeps made with ``truth``
    (:func:`calibration.diagnosis.identifiability.ring_session`), as each fold fits it: its
    start, its fit, its continuation, its SE."""
    from calibration.diagnosis.identifiability import ring_session as matrix_session
    from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes
    from calibration.photodiode_diagnosis.run import (_continued, _effect_sd, _fit_effect,
                                                      _start_effect)
    inst = instrument_from_photodiodes(matrix_session(effect, truth, seed))
    s, fe, e, _ = base_fit_and_effect(inst, effect)
    L = fe.layout
    fr, aop = _fit_effect(fe, _start_effect(fe, s.theta, s.base, e, s.sigma), s.sigma)
    fr, aop = _continued(fe, (fr, aop), s.sigma, None)
    assert fr.converged
    return (float(fr.theta[L.effect][0]), _effect_sd(fe, fr, aop, s.sigma)[0],
            float(np.mean(fr.theta[L.pointing][:inst.n_units])))
