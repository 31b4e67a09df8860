"""Readers of the ``skysim.diagnosis/1`` report dicts: each is rewritten as a dict of the
current schema, which :meth:`.report.DiagnosisReport.from_dict` reads (and ranks).

Three diagnoses wrote that schema in three shapes: the three-pair sensor's (``where`` a dict
of tables in mV), the sky field's (``level: sky``, ``where`` a dict of tables in DoLP units,
parameters as bare numbers) and the photodiode instrument's (``instrument: photodiodes``,
``where`` a list of slices). Shares of the gap are recomputed from the slices' RMS and size
with :func:`.shares.partition_shares`, limits with :func:`.shares.slice_limit`, so that every
report means the same by them. Nothing here writes that schema.
"""

from __future__ import annotations

from .shares import partition_shares, slice_limit

__all__ = ["from_legacy_dict", "from_ring_v1", "from_sky_v1", "from_three_pair_v1"]

_RING_KEYS = {"schema", "instrument", "verdict", "candidates", "where", "faults",
              "noise_floor", "data", "split", "seed", "thresholds"}
"""Keys of the photodiode diagnosis's dict that the report holds in its own fields."""
_VERDICT_KEYS = ("effect", "reason", "best_candidate", "gap_before", "gap_after", "shrink",
                 "gap_before_se", "gap_after_se", "shrink_se", "params")


def from_legacy_dict(d: dict) -> dict:
    """Any ``skysim.diagnosis/1`` dict as a dict of the current schema (module docstring);
    candidates and slices in the order written (the report ranks them)."""
    if d.get("level") == "sky":
        return from_sky_v1(d)
    if d.get("instrument") == "photodiodes":
        return from_ring_v1(d)
    return from_three_pair_v1(d)


_PAIRED_VERDICT_KEYS = ("group", "explained_share", "explained_share_se", "separated_by")
"""Verdict keys of the paired rule, read where a dict carries them."""


def _verdict(v: dict, params=None) -> dict:
    kw = {k: v.get(k) for k in _VERDICT_KEYS}
    kw.update({k: v[k] for k in _PAIRED_VERDICT_KEYS if v.get(k) is not None})
    kw["params"] = params if params is not None else (v.get("params") or {})
    if kw["best_candidate"] == "base":
        kw["best_candidate"] = None
    return kw


def _with_split(data: dict, split: dict | None) -> dict:
    """``data`` with the split under ``data["split"]``, its count named as in v2."""
    data = dict(data)
    split = dict(split if split is not None else data.get("split", {}))
    if "held_out_readings" in split:
        split["held_out_values"] = split.pop("held_out_readings")
    if split:
        data["split"] = split
    return data


def _slices(rows, floor: float, margin: float, dof_per_value: int = 1) -> list[dict]:
    """Slice dicts from ``(dimension, label, n, rms, lo, hi, unit)`` tuples, shares and
    limits recomputed per dimension."""
    out = []
    for dim in dict.fromkeys(r[0] for r in rows):
        part = [r for r in rows if r[0] == dim]
        shares = partition_shares([r[2] for r in part], [r[3] for r in part], floor)
        for r, share in zip(part, shares):
            limit = float(slice_limit(floor, r[2] * dof_per_value, margin))
            d = {"dimension": dim, "label": r[1], "n": r[2], "rms": r[3],
                 "share": float(share), "carries_gap": bool(r[3] > limit), "limit": limit}
            if r[4] is not None:
                d[f"lo_{r[6]}"], d[f"hi_{r[6]}"] = r[4], r[5]
            out.append(d)
    return out


def _report(instrument, metric, unit, verdict, candidates, where, where_after, floor,
            floor_method, faults, data, thresholds, seed, extra) -> dict:
    return {"instrument": instrument, "metric": metric, "unit": unit, "verdict": verdict,
            "candidates": candidates, "where": where, "where_after": where_after,
            "noise_floor": floor, "noise_floor_method": floor_method, "faults": faults,
            "data": data, "thresholds": thresholds, "seed": seed, "extra": extra}


