"""Angular acceptance of a ring unit's photodiodes and the quadrature that averages the sky's
Stokes vector over it.

The acceptance is the one measured on the units of the Gkanias et al. (2023) ring compass
[1]_ (their Fig. 9h): a torch was swept across two photodiodes in their 3D-printed casings in
10-deg steps and the readings logged (:data:`TORCH_SCAN`). Within about 20 deg of the axis the
readings sit on one plateau (11924-11972 counts, flat to 0.4 % while ``cos 20 deg = 0.94``):
the converter saturates there, so the on-axis response is at least the plateau and the widths
derived with the plateau as the peak are upper bounds. The unsaturated flanks fall from 0.4-0.7
of the plateau at 20 deg off-axis to 0.02-0.1 at 30 deg: steeper than a Gaussian, as a
photodiode behind an aperture is (a flat top vignetted at its edge). A generalized Gaussian

.. math:: a(\\theta) = \\exp[-\\ln 2\\,(\\theta / h)^n],\\qquad \\theta < 90^\\circ,

with ``h`` the half-width at half-maximum (HWHM) and ``n`` the edge's steepness, fits the six
flank readings of both photodiodes with a log-RMS of 0.14 (a Gaussian, ``n = 2``: 0.62):
``h = 22.7 +- 0.4 deg``, ``n = 4.7 +- 0.3`` (:func:`fit_torch_scan`). Beyond 40 deg the casing
lets through 0.1-3 % of the plateau: light through the plastic, which this acceptance leaves
out (sunlight reaching the photodiodes through the casing is what the ``stray_light`` and
``side_glare`` candidates model).

The width ``h`` of the diagnosis candidate is free between 0 (a pencil beam, the base model)
and 60 deg, the HWHM of a bare photodiode's cosine response, the widest any casing can leave
(a casing only narrows it). Directions below the horizon (a unit at 45 deg elevation sees the
ground from 45 deg off-axis) contribute no light: the ground is taken as dark. On the
measured acceptance the ground lies where ``a < 1e-7`` of the on-axis response; at the
60-deg bound a dark ground underestimates the radiance that units then see (a field of albedo
0.1-0.2 sends back a tenth to a fifth of the sky's light, unpolarized).

References
----------
.. [1] E. Gkanias, R. Mitchell, J. Stankiewicz, S. R. Khan, S. Mitra, B. Webb, "Celestial
   compass sensor mimics the insect eye for navigation under cloudy and occluded skies",
   Commun. Eng. 2:82 (2023), doi:10.1038/s44172-023-00132-w, Fig. 9h; the torch scan is
   ``sensor_response_distribution/map.txt`` of the repository
   InsectRobotics/CelestialCompassAnalysis (commit a14712c1165b385a51d0c9d2817af820409db4fe,
   GPL-3.0; the readings are quoted here as measured values, averaged over the two logged
   extremes at each angle).
.. [2] G. H. Golub, J. H. Welsch, "Calculation of Gauss quadrature rules", Math. Comp.
   23:221-230 (1969) (Gauss-Legendre nodes and weights, :func:`numpy.polynomial.legendre.leggauss`).
"""

from __future__ import annotations

import functools

import numpy as np

from skysim.exceptions import InvalidParameterError

__all__ = ["TORCH_SCAN", "PLATEAU_COUNTS", "ACCEPTANCE_HWHM_DEG", "ACCEPTANCE_ORDER",
           "HWHM_MAX_DEG", "fit_torch_scan", "acceptance", "acceptance_quadrature",
           "quadrature_rotations_deg", "observe_directions", "observe_axes",
           "observe_acceptance", "unit_up_vectors", "theta_max_deg", "visible_half_arc",
           "arc_azimuth_deg", "horizon_quadrature",
           "observe_cut_acceptance"]

TORCH_SCAN = {
    "angle_deg": np.arange(-90.0, 91.0, 10.0),
    "pd3_counts": np.array([2.0, 15.0, 36.0, 74.5, 107.0, 273.0, 517.5, 8047.5, 11956.5,
                            11926.0, 11952.0, 11970.0, 1253.0, 374.5, 155.5, 88.5, 50.5, 22.0,
                            4.0]),
    "pd4_counts": np.array([1.5, 6.5, 11.5, 21.5, 86.5, 249.5, 2684.5, 11944.5, 11961.5,
                            11935.0, 11965.5, 5270.0, 192.0, 101.0, 26.0, 21.5, 14.0, 8.5,
                            1.0]),
}
"""Torch scan of photodiodes 3 and 4 of a ring unit [counts, absolute values] against the
torch's angle from the photodiode's axis [deg] (reference [1] of the module)."""

PLATEAU_COUNTS = 11950.0
"""Level [counts] on which the scan's readings within about 20 deg of the axis sit (the
converter's saturation; median of the nine plateau readings, 11924-11972)."""

ACCEPTANCE_HWHM_DEG = 22.7
"""HWHM [deg] of the measured acceptance (:func:`fit_torch_scan`, an upper bound: the peak
is saturated)."""

ACCEPTANCE_ORDER = 4.7
"""Steepness ``n`` of the measured acceptance's edge (:func:`fit_torch_scan`)."""

HWHM_MAX_DEG = 60.0
"""Widest HWHM [deg]: a bare photodiode's cosine response (``cos 60 deg = 1/2``)."""

_CUT = 1e-6
"""Relative acceptance at which the polar quadrature stops (the weight left out beyond it is
below ``1e-6`` of the total for ``n >= 2``)."""


