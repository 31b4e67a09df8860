"""Figure output shared by every experiment: a headless backend and atomic PNG writes."""

from __future__ import annotations

from pathlib import Path

__all__ = ["pyplot", "save_png"]


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
