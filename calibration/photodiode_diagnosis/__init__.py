"""Sim-to-real gap diagnosis of multi-unit photodiode instruments (``skysim.photodiodes/1``).

One file one idea: :mod:`.instrument` (adapter from the file), :mod:`.faults` (dead, stuck,
saturated, zero, duplicated and non-Malus channels), :mod:`.forward` (compound-eye sensor
under a sky, Malus's law, profiled radiance), :mod:`.fit` (grouped-Jacobian
Levenberg-Marquardt), :mod:`.pointing` (unit pointing calibrated on other sessions),
:mod:`.effects` (multiple scattering, field of view, occlusion, yaw
scale, clock offset, tilt), :mod:`.effect_fit` (what fitting one candidate shares),
:mod:`.clock` (the clock's starts, sensitivity, sky-model spread, mirror time and
refinement) and :mod:`.run` (held-out gap, where, which, how far, heading error). Method and report: ``docs/diagnosis.md``.
"""

from skysim._lazy import lazy_namespace

_EXPORTS = {
    **dict.fromkeys(("RING_EFFECT_NAMES", "EffectUnavailableError", "get_ring_effect"),
                    ".effects"),
    **dict.fromkeys(("InstrumentDataError", "NoUsableChannelsError", "PointingCalibrationError",
                     "SunTooLowError", "YawInRadiansWarning"), ".errors"),
    "screen": ".faults",
    **dict.fromkeys(("Instrument", "instrument_from_photodiodes"), ".instrument"),
    "calibrated_pointing": ".pointing",
    **dict.fromkeys(("diagnose_instrument", "diagnose_photodiodes"), ".run"),
}
"""Each public name and the submodule that defines it, imported on first use (PEP 562): a
module importing one submodule does not import the whole diagnosis."""

__getattr__, __dir__ = lazy_namespace(__name__, _EXPORTS)

__all__ = ["RING_EFFECT_NAMES", "EffectUnavailableError", "Instrument", "InstrumentDataError",
           "NoUsableChannelsError", "PointingCalibrationError", "SunTooLowError",
           "calibrated_pointing", "diagnose_instrument",
           "diagnose_photodiodes", "get_ring_effect", "instrument_from_photodiodes",
           "is_three_pair_sensor", "screen", "YawInRadiansWarning"]


def is_three_pair_sensor(sidecar: dict) -> bool:
    """True for a one-unit instrument with the three orthogonal pairs 60/150, 0/90, 120/30 deg
    (the three-pair sensor, diagnosed through its log-ratio channels).

    False for a malformed ``units`` (the reader then says what is wrong with it).
    """
    units = sidecar.get("units")
    need = {60, 150, 0, 90, 120, 30}
    if not (isinstance(units, list) and len(units) == 1 and isinstance(units[0], dict)
            and isinstance(units[0].get("photodiodes"), list)):
        return False
    try:
        return {round(float(a)) % 180 for a in units[0]["photodiodes"]} >= need
    except (TypeError, ValueError, OverflowError):
        return False