def fit_torch_scan():
    """The measured acceptance's HWHM and edge steepness from :data:`TORCH_SCAN`.

    Fits ``log(r / plateau) = -ln 2 (|theta - b_k| / h)^n`` to the edge readings of both
    photodiodes (those within 30 deg of the axis and below 90 % of the plateau, six in all:
    from 40 deg outward the readings level off at 0.1-3 % of the plateau, light through the
    casing, not the aperture's edge), with one centre ``b_k`` per photodiode (its own
    mounting) and ``h``, ``n`` shared.

    Returns
    -------
    dict
        ``hwhm_deg``, ``order``, their standard errors ``hwhm_se_deg``, ``order_se``, the
        centres ``centres_deg`` (2,) and ``log_rms`` (RMS of the log residuals), and
        ``gaussian_log_rms``: the same fit with ``n = 2``.
    """
    from scipy.optimize import least_squares
    x = TORCH_SCAN["angle_deg"]
    sel = [(r / PLATEAU_COUNTS) for r in (TORCH_SCAN["pd3_counts"], TORCH_SCAN["pd4_counts"])]
    keep = [(np.abs(x) <= 30.0) & (y < 0.9) for y in sel]

    def resid(h, n, b):
        return np.concatenate([-np.log(2.0) * (np.abs(x[k] - bk) / h) ** n - np.log(y[k])
                               for y, k, bk in zip(sel, keep, b)])
    full = least_squares(lambda p: resid(p[0], p[1], p[2:]), [20.0, 4.0, 0.0, 0.0])
    dof = full.fun.size - full.x.size
    cov = np.linalg.inv(full.jac.T @ full.jac) * np.sum(full.fun ** 2) / dof
    gauss = least_squares(lambda p: resid(p[0], 2.0, p[1:]), [20.0, 0.0, 0.0])
    return {"hwhm_deg": float(full.x[0]), "order": float(full.x[1]),
            "hwhm_se_deg": float(np.sqrt(cov[0, 0])), "order_se": float(np.sqrt(cov[1, 1])),
            "centres_deg": full.x[2:].copy(),
            "log_rms": float(np.sqrt(np.mean(full.fun ** 2))),
            "gaussian_log_rms": float(np.sqrt(np.mean(gauss.fun ** 2)))}


@functools.lru_cache(maxsize=16)
def _leggauss(n: int):
    """Gauss-Legendre nodes and weights on [-1, 1] ([2]_), read-only and remembered: a fit
    builds the same rules at every evaluation of the acceptance, and their eigenvalue
    problems cost 2 ms of each (more than the sky's sums, :func:`_single_scattering_sums`)."""
    x, w = np.polynomial.legendre.leggauss(n)
    x.flags.writeable = w.flags.writeable = False
    return x, w


def _check_width(hwhm_deg, order):
    h, n = float(hwhm_deg), float(order)
    if not np.isfinite(h) or not 0.0 < h <= HWHM_MAX_DEG:
        raise InvalidParameterError(
            f"acceptance half-width {hwhm_deg!r} deg must be in (0, {HWHM_MAX_DEG:g}]")
    if not np.isfinite(n) or n < 2.0:
        raise InvalidParameterError(f"acceptance order {order!r} must be finite and >= 2")
    return h, n


def acceptance(theta_deg, hwhm_deg: float, order: float = ACCEPTANCE_ORDER) -> np.ndarray:
    """Relative response of a photodiode to light ``theta_deg`` [deg] off its axis.

    ``exp(-ln 2 (theta / h)^n)`` in front of the photodiode (``theta < 90 deg``), 0 behind.

    Parameters
    ----------
    theta_deg : array_like
        Off-axis angle [deg], >= 0.
    hwhm_deg : float
        Half-width at half-maximum ``h`` [deg], in (0, :data:`HWHM_MAX_DEG`].
    order : float
        Edge steepness ``n`` (>= 2; 2 is a Gaussian).

    Returns
    -------
    ndarray
        Response relative to the on-axis one.

    Raises
    ------
    InvalidParameterError
        For a width or order out of range.
    """
    h, n = _check_width(hwhm_deg, order)
    t = np.asarray(theta_deg, float)
    return np.where(t < 90.0, np.exp(-np.log(2.0) * (t / h) ** n), 0.0)


def acceptance_quadrature(hwhm_deg: float, order: float = ACCEPTANCE_ORDER, *,
                          n_polar: int = 4, n_azimuth: int = 6):
    """Directions and weights that average a field over the acceptance.

    Gauss-Legendre in the off-axis angle ``theta`` on ``[0, theta_max]`` (``theta_max`` where
    the acceptance falls to ``1e-6``, at most 90 deg) times the midpoint rule in the azimuth
    about the axis (exact for azimuthal harmonics below ``n_azimuth``), each node weighted by
    ``a(theta) sin(theta)`` and the weights normalised to sum to 1, so that
    ``sum(w f) -> int a f dOmega / int a dOmega``.

    Parameters
    ----------
    hwhm_deg, order : float
        The acceptance (:func:`acceptance`).
    n_polar, n_azimuth : int
        Nodes in ``theta`` and in the azimuth (>= 1 each).

    Returns
    -------
    theta_deg, azimuth_deg, weights : ndarray (n_polar * n_azimuth,)
        Off-axis angle [deg], azimuth about the axis [deg] and weight of each direction.

    Raises
    ------
    InvalidParameterError
        For a width or order out of range, or node counts below 1.
    """
    h, n = _check_width(hwhm_deg, order)
    for name, v in (("n_polar", n_polar), ("n_azimuth", n_azimuth)):
        if int(v) != v or v < 1:
            raise InvalidParameterError(f"{name} {v!r} must be a positive integer")
    t_max = theta_max_deg(h, n)
    x, gw = _leggauss(int(n_polar))
    t = 0.5 * t_max * (x + 1.0)
    w_t = gw * acceptance(t, h, n) * np.sin(np.radians(t))
    b = 360.0 * (np.arange(n_azimuth) + 0.5) / n_azimuth
    # alternate rings half a step apart in azimuth: fewer coincident azimuths across rings
    az = (b[None, :] + 180.0 / n_azimuth * (np.arange(n_polar) % 2)[:, None]) % 360.0
    w = np.repeat(w_t, n_azimuth)
    return np.repeat(t, n_azimuth), az.ravel(), w / w.sum()


