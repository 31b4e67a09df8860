"""Builder of ``water_cloud_phase_550nm.csv``: the phase matrix of the default water cloud.

The droplets of :class:`skysim.clouds.CloudLayer` (liquid water, Hale & Querry 1973
refractive index, gamma size distribution of Hansen & Travis 1974 with effective radius
10 um and effective variance 0.1) at 550 nm, from sasktran2's Lorenz-Mie code through
:func:`skysim.clouds.cloud_optics`: the phase-matrix elements ``p11`` (mean 1 over the
sphere) and ``p12`` (positive: polarized perpendicular to the scattering plane) every 0.1 deg
of scattering angle, and, as header comments, the single-scattering albedo and the asymmetry
parameter. ``tests/test_cloud_light.py`` checks the table against miepython, an independent
Mie code.

Run (needs the ``rt`` extra): ``python skysim/data/build_water_cloud_phase.py`` (writes the
CSV beside this file).
"""

from pathlib import Path

import numpy as np


def main() -> None:
    from skysim.clouds import cloud_optics
    from skysim.io import atomic_write
    o = cloud_optics(550.0, 10.0, 0.1)
    head = ["# Phase matrix of a liquid-water cloud at 550 nm: gamma size distribution "
            "(Hansen & Travis 1974, eq. 2.56), effective radius 10 um, effective variance 0.1; "
            "refractive index of Hale & Querry (1973)",
            "# Lorenz-Mie (sasktran2.mie) through skysim.clouds.cloud_optics; built by "
            "build_water_cloud_phase.py",
            f"# single_scattering_albedo = {o.single_scattering_albedo:.9f}",
            f"# asymmetry_parameter = {o.asymmetry_parameter:.9f}",
            "angle_deg,p11,p12"]
    rows = [f"{a:.1f},{p:.7e},{q:.7e}" for a, p, q in zip(o.angle_deg, o.p11, o.p12)]
    if not np.allclose(np.diff(o.angle_deg), 0.1):
        raise SystemExit("expected scattering angles every 0.1 deg")
    atomic_write(Path(__file__).with_name("water_cloud_phase_550nm.csv"),
                 lambda p: p.write_text("\n".join(head + rows) + "\n"))


if __name__ == "__main__":
    main()