def from_three_pair_v1(d: dict) -> dict:
    """The three-pair sensor's ``skysim.diagnosis/1`` dict (gaps in mV)."""
    w, v = d["where"], d["verdict"]
    floor = float(v["noise_floor"])
    margin = d.get("thresholds", {}).get("none_margin", 0.10)
    rows = []
    for key, dim in (("by_channel", "channel"), ("by_time", "sweep"),
                     ("by_illuminance", "illuminance_lx"),
                     ("by_sun_elevation", "sun_elevation_deg")):
        for s in w.get(key, []):
            label = s["slice"].removeprefix("sweep ").removesuffix(" lx").removesuffix(" deg")
            rows.append((dim, label, int(s["n"]), float(s["rms_mV"]), None, None, None))
    data = _with_split(d.get("data", {}), None)
    nuisance = data.pop("nuisance", None)
    extra = {"harmonics": w.get("by_harmonic", []), "base_fit": d.get("base_fit")}
    if nuisance is not None:
        extra["nuisance"] = nuisance
    nf = d.get("noise_floor", {})
    if "per_channel_mV" in nf:
        extra["noise_floor_per_channel_mV"] = nf["per_channel_mV"]
    return _report(
        "three_pair", str(v.get("metric", "")).removesuffix(" [mV]"), "mV", _verdict(v),
        list(d["candidates"]), _slices(rows, floor, margin), None, floor,
        nf.get("method", ""), [], data, dict(d.get("thresholds", {})), d.get("seed"), extra)


def _sky_params(p: dict) -> dict:
    return {k: {"value": float(x), "unit": "1"} for k, x in (p or {}).items()}


def _sky_slices(w: dict, floor: float, margin: float):
    rows = []
    for key, dim in (("by_sun_distance", "sun_distance_deg"), ("horizon", "horizon"),
                     ("neutral_points", "neutral_points"), ("by_view_zenith", "view_zenith_deg")):
        for s in w.get(key, []):
            rows.append((dim, s["slice"], int(s["points"]), float(s["rms"]), None, None, None))
    return _slices(rows, floor, margin, dof_per_value=2)


def from_sky_v1(d: dict) -> dict:
    """The sky field's ``skysim.diagnosis/1`` dict (``level: sky``; gaps in DoLP units)."""
    v = d["verdict"]
    floor = float(v["noise_floor"])
    margin = d.get("thresholds", {}).get("none_margin", 0.10)
    cands = []
    for c in d["candidates"]:
        c = dict(c)
        if c.get("available", True):
            c["params"] = _sky_params(c.get("params"))
            c["k"] = int(c.get("k", 1)) - 1          # parameters added to d_max
        cands.append(c)
    wa = d.get("where_after")
    extra = {k: d[k] for k in ("engine_settings", "seconds") if k in d}
    return _report(
        "sky", str(v.get("metric", "")).removesuffix(" [DoLP units]"), "DoLP",
        _verdict(v, _sky_params(v.get("params"))), cands,
        _sky_slices(d["where"], floor, margin),
        None if wa is None else _sky_slices(wa, floor, margin), floor,
        "given: the RMS Stokes residual a perfect model leaves on these data", [],
        _sky_data(d.get("data", {})), dict(d.get("thresholds", {})), d.get("seed"), extra)


def _sky_data(data: dict) -> dict:
    data = dict(data)
    split = {"method": "given calibration cases; the others withheld"}
    for old, new in (("held_out_points", "held_out_values"),
                     ("calibration_points", "calibration_values")):
        if old in data:
            split[new] = data.pop(old)
    return _with_split(data, split)


def from_ring_v1(d: dict) -> dict:
    """The photodiode instrument's ``skysim.diagnosis/1`` dict (gaps as fractions of each
    unit's mean reading)."""
    v = d["verdict"]
    nf = d.get("noise_floor") or {}
    floor = nf.get("rms")
    # the ring's thresholds where its dict carries them (dicts without: none margin 0.10)
    thresholds = dict(d.get("thresholds") or {"none_margin": 0.10})
    margin = thresholds["none_margin"]
    where = []
    if floor is not None:
        rows = [(w["dimension"], w["label"], int(w["n"]), float(w["rms"]), w.get("lo_deg"),
                 w.get("hi_deg"), "deg" if "lo_deg" in w else None) for w in d["where"]]
        where = _slices(rows, float(floor), margin)
    data = _with_split(d.get("data", {}), d.get("split"))
    # everything else the ring diagnosis reports (heading error, base fit, ...) is kept
    extra = {k: v for k, v in d.items() if k not in _RING_KEYS and v is not None}
    parts = {k: nf[k] for k in ("white_noise_rms", "replica_held_out_gap") if k in nf}
    if parts:
        extra["noise_floor_parts"] = parts
    return _report(
        "photodiodes", str(v.get("metric", "")), "1", _verdict(v), list(d["candidates"]),
        where, None, None if floor is None else float(floor), nf.get("method", ""),
        list(d.get("faults", [])), data, thresholds, d.get("seed"), extra)