def quadrature_rotations_deg(theta_deg, azimuth_deg) -> np.ndarray:
    """Rotation vectors [deg] (k, 3) in a unit's frame that turn its axis ``theta_deg`` off
    along ``azimuth_deg`` about it: rotations by ``theta`` about the in-plane axis
    ``(cos b, sin b, 0)``, which carry the unit's polarizer frame along the great circle (the
    parallel transport of its reference direction)."""
    t, b = np.asarray(theta_deg, float), np.radians(np.asarray(azimuth_deg, float))
    return np.stack([t * np.cos(b), t * np.sin(b), np.zeros_like(t)], axis=-1)


def theta_max_deg(hwhm_deg: float, order: float = ACCEPTANCE_ORDER, cut: float = _CUT) -> float:
    """Off-axis angle [deg] where the acceptance (:func:`acceptance`) falls to ``cut`` of its
    on-axis value, at most 90 deg: ``h (ln(1/cut) / ln 2)^(1/n)``."""
    return float(min(90.0, hwhm_deg * (np.log(1.0 / cut) / np.log(2.0)) ** (1.0 / order)))


def visible_half_arc(theta_deg, up) -> np.ndarray:
    """Half-width [rad] of the arc of directions ``theta_deg`` off a unit's axis that look
    above the horizon, about the axis's upward tilt: a direction at azimuth ``beta`` from
    that tilt looks at elevation ``arcsin(sin e cos theta + cos e sin theta cos beta)``
    (``e`` the axis's elevation, ``up`` the local vertical in the unit's frame,
    :func:`unit_up_vectors`), above the horizon for ``|beta| <= arccos(-tan e cot theta)``:
    pi (the whole circle) out to ``theta = 90 - e``, 0 for none."""
    sin_e, cos_e = up[2], np.hypot(up[0], up[1])
    t = np.radians(np.asarray(theta_deg, float))
    with np.errstate(divide="ignore", invalid="ignore"):
        lim = np.where(cos_e * np.sin(t) > 0.0, -sin_e * np.cos(t) / (cos_e * np.sin(t)),
                       -np.inf)
    return np.arccos(np.clip(lim, -1.0, 1.0))


def arc_azimuth_deg(beta_deg, up) -> np.ndarray:
    """The azimuth about a unit's axis [deg] (the convention of
    :func:`quadrature_rotations_deg`) of a direction ``beta_deg`` from the axis's upward
    tilt: the direction tilts along ``beta + phi_up`` and a rotation about
    ``(cos b, sin b, 0)`` tilts the axis along ``(sin b, -cos b)``, so ``b = beta + phi_up +
    90 deg``."""
    phi = np.degrees(np.arctan2(up[1], up[0])) if np.hypot(up[0], up[1]) > 0 else 0.0
    return (np.asarray(beta_deg, float) + phi + 90.0) % 360.0


