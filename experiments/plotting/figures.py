"""Figure output shared by every experiment: a headless backend and atomic PNG writes."""

from __future__ import annotations

from pathlib import Path

__all__ = ["pyplot", "quantity_label", "save_png"]


def pyplot():
    """:mod:`matplotlib.pyplot` on the non-interactive Agg backend (no display needed)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save_png(fig, path, dpi: int = 110) -> Path:
    """Write ``fig`` as PNG atomically (never a half-written figure) and close it."""
    import matplotlib.pyplot as plt

    from skysim.io import atomic_write
    path = Path(path)
    try:
        atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png"))
    finally:
        plt.close(fig)
    return path


_UNITS = {"deg": "deg", "lx": "lx", "s": "s", "min": "min", "h": "h", "m": "m", "km": "km",
          "nm": "nm", "C": "°C", "K": "K", "hPa": "hPa", "pct": "%", "dn": "DN", "v": "V",
          "mv": "mV", "e": "e-", "px": "px", "hz": "Hz"}
"""Unit suffixes of column names and how a figure writes them."""


def quantity_label(name: str) -> str:
    """A column name as a figure's words: ``illuminance_lx`` -> ``illuminance [lx]``,
    ``sun_elevation_deg`` -> ``sun elevation [deg]``, ``time of day`` unchanged (a last
    word that is not a known unit stays a word)."""
    head, _, last = str(name).rpartition("_")
    unit = _UNITS.get(last) or _UNITS.get(last.lower())
    if head and unit:
        return f"{head.replace('_', ' ')} [{unit}]"
    return str(name).replace("_", " ")
