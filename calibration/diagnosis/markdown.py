"""``report.md`` of a :class:`.report.DiagnosisReport` (one layout for every instrument)."""

from __future__ import annotations

import json

import numpy as np

__all__ = ["report_markdown"]

MAX_SLICES = 12
"""Slices listed under "Where" (the largest shares; the JSON report holds them all)."""


def _fmt(x, nd: int = 3) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "—"
    return f"{x:.{nd}g}"


def _gap(x, se=None) -> str:
    return _fmt(x, 4) + ("" if se is None else f" ± {_fmt(se, 2)}")


def _params_table(params: dict) -> list[str]:
    lines = ["| parameter | value | standard error | unit |", "|---|---|---|---|"]
    for k, p in params.items():
        se = p.get("se", p.get("uncertainty"))
        lines.append(f"| {k} | {_fmt(p.get('value'), 4)} | {_fmt(se, 2)} | "
                     f"{p.get('unit', '')} |")
    return lines + [""]


def report_markdown(r) -> str:
    """Markdown text of report ``r``: verdict, gaps, parameters, candidates, where, faults,
    data and split, notes."""
    v, u = r.verdict, r.unit
    source = r.data.get("path") or r.instrument
    lines = [f"# Sim-to-real gap diagnosis: {source}", "",
             f"**Verdict: `{v.effect}`** — {v.reason}.", "",
             f"- instrument: {r.instrument}",
             f"- metric: {r.metric} [{u}]",
             f"- noise floor: {_fmt(r.noise_floor, 4)} {u} ({r.noise_floor_method})"]
    if v.gap_before is not None:
        shrink = "—" if v.shrink is None else f"{100 * v.shrink:.1f}"
        if v.shrink_se is not None and v.shrink is not None:
            shrink += f" ± {100 * v.shrink_se:.1f}"
        lines.append(f"- gap before: {_gap(v.gap_before, v.gap_before_se)} {u}; after "
                     f"(`{v.best_candidate or 'base'}`): {_gap(v.gap_after, v.gap_after_se)} "
                     f"{u}; shrink {shrink} %")
    if v.explained_share is not None:
        se = "" if v.explained_share_se is None else f" ± {100 * v.explained_share_se:.0f}"
        lines.append(f"- share of the excess held-out variance removed by "
                     f"`{v.best_candidate}`: {100 * v.explained_share:.0f}{se} %")
    if v.group:
        lines.append("- candidates not told apart: " + ", ".join(f"`{g}`" for g in v.group)
                     + "".join(f"; to separate `{e}`: {m}"
                               for e, m in (v.separated_by or {}).items()))
    he = r.extra.get("heading_error") or {}
    if he.get("base_deg") is not None:
        lines.append(f"- heading error (RMS): base {he['base_deg']:.2f} deg"
                     + (f", best {he['best_deg']:.2f} deg" if he.get("best_deg") else "")
                     + (f" (modulo {he['ambiguity_deg']:g} deg: {he['ambiguity']})"
                        if he.get("ambiguity_deg", 360.0) != 360.0 else ""))
    lines.append("")
    if v.params:
        lines += _params_table(v.params)
    lines += ["## Candidates (ranked by held-out score)", "",
              ("Paired difference: held-out mean square minus the best-ranked candidate's on "
               f"the same readings [{u}^2], ± its jackknife SE over held-out blocks."), "",
              f"| rank | effect | k | held-out gap [{u}] | shrink | score | paired difference "
              "| share of excess | at bound | explains |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for i, c in enumerate(r.candidates, 1):
        if not c.available:
            lines.append(f"| — | {c.effect} | — | unavailable | — | — | — | — | — | "
                         f"{c.error} |")
            continue
        paired = ("—" if c.paired_difference is None else
                  f"{_fmt(c.paired_difference, 3)} ± {_fmt(c.paired_difference_se, 2)}")
        share = ("—" if c.explained_share is None else
                 f"{100 * c.explained_share:.0f} ± {100 * (c.explained_share_se or 0):.0f} %")
        held = "".join(f" ({k} held at {v:g})" for k, v in (c.details.get("held") or {}).items())
        lines.append(f"| {i} | {c.effect}{held} | {c.k} | {_fmt(c.gap_after, 4)} | "
                     f"{100 * c.shrink:.1f} % | {c.score:.1f} | {paired} | {share} | "
                     f"{', '.join(c.at_bound) or '—'} | {'yes' if c.explained else 'no'} |")
    lines += ["", "## Where the gap lies (held-out residuals of the base model)", "",
              ("Share: of the excess squared gap over the noise floor within each dimension; "
               "a slice carries the gap when its RMS exceeds what white noise at the floor "
               "reaches in 99 % of slices of its size."), "",
              f"| dimension | slice | n | RMS [{u}] | share | carries the gap |",
              "|---|---|---|---|---|---|"]
    for s in r.where[:MAX_SLICES]:
        lines.append(f"| {s.dimension} | {s.label} | {s.n} | {_fmt(s.rms, 4)} | "
                     f"{100 * s.share:.1f} % | {'yes' if s.carries_gap else 'no'} |")
    if not r.where:
        lines.append("| — | no held-out residuals | | | | |")
    elif not r.carrying_gap():
        lines += ["", "No slice exceeds its noise limit."]
    harm = [h for h in r.extra.get("harmonics", []) if h["fraction_of_variance"] > 0.1]
    if harm and r.carrying_gap():
        lines += ["", "Harmonics holding more than 10 % of the residual variance: "
                  + "; ".join(f"{h['component']} ({100 * h['fraction_of_variance']:.0f} %)"
                              for h in harm) + "."]
    if r.faults:
        lines += ["", "## Faults", ""]
        lines += [f"- {f['channel']}: {f['kind']} {f.get('evidence', '')}" for f in r.faults]
    d = r.data
    split = d.get("split", {})
    lines += ["", "## Data and split", ""]
    if split:
        lines.append("- split: " + ", ".join(f"{k} {val}" for k, val in split.items()))
    if "cleaning" in d:
        lines.append(f"- cleaning: {json.dumps(d['cleaning'])}")
    nuisance = r.extra.get("nuisance")
    if nuisance:
        lines.append(f"- nuisance: heading offset {nuisance['heading_offset_deg']:.3f} deg "
                     f"({nuisance['note']})")
    if r.notes:
        lines += ["", "## Notes", ""] + [f"{n}\n" for n in r.notes]
    return "\n".join(lines) + "\n"