def _columns(sensor, sky, att, sun_enu, theta_deg, azimuth_deg, weights, *,
             drop_below: bool = True, dark_below: bool = False, per_column: bool = True):
    """Every unit's view along every direction about its axis, those below the horizon at
    any sample dropped: the geometry and the sky's light of each kept column.

    One rotation per direction, built once and applied after every unit's own installation
    error (a column's unit-to-sensor matrix is the unit's times the direction's); what a
    column sees at every sample is a ``(n x 3) @ (3 x c)`` product of a per-sample vector
    (the local vertical, the sun) in the sensor frame with the columns' axes, and the sky's
    light comes from one call on all columns (:func:`_sky_light`).

    With ``drop_below`` False a column below the horizon at some sample raises
    :class:`~sensor.compound_eye.UnitBelowHorizonError` (naming its unit and sample), as the
    sensor's own sampling does. With ``dark_below`` every column is kept and ``visible``
    says at which samples it looks above the horizon (the ground dark there only).

    ``theta_deg``, ``azimuth_deg``, ``weights`` are either one set of directions (k,) shared
    by every unit or a sequence of one set per unit (lengths may differ).

    Returns
    -------
    dict
        ``unit``, ``weight``, ``theta`` (c,) of the kept columns; ``visible`` (n, c) bool;
        ``axes`` (c, 3, 3) their unit-to-sensor matrices; ``R_ns`` (n, 3, 3) the
        sensor-to-ENU rotation of every sample; ``radiance`` (n, c) of the sky; with
        ``per_column``, ``dop``, ``e_x``, ``e_y`` (the e-vector's components on each
        column's polarizer x and y axes), ``elevation``, ``azimuth`` [deg] (n, c); without,
        what :func:`_stokes_average` sums: ``q``, ``u`` (n, c), the linearly polarized
        radiance ``I d cos 2 chi``, ``I d sin 2 chi`` in each column's polarizer frame, and
        ``e_x``, ``e_y``, or for the single-scattering sky the sums themselves (``sums``,
        :func:`_single_scattering_sums`) and the sun in the sensor frame ``s_sensor`` (n, 3).
    """
    from scipy.spatial.transform import Rotation

    from sensor.compound_eye import UnitBelowHorizonError

    m = sensor.n_units
    if isinstance(theta_deg, (list, tuple)) and theta_deg and np.ndim(theta_deg[0]) == 1:
        sets = list(zip(theta_deg, azimuth_deg, weights))
        if len(sets) != m:
            raise InvalidParameterError(
                f"{len(sets)} sets of directions for a sensor of {m} units")
    else:
        sets = [(theta_deg, azimuth_deg, weights)] * m
    t = np.concatenate([np.asarray(s_[0], float) for s_ in sets])
    b = np.concatenate([np.asarray(s_[1], float) for s_ in sets])
    w = np.concatenate([np.asarray(s_[2], float) for s_ in sets])
    sizes = np.array([np.size(s_[0]) for s_ in sets])
    unit = np.repeat(np.arange(m), sizes)
    axes = sensor.unit_matrices(True)[unit]                                     # (c, 3, 3)
    if np.any(t != 0.0):        # the units' own axes (the sensor's sampling) need no turn
        axes = axes @ Rotation.from_rotvec(quadrature_rotations_deg(t, b),
                                           degrees=True).as_matrix()
    R_ns = att.as_matrix().reshape(-1, 3, 3) @ sensor.body_installation().as_matrix()
    vz = R_ns[:, 2, :] @ axes[:, :, 2].T            # the views' ENU up component (n, c)
    visible = vz >= 0.0
    keep = np.ones(unit.size, bool) if dark_below else np.all(visible, axis=0)
    if not drop_below and not keep.all():
        below = ~visible
        i, c = np.argwhere(below)[0]
        el = np.degrees(np.arcsin(np.clip(vz[i, c], -1.0, 1.0)))
        raise UnitBelowHorizonError(
            f"unit {unit[c]} looks {el:.2f} deg below the horizon at sample {i} "
            f"({int(below.sum())} unit-samples in all); limit pitch/roll or tilt the unit up")
    if not keep.any() or (dark_below and not visible.any()):
        raise UnitBelowHorizonError("every direction about every unit's axis looks below the "
                                    "horizon at some sample")
    if not keep.all():
        axes, vz, visible = axes[keep], vz[:, keep], visible[:, keep]
    cols = {"unit": unit[keep], "weight": w[keep], "theta": t[keep], "visible": visible,
            "axes": axes, "R_ns": R_ns}
    s_sensor = _sun_in_sensor(sky, R_ns, sun_enu)
    if s_sensor is not None and not per_column:
        cols["s_sensor"] = s_sensor
        cols["sums"] = _single_scattering_sums(cols, s_sensor, sky.dmax, m)
    else:
        cols.update(_sky_light(sky, R_ns, axes, vz, sun_enu, per_column, s_sensor))
    return cols


def _enu(R_ns, axes, k, j) -> np.ndarray:
    """ENU component ``j`` (n, c) of the columns' axis ``k`` (0, 1: polarizer x, y; 2: view)
    at every sample."""
    return R_ns[:, j, :] @ axes[:, :, k].T


def _view_angles(view):
    """Elevation and azimuth [deg, in [0, 360)] (n, c) of ENU view components ``view``, and
    the horizontal length of each view."""
    vx, vy, vz = view
    horiz = np.sqrt(vx * vx + vy * vy)
    el = np.degrees(np.arctan2(vz, horiz))
    az = np.degrees(np.arctan2(vx, vy))
    az[az < 0.0] += 360.0
    return el, az, horiz


def _sun_in_sensor(sky, R_ns, sun_enu):
    """The unit sun vector in the sensor frame (n, 3) at every sample, for the
    single-scattering sky (:class:`skysim.sky.RayleighSky` in float64), whose light
    :func:`_sky_light` and :func:`_single_scattering_sums` read off the sun's projections on
    the columns' axes; None for every other sky.

    Raises
    ------
    SunBelowHorizonError
        For a sun below the sky model's lowest elevation, as :meth:`skysim.sky.Sky.field`.
    """
    from skysim.geometry import elevation_azimuth
    from skysim.sky import RayleighSky
    from skysim.validation import check_finite, check_sun_above_horizon

    if type(sky) is not RayleighSky or sky.dtype != np.float64:
        return None
    sun = np.asarray(sun_enu, float).reshape(-1, 3)
    check_sun_above_horizon(elevation_azimuth(sun)[0], sky.min_sun_elevation_deg)
    check_finite("sun vector", sun)
    s = sun / np.linalg.norm(sun, axis=-1, keepdims=True)
    return np.einsum("nji,nj->ni", R_ns, s)


def _sky_light(sky, R_ns, axes, vz, sun_enu, per_column: bool, s_sensor=None) -> dict:
    """The sky's light on the columns ``axes`` (c, 3, 3) at the samples' rotations ``R_ns``
    (``vz`` (n, c) the views' ENU up component): the entries of :func:`_columns` after its
    geometry.

    The single-scattering sky (``s_sensor``, the sun in the sensor frame, given:
    :func:`_sun_in_sensor`) is read off the sun's projections ``p_x``, ``p_y`` on each
    column's polarizer axes: its e-vector ``v x s`` has the components ``(-p_y, p_x)`` on
    them (the axes and the view are right-handed) and ``sin^2 gamma = p_x^2 + p_y^2``
    (:func:`skysim.rayleigh.stokes_from_sun_projections`), no angle computed. Every other
    sky goes through angles: :meth:`skysim.sky.Sky.field` at each view's elevation (clipped
    at the horizon: a column below it adds no light, :func:`_stokes_average`) and azimuth,
    its angle of polarization turned onto the polarizer axes through the view's local sky
    basis ``e_el = (-sin h sin A, -sin h cos A, cos h)``, ``e_az = (cos A, -sin A, 0)``
    (with ``sin h``, ``cos h``, ``sin A``, ``cos A`` read off the view vector; ``A = 0``
    straight up, as the view's azimuth is there). The two agree to rounding (tested).
    """
    from skysim.geometry import cos_sin_deg, elevation_azimuth

    if s_sensor is not None:
        from skysim.rayleigh import stokes_from_sun_projections
        p_x, p_y = (s_sensor @ axes[:, :, k].T for k in (0, 1))
        radiance = stokes_from_sun_projections(p_x, p_y, sky.dmax)[0]
        s2 = p_x * p_x + p_y * p_y
        dop = np.multiply(s2, sky.dmax)
        dop /= np.subtract(2.0, s2)
        e_x, e_y = _e_from_projections(p_x, p_y, R_ns, axes)
        el, az, _ = _view_angles((_enu(R_ns, axes, 2, 0), _enu(R_ns, axes, 2, 1), vz))
        return {"radiance": radiance, "dop": dop, "e_x": e_x, "e_y": e_y, "elevation": el,
                "azimuth": az}
    sun = np.asarray(sun_enu, float).reshape(-1, 3)
    sun_el, sun_az = elevation_azimuth(sun)
    view = (_enu(R_ns, axes, 2, 0), _enu(R_ns, axes, 2, 1), vz)
    vx, vy = view[:2]
    el, az, horiz = _view_angles(view)
    fld = sky.field(np.clip(el, 0.0, 90.0), az, sun_el[:, None], sun_az[:, None])
    up = horiz == 0.0
    if up.any():
        safe = np.where(up, 1.0, horiz)
        sa, ca = np.where(up, 0.0, vx / safe), np.where(up, 1.0, vy / safe)
    else:
        inv = 1.0 / horiz
        sa, ca = vx * inv, vy * inv
    c, s = cos_sin_deg(fld.aop_deg)
    e = []
    for k in (0, 1):     # the e-vector on the polarizer x, then y axes
        ax, ay, az_ = (_enu(R_ns, axes, k, j) for j in range(3))
        on_el = horiz * az_ - vz * (sa * ax + ca * ay)
        on_az = ca * ax - sa * ay
        e.append(c * on_el + s * on_az)
    out = {"radiance": fld.I, "e_x": e[0], "e_y": e[1]}
    if per_column:
        out.update(dop=fld.dop, elevation=el, azimuth=az)
    else:
        ex, ey = e
        # the polarized radiance on the polarizer axes: I d (cos 2 chi, sin 2 chi) of the
        # e-vector (e_x, e_y), a unit vector
        Lp = fld.I * fld.dop / (ex * ex + ey * ey)
        out["q"], out["u"] = Lp * (ex * ex - ey * ey), Lp * (2.0 * ex * ey)
    return out


def _single_scattering_sums(cols, s_sensor, dmax: float, m: int):
    """Each unit's weighted sums over its columns of the single-scattering sky's ``I``,
    ``Q``, ``U`` (n, m each; ``Q``, ``U`` in each column's polarizer frame), a column adding
    nothing at the samples where it looks below the horizon, and of the views of the
    columns above it in the sensor frame (n, m, 3).

    With ``p_x = s . x``, ``p_y = s . y`` the sun's projections on a column's polarizer
    axes (:func:`skysim.rayleigh.stokes_from_sun_projections`), ``I = 3/2 - 3/4 (p_x^2 +
    p_y^2)``, ``Q = 3/4 d_max (p_y^2 - p_x^2)``, ``U = -3/2 d_max p_x p_y`` are quadratic
    forms in the sun: a unit's weighted sum over the columns that see the sky at every
    sample is ``s^T A s`` with ``A = sum w (y y^T - x x^T)`` (for ``Q``) and the like, three
    3 x 3 matrices per unit built once, so those columns cost nothing per sample; only
    the columns the horizon cuts at some sample (a tilting platform) are summed one by one.
    On the real ring session's thinned samples (1,240 samples, 8 units of 84 directions)
    the ``fov`` candidate's observation takes 4.6 ms this way, against 22 ms summing every
    column; equal to rounding (tested against the route through angles)."""
    from skysim.rayleigh import stokes_from_sun_projections
    unit, w, vis, axes = cols["unit"], cols["weight"], cols["visible"], cols["axes"]
    always = vis.all(axis=0)                                           # (c,)
    H = np.zeros((m, int(always.sum())))                     # (m, c'): weight of each column
    H[unit[always], np.arange(H.shape[1])] = w[always]
    x, y, z = (axes[always, :, k] for k in range(3))

    def outer(a, b):
        return (a[:, :, None] * b[:, None, :]).reshape(-1, 9)

    xx, yy, xy = outer(x, x), outer(y, y), outer(x, y)
    A = np.stack([H @ (xx + yy), H @ (yy - xx), H @ xy])                 # (3, m, 9)
    ss = (s_sensor[:, :, None] * s_sensor[:, None, :]).reshape(-1, 9)     # (n, 9)
    forms = ss @ A.reshape(3 * m, 9).T                                     # (n, 3m)
    I = 1.5 * H.sum(axis=1) - 0.75 * forms[:, :m]
    Q = 0.75 * dmax * forms[:, m:2 * m]
    U = -1.5 * dmax * forms[:, 2 * m:]
    view = np.broadcast_to(H @ z, (s_sensor.shape[0], m, 3))
    cut = np.flatnonzero(~always)
    if cut.size:
        G = np.zeros((cut.size, m))
        G[np.arange(cut.size), unit[cut]] = w[cut]
        v = vis[:, cut]
        p_x, p_y = (s_sensor @ axes[cut, :, k].T for k in (0, 1))
        for total, part in zip((I, Q, U), stokes_from_sun_projections(p_x, p_y, dmax)):
            total += np.where(v, part, 0.0) @ G
        G3 = (G[:, :, None] * axes[cut, None, :, 2]).reshape(cut.size, 3 * m)
        view = view + (v @ G3).reshape(-1, m, 3)
    return I, Q, U, view


def _e_from_projections(p_x, p_y, R_ns, axes):
    """The single-scattering e-vector's components ``(e_x, e_y)`` (n, c) on the polarizer
    axes of the columns ``axes`` from the sun's projections ``p_x``, ``p_y`` on them:
    ``(-p_y, p_x) / sin gamma``. Along the sun and the anti-sun, where the angle of
    polarization is undefined and taken as 0 (:func:`skysim.rayleigh.polarization_field`),
    the e-vector is the view's meridian direction ``e_el`` (straight up a view's ``A = 0``)."""
    s2 = p_x * p_x + p_y * p_y
    with np.errstate(divide="ignore", invalid="ignore"):     # along the sun: set below
        k = np.divide(1.0, np.sqrt(s2))
        e_x = np.multiply(p_y, k)
        np.negative(e_x, out=e_x)
        e_y = np.multiply(p_x, k, out=k)
    along = s2 == 0.0
    if along.any():
        i, c = np.nonzero(along)
        R = R_ns[i]
        v = np.einsum("pij,pj->pi", R, axes[c, :, 2])
        horiz = np.hypot(v[:, 0], v[:, 1])
        up = horiz == 0.0
        safe = np.where(up, 1.0, horiz)
        sa, ca = np.where(up, 0.0, v[:, 0] / safe), np.where(up, 1.0, v[:, 1] / safe)
        e_el = np.stack([-v[:, 2] * sa, -v[:, 2] * ca, horiz], axis=-1)
        for e, k_ in ((e_x, 0), (e_y, 1)):
            e[i, c] = np.einsum("pi,pi->p", e_el, np.einsum("pij,pj->pi", R, axes[c, :, k_]))
    return e_x, e_y


def _e_components(cols, which):
    """The e-vector's components ``(e_x, e_y)`` (n, len(which)) on the polarizer axes of
    the columns ``which`` (those :func:`_columns` computed, or from the sun's projections)."""
    if "e_x" in cols:
        return cols["e_x"][:, which], cols["e_y"][:, which]
    axes = cols["axes"][which]
    p_x, p_y = (cols["s_sensor"] @ axes[:, :, k].T for k in (0, 1))
    return _e_from_projections(p_x, p_y, cols["R_ns"], axes)


def _e_vector_sensor(cols, which) -> np.ndarray:
    """Unit e-vectors (n, len(which), 3) in the sensor frame of the columns ``which``."""
    ax = cols["axes"][which]
    e_x, e_y = _e_components(cols, which)
    e = ax[:, :, 0] * e_x[:, :, None]
    e += ax[:, :, 1] * e_y[:, :, None]
    e /= np.sqrt(np.einsum("ncj,ncj->nc", e, e))[:, :, None]
    return e


def observe_directions(sensor, sky, att, sun_enu, theta_deg, azimuth_deg, weights):
    """What each unit sees along directions about its axis, those below the horizon dropped.

    Parameters
    ----------
    sensor : sensor.compound_eye.CompoundEyeSensor
        The instrument (its units' own installation errors kept: each direction's rotation
        is applied after them).
    sky, att, sun_enu
        As for :meth:`~sensor.compound_eye.CompoundEyeSensor.observe`.
    theta_deg, azimuth_deg, weights : array_like (k,), or a list of one per unit
        Directions about each unit's axis [deg] and their weights
        (:func:`acceptance_quadrature`, or :func:`horizon_quadrature`'s per-unit sets).

    Returns
    -------
    obs : SkySample
        What the kept directions see, columns ``(unit, direction)`` in unit order.
    unit : ndarray of int (c,)
        Unit of each column.
    weight : ndarray (c,)
        Weight of each column (those of directions below the horizon at any sample dropped,
        the rest unchanged: the ground is dark).
    theta : ndarray (c,)
        Off-axis angle [deg] of each column.
    """
    from sensor.compound_eye import SkySample
    from skysim.geometry import wrap_axial_deg

    cols = _columns(sensor, sky, att, sun_enu, theta_deg, azimuth_deg, weights)
    chi = wrap_axial_deg(np.degrees(np.arctan2(cols["e_y"], cols["e_x"])))
    e_s = _e_vector_sensor(cols, np.arange(cols["unit"].size))
    obs = SkySample(cols["radiance"], cols["dop"], chi, e_s, cols["elevation"],
                    cols["azimuth"])
    return obs, cols["unit"], cols["weight"], cols["theta"]


def observe_axes(sensor, sky, att, sun_enu):
    """What each unit sees along its own axis: the sensor's sampling
    (:meth:`~sensor.compound_eye.CompoundEyeSensor.observe`, equal to rounding) by the
    vectorised pass of :func:`observe_directions`, which reads each view's sky basis off its
    vector.

    Parameters
    ----------
    sensor, sky, att, sun_enu
        As for :meth:`~sensor.compound_eye.CompoundEyeSensor.observe`.

    Returns
    -------
    SkySample
        One column per unit.

    Raises
    ------
    UnitBelowHorizonError
        If a unit looks below the ENU horizon at some sample (names unit and sample).
    """
    from sensor.compound_eye import SkySample
    from skysim.geometry import wrap_axial_deg

    cols = _columns(sensor, sky, att, sun_enu, [0.0], [0.0], [1.0], drop_below=False)
    chi = wrap_axial_deg(np.degrees(np.arctan2(cols["e_y"], cols["e_x"])))
    return SkySample(cols["radiance"], cols["dop"], chi,
                     _e_vector_sensor(cols, np.arange(sensor.n_units)), cols["elevation"],
                     cols["azimuth"])


def observe_acceptance(sensor, sky, att, sun_enu, theta_deg, azimuth_deg, weights):
    """What each unit's photodiodes see through an acceptance: the sky's Stokes vector
    averaged over the directions about its axis (:func:`observe_directions`), radiance
    included.

    ``I = sum w L``, ``Q = sum w L d cos 2 chi``, ``U = sum w L d sin 2 chi`` over each
    unit's kept directions (``chi`` in the unit's polarizer frame, carried along each
    direction); the unit's view is the weighted mean of its directions above the horizon and
    its e-vector in the sensor frame that of its direction nearest the axis.

    Parameters
    ----------
    sensor, sky, att, sun_enu, theta_deg, azimuth_deg, weights
        As for :func:`observe_directions`.

    Returns
    -------
    SkySample
        One column per unit.
    """
    cols = _columns(sensor, sky, att, sun_enu, theta_deg, azimuth_deg, weights,
                    per_column=False)
    return _stokes_average(cols, sensor.n_units)


def _stokes_average(cols, m):
    """One column per unit: the Stokes average of ``cols`` (:func:`_columns` without
    ``per_column``), a column contributing no light at the samples where it looks below
    the horizon."""
    from sensor.compound_eye import SkySample
    from skysim.geometry import elevation_azimuth

    unit, theta, vis = cols["unit"], cols["theta"], cols["visible"]
    if "sums" in cols:
        I, Q, U, view = cols["sums"]
    else:
        G = np.zeros((unit.size, m))
        G[np.arange(unit.size), unit] = cols["weight"]            # (c, m): weight into unit
        I = np.where(vis, cols["radiance"], 0.0) @ G
        Q = np.where(vis, cols["q"], 0.0) @ G
        U = np.where(vis, cols["u"], 0.0) @ G
        axis_sum = G[:, :, None] * cols["axes"][:, None, :, 2]             # (c, m, 3)
        view = (vis @ axis_sum.reshape(unit.size, 3 * m)).reshape(-1, m, 3)
    # the view: the weighted mean of the directions above the horizon at each sample, the
    # columns' axes summed in the sensor frame and turned into ENU once per unit
    el, az = elevation_azimuth(np.einsum("nij,nmj->nmi", cols["R_ns"], view))
    # each unit's e-vector from its direction nearest the axis (the sample's frame)
    first = np.array([np.flatnonzero(unit == u)[np.argmin(theta[unit == u])]
                      for u in range(m)])
    return SkySample(I, np.hypot(Q, U) / I, 0.5 * np.degrees(np.arctan2(U, Q)),
                     _e_vector_sensor(cols, first), el, az)


def unit_up_vectors(sensor, att) -> np.ndarray:
    """The local vertical (ENU up) in each unit's frame (m, 3), averaged over the samples and
    normalised: its z component is the sine of the unit's axis elevation, its x, y components
    point along the unit's axis's upward tilt (installation errors included).

    Parameters
    ----------
    sensor : sensor.compound_eye.CompoundEyeSensor
    att : scipy.spatial.transform.Rotation
        Body-to-ENU attitudes (n).

    Returns
    -------
    ndarray (m, 3)
    """
    R_ns = att.as_matrix().reshape(-1, 3, 3) @ sensor.body_installation().as_matrix()
    up_s = R_ns[:, 2, :].mean(axis=0)                   # ENU up in the sensor frame
    up = np.einsum("mij,i->mj", sensor.unit_matrices(True), up_s)
    return up / np.linalg.norm(up, axis=-1, keepdims=True)


def horizon_quadrature(hwhm_deg: float, up, order: float = ACCEPTANCE_ORDER, *,
                       n_polar: int = 6, n_azimuth: int = 6, n_arc: int | None = None):
    """Directions and weights that average a field over the acceptance of a unit whose view
    the horizon cuts, the ground dark: ``sum(w f) -> int_sky a f dOmega / int a dOmega``
    (the normalisation is the whole acceptance: a photodiode sees the dark ground as no
    light, so a cut acceptance collects less light, with the sky's polarization of its
    visible part).

    With the unit's axis at elevation ``e`` and the direction ``theta`` off it at azimuth
    ``beta`` about it (from the axis's upward tilt), the direction looks at elevation
    ``arcsin(sin e cos theta + cos e sin theta cos beta)``: above the horizon for every
    ``beta`` out to ``theta_0 = 90 - e``, and beyond it on the arc
    ``|beta| <= arccos(-tan e cot theta)``. The rule resolves that step exactly: on
    ``[0, theta_0]`` the rule of :func:`acceptance_quadrature` (Gauss-Legendre in ``theta``,
    midpoints in the azimuth); on ``[theta_0, theta_max]`` Gauss-Legendre in ``s`` with
    ``theta = theta_0 + (theta_max - theta_0) s^2`` (the arc's half-width falls from 180 deg
    as ``sqrt(theta - theta_0)``, which is smooth in ``s``) times Gauss-Legendre on the arc.
    Where the acceptance ends before the horizon (``theta_max <= theta_0``) this is the rule
    of :func:`acceptance_quadrature`.

    Parameters
    ----------
    hwhm_deg, order : float
        The acceptance (:func:`acceptance`).
    up : array_like (3,) or (m, 3)
        The local vertical in each unit's frame (:func:`unit_up_vectors`).
    n_polar : int
        Gauss-Legendre nodes in ``theta`` on each of the two stretches.
    n_azimuth, n_arc : int
        Azimuth nodes on the full circles of the visible cap and on the arcs of the cut band
        (``n_arc`` None: ``n_azimuth``).

    Returns
    -------
    theta_deg, azimuth_deg, weights : list of ndarray
        One set per unit: off-axis angle [deg], azimuth about the axis [deg] (the convention
        of :func:`quadrature_rotations_deg`) and weight of each direction.

    Raises
    ------
    InvalidParameterError
        For a width or order out of range, node counts below 1, or a unit whose axis looks
        below the horizon.
    """
    h, n = _check_width(hwhm_deg, order)
    th0, az0, w0 = acceptance_quadrature(h, n, n_polar=n_polar, n_azimuth=n_azimuth)
    t_max = theta_max_deg(h, n)
    x, gw = _leggauss(int(n_polar))
    n_arc = int(n_azimuth if n_arc is None else n_arc)
    if n_arc < 1:
        raise InvalidParameterError(f"n_arc {n_arc!r} must be a positive integer")
    xb, gb = _leggauss(n_arc)
    out_t, out_b, out_w = [], [], []
    for u in np.atleast_2d(np.asarray(up, float)):
        sin_e = float(np.clip(u[2], -1.0, 1.0))
        if not sin_e > 0.0:
            raise InvalidParameterError(
                f"a unit's axis looks {-np.degrees(np.arcsin(sin_e)):.2f} deg below the "
                f"horizon (up vector {u.tolist()!r} in its frame): its acceptance needs the "
                f"axis above it")
        e = np.degrees(np.arcsin(sin_e))
        t0 = 90.0 - e
        if t0 >= t_max:
            out_t.append(th0), out_b.append(az0), out_w.append(w0)
            continue
        # the fully visible cap [0, t0]: Gauss-Legendre x midpoints
        t_a = 0.5 * t0 * (x + 1.0)
        w_a = gw * 0.5 * np.radians(t0) * acceptance(t_a, h, n) * np.sin(np.radians(t_a)) \
            * 2.0 * np.pi / n_azimuth
        b = 360.0 * (np.arange(n_azimuth) + 0.5) / n_azimuth
        b_a = (b[None, :] + 180.0 / n_azimuth * (np.arange(n_polar) % 2)[:, None]) % 360.0
        # the cut band [t0, t_max], theta = t0 + (t_max - t0) s^2, on the visible arc
        s_ = 0.5 * (x + 1.0)
        t_b = t0 + (t_max - t0) * s_ ** 2
        dt = gw * 0.5 * 2.0 * np.radians(t_max - t0) * s_            # dtheta = 2 (..) s ds
        half = visible_half_arc(t_b, u)                                # (n_polar,) [rad]
        if np.all(half >= np.pi):
            # the arc is the whole circle at every node (an axis at the zenith, whose
            # acceptance ends at the horizon): nothing is cut, and the uncut rule's
            # midpoints in azimuth keep the acceptance's symmetry about the axis exactly
            out_t.append(th0), out_b.append(az0), out_w.append(w0)
            continue
        beta = np.degrees(half[:, None] * xb[None, :])
        a_b = dt * acceptance(t_b, h, n) * np.sin(np.radians(t_b))
        w_b = (a_b * half)[:, None] * gb[None, :]
        b_b = arc_azimuth_deg(beta, u)
        # the normalisation, the whole acceptance, on the same nodes with full circles: the
        # rule's error in the polar angle then cancels between the visible part and the whole
        # (a separate fine integral left the weights summing to 0.997-1.003 and the radiance
        # jumping by 3e-3 where the horizon starts to cut), and as the cut band vanishes the
        # rule becomes the uncut one, normalised by its own sum
        total = n_azimuth * np.sum(w_a) + 2.0 * np.pi * np.sum(a_b)
        out_t.append(np.concatenate([np.repeat(t_a, n_azimuth), np.repeat(t_b, n_arc)]))
        out_b.append(np.concatenate([b_a.ravel(), b_b.ravel()]))
        out_w.append(np.concatenate([np.repeat(w_a, n_azimuth), w_b.ravel()]) / total)
    return out_t, out_b, out_w


def observe_cut_acceptance(sensor, sky, att, sun_enu, hwhm_deg: float,
                           order: float = ACCEPTANCE_ORDER, *, n_polar: int = 6,
                           n_azimuth: int = 6, n_arc: int | None = None):
    """What each unit's photodiodes see through an acceptance that the horizon may cut, the
    ground dark: the Stokes average of :func:`observe_acceptance` on the rule of
    :func:`horizon_quadrature` for each unit's mean vertical (:func:`unit_up_vectors`); a
    direction that looks below the horizon at some sample (a tilting platform) adds no light
    at that sample only.

    Parameters
    ----------
    sensor, sky, att, sun_enu
        As for :meth:`~sensor.compound_eye.CompoundEyeSensor.observe`.
    hwhm_deg, order : float
        The acceptance (:func:`acceptance`).
    n_polar, n_azimuth, n_arc : int
        Nodes of :func:`horizon_quadrature`.

    Returns
    -------
    SkySample
        One column per unit.
    """
    t, b, w = horizon_quadrature(hwhm_deg, unit_up_vectors(sensor, att), order,
                                 n_polar=n_polar, n_azimuth=n_azimuth, n_arc=n_arc)
    cols = _columns(sensor, sky, att, sun_enu, t, b, w, dark_below=True, per_column=False)
    return _stokes_average(cols, sensor.n_units)
