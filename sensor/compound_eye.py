"""Multi-direction ("compound-eye") polarization sensor with raw photodiode output.

Frames (all right-handed; rotations are :class:`scipy.spatial.transform.Rotation`):

- **ENU** (navigation frame n): x east, y north, z up.
- **Body** b: x right, y forward (the heading reference axis), z up. It mirrors ENU: at zero
  attitude with yaw 0 the body frame *is* ENU. A direction in the body or sensor frame is given
  like a sky direction: elevation above the x-y plane and azimuth clockwise (seen from above)
  from the forward axis, so :func:`skysim.geometry.direction_vector` applies unchanged.
- **Sensor** s: the frame of the instrument; nominally the body frame. The sensor-to-body
  installation error is a small rotation ``phi_1``: ``R_bs = Rotation.from_rotvec(phi_1)``.
  The zenith unit defines the sensor frame (its own installation error is zero by definition).
- **Unit** u_i: z along the unit's optical axis ``v``; x along ``e_el`` (the local meridian,
  towards the sensor zenith), y along ``e_az`` (see :func:`skysim.geometry.local_basis`).
  For a zenith unit the meridian is that of the unit's ``azimuth_deg``, so its x-axis points to
  azimuth ``azimuth_deg + 180``. Polarizer angles are measured from unit x towards unit y.
  A unit's installation error ``phi_i`` is a small rotation in its own frame:
  ``R_su = R_su_nominal * Rotation.from_rotvec(phi_i)`` (rotation about z: polarizer azimuth
  error; about x, y: pointing error).

Attitude (:func:`body_attitude`): ``R_nb = Rz(-yaw) Rx(pitch) Ry(roll)``, yaw clockwise from
north, pitch nose up, roll right side down.

Photodiode model (Malus's law for partially linearly polarized light [1]_): a photodiode behind
an ideal polarizer at angle ``a`` reads ``c * I * (1 + d cos 2(chi - a)) + noise`` counts,
where ``chi`` is the E-vector angle in the unit frame, then the reading is quantised and
clipped to ``[0, saturation_value]``.

References
----------
.. [1] G. Guo, X. Liu, J. Yang, Y. Wang (Beihang University), "A method of multi-direction
   calibration for polarization sensor imitating compound eye", Chinese patent (2020).
.. [2] E. Hecht, Optics, 5th ed., Pearson (2017), sect. 8.2 (Malus's law).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from skysim import __version__
from skysim.exceptions import InvalidParameterError
from skysim.geometry import cos_sin_deg, elevation_azimuth, local_basis, wrap_axial_deg, wrap_deg
from skysim.sky import Sky
from skysim.sun import Site, sun_vector
from skysim.validation import check_finite

from .photodiodes_io import (
    ACCEL_COLUMNS,
    PHOTODIODES_SCHEMA,
    PhotodiodeData,
    photodiode_column,
)

__all__ = ["THREE_PAIR_ANGLES_DEG", "FOUR_ANGLES_DEG", "GRAVITY_MPS2", "UnitBelowHorizonError",
           "Unit", "PhotodiodeModel", "CompoundEyeSensor", "SkySample", "body_attitude",
           "attitude_angles", "patent_configuration", "ring_configuration",
           "with_random_installation_errors"]

THREE_PAIR_ANGLES_DEG = (60.0, 150.0, 0.0, 90.0, 120.0, 30.0)
"""Three opponent pairs in the order of Yang et al. (2014): U1 = 60/150, U2 = 0/90, U3 = 120/30."""

FOUR_ANGLES_DEG = (0.0, 45.0, 90.0, 135.0)
"""Four photodiodes at 0/45/90/135 deg (division-of-amplitude polarimeter)."""

GRAVITY_MPS2 = 9.80665
"""Standard gravity [m/s^2]."""


class UnitBelowHorizonError(InvalidParameterError):
    """A unit looks below the horizon (of the sensor frame, or of ENU at some attitude).

    Ground-based sky models only look up: tilt the unit up or limit the carrier attitudes.
    """


@dataclass(frozen=True)
class Unit:
    """One polarization unit.

    Parameters
    ----------
    azimuth_deg : float
        Azimuth of the optical axis in the sensor frame [deg, clockwise from forward].
    elevation_deg : float
        Elevation of the optical axis above the sensor x-y plane [deg], in [0, 90].
    photodiodes_deg : tuple of float
        Polarizer angles [deg] (unit frame, from x towards y).
    installation_error_deg : 3 floats
        Rotation vector of the unit's installation error in its own frame [deg].
    """

    azimuth_deg: float
    elevation_deg: float
    photodiodes_deg: tuple = THREE_PAIR_ANGLES_DEG
    installation_error_deg: tuple = (0.0, 0.0, 0.0)

    def describe(self) -> dict:
        return {"azimuth_deg": float(self.azimuth_deg), "elevation_deg": float(self.elevation_deg),
                "photodiodes": [float(a) for a in self.photodiodes_deg]}


@dataclass(frozen=True)
class PhotodiodeModel:
    """Photodiode and ADC parameters.

    Parameters
    ----------
    counts_per_radiance : float
        Mean reading [counts] for unpolarized light of relative radiance 1 (the Rayleigh sky's
        ``I`` has mean 1 and stays below 1.5, so 20,000 keeps a 16-bit ADC below saturation).
    noise_counts : float
        Gaussian read + ADC noise [counts, 1 sigma] (a few LSB of a 16-bit converter).
    bits : int
        ADC resolution; readings are rounded to integers and clipped to [0, 2**bits - 1].
    """

    counts_per_radiance: float = 20_000.0
    noise_counts: float = 3.0
    bits: int = 16

    @property
    def saturation_value(self) -> float:
        return float(2 ** self.bits - 1)


@dataclass(frozen=True)
class SkySample:
    """What every unit sees at every sample (shapes (n, m) or (n, m, 3)).

    Attributes
    ----------
    radiance, dop : relative radiance and degree of linear polarization.
    aop_unit_deg : E-vector angle in the unit frame [deg, from unit x towards y, in [-90, 90)].
    e_vector_sensor : unit E-vector in the sensor frame (sign arbitrary: an axis).
    view_elevation_deg, view_azimuth_deg : actual view directions in ENU [deg].
    """

    radiance: np.ndarray
    dop: np.ndarray
    aop_unit_deg: np.ndarray
    e_vector_sensor: np.ndarray
    view_elevation_deg: np.ndarray
    view_azimuth_deg: np.ndarray


def body_attitude(yaw_deg, pitch_deg=0.0, roll_deg=0.0) -> Rotation:
    """Body-to-ENU rotation(s) ``R_nb`` from yaw/pitch/roll [deg] (see module doc)."""
    yaw, pitch, roll = np.broadcast_arrays(*(np.atleast_1d(check_finite(n, v)) for n, v in (
        ("yaw_deg", yaw_deg), ("pitch_deg", pitch_deg), ("roll_deg", roll_deg))))
    # intrinsic Z-X'-Y'' turns by (-yaw, pitch, roll): the product of their quaternions
    # (scalar last), as ``Rotation.from_euler("ZXY", ...)`` forms it, in closed form: 0.13 ms
    # for 1,500 samples against its 1.26 ms (a fit evaluates new headings hundreds of
    # times), the matrices equal to 7e-16
    cz, sz = cos_sin_deg(-0.5 * yaw)
    cx, sx = cos_sin_deg(0.5 * pitch)
    cy, sy = cos_sin_deg(0.5 * roll)
    q = np.stack([cy * cz * sx - cx * sz * sy, cx * cz * sy + cy * sz * sx,
                  cx * cy * sz + cz * sx * sy, cx * cy * cz - sx * sy * sz], axis=-1)
    return Rotation.from_quat(q)


def attitude_angles(attitude: Rotation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`body_attitude`: ``(yaw in [0, 360), pitch, roll)`` [deg]."""
    zxy = np.atleast_2d(attitude.as_euler("ZXY", degrees=True))
    return wrap_deg(-zxy[:, 0], 0.0), zxy[:, 1], zxy[:, 2]


def _unit_matrices(units, with_errors: bool) -> np.ndarray:
    az = np.array([u.azimuth_deg for u in units], dtype=float)
    el = np.array([u.elevation_deg for u in units], dtype=float)
    v, e_el, e_az = local_basis(el, az)
    nominal = np.stack([e_el, e_az, v], axis=-1)          # columns: unit x, y, z in sensor frame
    if not with_errors:
        return nominal
    err = Rotation.from_rotvec(np.array([u.installation_error_deg for u in units], float),
                               degrees=True).as_matrix()
    return nominal @ err


@dataclass(frozen=True)
class CompoundEyeSensor:
    """A set of polarization units on one rigid sensor head, mounted on a carrier body.

    Parameters
    ----------
    units : tuple of Unit
        Unit 0 should be the zenith unit when the installation calibration is used.
    installation_error_deg : 3 floats
        Sensor-to-body installation error ``phi_1`` as a rotation vector [deg].
    photodiode : PhotodiodeModel

    Raises
    ------
    UnitBelowHorizonError
        If a unit's elevation in the sensor frame is negative.
    """

    units: tuple
    installation_error_deg: tuple = (0.0, 0.0, 0.0)
    photodiode: PhotodiodeModel = field(default_factory=PhotodiodeModel)

    def __post_init__(self):
        if len(self.units) == 0:
            raise InvalidParameterError("a compound-eye sensor needs at least one unit")
        for i, u in enumerate(self.units):
            if not 0.0 <= float(u.elevation_deg) <= 90.0:
                raise UnitBelowHorizonError(
                    f"unit {i} elevation_deg={u.elevation_deg!r} is outside [0, 90]: a sky "
                    "polarization unit must look at or above the sensor's horizon")
            check_finite(f"unit {i} installation_error_deg", u.installation_error_deg)
        check_finite("installation_error_deg", self.installation_error_deg)

    @property
    def n_units(self) -> int:
        return len(self.units)

    def unit_matrices(self, with_errors: bool = True) -> np.ndarray:
        """Unit-to-sensor rotation matrices (m, 3, 3); columns are unit x, y, z."""
        return _unit_matrices(self.units, with_errors)

    def body_installation(self) -> Rotation:
        """Sensor-to-body rotation ``R_bs``."""
        return Rotation.from_rotvec(np.asarray(self.installation_error_deg, float), degrees=True)

    def view_directions_sensor(self, with_errors: bool = True) -> np.ndarray:
        """Optical axes in the sensor frame, (m, 3)."""
        return self.unit_matrices(with_errors)[:, :, 2]

    def observe(self, sky: Sky, attitude: Rotation, sun_enu) -> SkySample:
        """What each unit sees, along its actual (erroneous) direction, at n attitudes.

        Parameters
        ----------
        sky : Sky
        attitude : Rotation of length n
            True body-to-ENU attitudes ``R_nb``.
        sun_enu : array (n, 3)
            Sun unit vectors in ENU.

        Raises
        ------
        UnitBelowHorizonError
            If a unit looks below the ENU horizon at some attitude (names unit and sample).
        SunBelowHorizonError
            If the sun is below the horizon.
        """
        R_nb = attitude.as_matrix().reshape(-1, 3, 3)
        R_ns = R_nb @ self.body_installation().as_matrix()
        M_su = self.unit_matrices(True)                                     # (m, 3, 3)
        n, m = R_ns.shape[0], M_su.shape[0]
        # each unit's optical axis (its z column) in ENU for every sample: one (3n x 3) @
        # (3 x m) matrix product (a batched einsum over (n, m) is several times slower)
        view = (R_ns.reshape(3 * n, 3) @ M_su[:, :, 2].T).reshape(n, 3, m).transpose(0, 2, 1)
        el, az = elevation_azimuth(view)
        below = el < 0.0
        if below.any():
            s, u = np.argwhere(below)[0]
            raise UnitBelowHorizonError(
                f"unit {u} looks {el[s, u]:.2f} deg below the horizon at sample {s} "
                f"({int(below.sum())} unit-samples in all); limit pitch/roll or tilt the unit up")
        sun_el, sun_az = elevation_azimuth(np.asarray(sun_enu, float).reshape(-1, 3))
        fld = sky.field(np.minimum(el, 90.0), az, sun_el[:, None], sun_az[:, None])
        e_n = fld.e_vector
        # e-vector in each unit's frame, x and y components: ENU -> sensor (one batched
        # (m, 3) @ (3, 3) product per sample), then onto the unit's x and y axes
        e_sens = np.matmul(e_n, R_ns)                                      # (n, m, 3)
        ux, uy = M_su[:, :, 0], M_su[:, :, 1]                              # (m, 3) each
        e_ux = e_sens[..., 0] * ux[:, 0] + e_sens[..., 1] * ux[:, 1] + e_sens[..., 2] * ux[:, 2]
        e_uy = e_sens[..., 0] * uy[:, 0] + e_sens[..., 1] * uy[:, 1] + e_sens[..., 2] * uy[:, 2]
        chi = np.degrees(np.arctan2(e_uy, e_ux))
        # back to the sensor frame through the unit's x and y axes (the e-vector in the
        # unit's image plane has no z component)
        e_s = ux * e_ux[..., None] + uy * e_uy[..., None]
        e_s /= np.linalg.norm(e_s, axis=-1, keepdims=True)
        return SkySample(fld.I, fld.dop, wrap_axial_deg(chi), e_s, el, az)

    def photodiode_readings(self, obs: SkySample, rng: np.random.Generator):
        """Readings [counts] of all photodiodes (n, P) and their column names (P,).

        Malus's law ``c I (1 + d cos 2(chi - a))`` plus Gaussian noise, rounded and clipped to
        ``[0, saturation_value]``.
        """
        pd_unit = np.array([i for i, u in enumerate(self.units) for _ in u.photodiodes_deg])
        pd_angle = np.array([a for u in self.units for a in u.photodiodes_deg], dtype=float)
        names = [photodiode_column(i, a) for i, a in zip(pd_unit, pd_angle)]
        pm = self.photodiode
        chi = np.radians(obs.aop_unit_deg[:, pd_unit] - pd_angle)
        mean = pm.counts_per_radiance * obs.radiance[:, pd_unit] * (
            1.0 + obs.dop[:, pd_unit] * np.cos(2.0 * chi))
        noisy = mean + pm.noise_counts * rng.standard_normal(mean.shape)
        return np.clip(np.round(noisy), 0.0, pm.saturation_value), names

    def describe(self) -> dict:
        """Sidecar ``units`` and sensor description (nominal geometry only)."""
        return {"type": "compound eye", "n_units": self.n_units,
                "units": [u.describe() for u in self.units]}

    def sample(self, sky: Sky, site: Site, times, yaw_deg, pitch_deg, roll_deg,
               rng: np.random.Generator, *, attitude_noise_deg: float = 0.0,
               accel_noise_mps2: float = 0.0, yaw_reference: str = "north",
               yaw_offset_deg: float = 0.0, include_truth: bool = True, seed=None,
               sweep=None, source: str = "sun") -> PhotodiodeData:
        """Simulate raw photodiode data (schema "skysim.photodiodes/2").

        Parameters
        ----------
        sky : Sky
        site : Site
        times : timezone-aware times, length n
        yaw_deg, pitch_deg, roll_deg : arrays (n,)
            True carrier attitude [deg].
        rng : numpy.random.Generator
        attitude_noise_deg : float
            1-sigma noise of the recorded reference attitude (navigation module) [deg], added
            independently to yaw, pitch and roll (the patent's reference is 0.1 deg).
        accel_noise_mps2 : float
            1-sigma noise per axis of the recorded accelerometer specific force [m/s^2]
            (static carrier: the specific force is ``g`` along body up).
        yaw_reference : {"north", "relative"}
            With "relative", the recorded yaw is ``yaw - yaw_offset_deg`` (an instrument on a
            platform that only knows its rotation since start).
        include_truth : bool
            Add ``true_yaw_deg``, ``true_pitch_deg``, ``true_roll_deg`` (metadata columns).
        seed : optional
            Recorded in the sidecar.
        source : {"sun", "moon"}
            The body that lights ``sky`` (the position handed to its field): the Moon for a
            moonlit sky (:class:`skysim.night.MoonlitSky`).
        """
        if yaw_reference not in ("north", "relative"):
            raise InvalidParameterError(
                f"yaw_reference must be 'north' or 'relative'; got {yaw_reference!r}")
        if source == "sun":
            sun, idx = sun_vector(times, site)
        elif source == "moon":
            from skysim.moon import moon_vector
            sun, idx = moon_vector(times, site)
        else:
            raise InvalidParameterError(f"source must be 'sun' or 'moon'; got {source!r}")
        n = len(idx)
        yaw, pitch, roll = (np.broadcast_to(check_finite(k, v), (n,)).astype(float) for k, v in (
            ("yaw_deg", yaw_deg), ("pitch_deg", pitch_deg), ("roll_deg", roll_deg)))
        att = body_attitude(yaw, pitch, roll)
        counts, names = self.photodiode_readings(self.observe(sky, att, sun), rng)
        noise = attitude_noise_deg * rng.standard_normal((3, n))
        rec_yaw = np.mod(yaw + noise[0] - (yaw_offset_deg if yaw_reference == "relative" else 0.0),
                         360.0)
        up_body = att.inv().apply(np.array([0.0, 0.0, 1.0]))
        accel = (GRAVITY_MPS2 * up_body.reshape(n, 3)
                 + accel_noise_mps2 * rng.standard_normal((n, 3)))
        tz = getattr(times, "tz", None)
        cols = {"time": idx.tz_convert(tz) if tz is not None else idx, "yaw_deg": rec_yaw,
                "pitch_deg": pitch + noise[1], "roll_deg": roll + noise[2]}
        cols.update({c: accel[:, k] for k, c in enumerate(ACCEL_COLUMNS)})
        cols.update({name: counts[:, j] for j, name in enumerate(names)})
        table = pd.DataFrame(cols)
        if sweep is not None:
            table["sweep"] = np.broadcast_to(np.asarray(sweep), (n,))
        if include_truth:
            table["true_yaw_deg"] = yaw
            table["true_pitch_deg"], table["true_roll_deg"] = pitch, roll
        pm = self.photodiode
        sidecar = {
            "schema": PHOTODIODES_SCHEMA, "site": site.to_dict(), "yaw_reference": yaw_reference,
            "yaw_sense": "clockwise", "units": [u.describe() for u in self.units],
            "readings": "raw", "reading_unit": "counts", "adc_full_scale": pm.saturation_value,
            "saturation_value": pm.saturation_value,
            "frames": "body x right, y forward (heading axis), z up; unit azimuth clockwise "
                      "from forward",
            "generator": {
                "package": "skysim", "version": __version__, "sky": sky.describe(),
                "source": source, "sensor": "sensor.compound_eye.CompoundEyeSensor",
                "installation_error_deg": [float(x) for x in self.installation_error_deg],
                "unit_installation_error_deg": [[float(x) for x in u.installation_error_deg]
                                                for u in self.units],
                "photodiode": {"counts_per_radiance": pm.counts_per_radiance,
                               "noise_counts": pm.noise_counts, "bits": pm.bits},
                "attitude_noise_deg": attitude_noise_deg, "accel_noise_mps2": accel_noise_mps2,
                "yaw_offset_deg": yaw_offset_deg if yaw_reference == "relative" else 0.0,
                "seed": seed}}
        return PhotodiodeData(table, sidecar)

    @classmethod
    def from_sidecar(cls, sidecar: dict, photodiode: PhotodiodeModel | None = None):
        """Nominal sensor (no installation errors) from a photodiode sidecar's ``units``."""
        units = tuple(Unit(float(u["azimuth_deg"]), float(u["elevation_deg"]),
                           tuple(float(a) for a in u["photodiodes"])) for u in sidecar["units"])
        return cls(units, photodiode=photodiode or PhotodiodeModel())

    def nominal(self) -> "CompoundEyeSensor":
        """The same sensor without installation errors (what an uncompensated user assumes)."""
        return replace(self, installation_error_deg=(0.0, 0.0, 0.0),
                       units=tuple(replace(u, installation_error_deg=(0.0, 0.0, 0.0))
                                   for u in self.units))

    def with_installation(self, body_deg, units_deg) -> "CompoundEyeSensor":
        """The same sensor with given ``phi_1`` (3,) and per-unit errors (m, 3) [deg]."""
        units_deg = np.asarray(units_deg, float).reshape(self.n_units, 3)
        return replace(self, installation_error_deg=tuple(np.asarray(body_deg, float)),
                       units=tuple(replace(u, installation_error_deg=tuple(e))
                                   for u, e in zip(self.units, units_deg)))


def patent_configuration(tilt_elevation_deg: float = 60.0, photodiodes=THREE_PAIR_ANGLES_DEG,
                         photodiode: PhotodiodeModel | None = None) -> CompoundEyeSensor:
    """The patent's layout [1]_: unit 0 at the zenith, units 1..8 (the patent's i = 2..9)
    tilted to ``tilt_elevation_deg`` at azimuths 0, 45, ..., 315 deg."""
    units = [Unit(0.0, 90.0, tuple(photodiodes))] + [
        Unit(45.0 * k, tilt_elevation_deg, tuple(photodiodes)) for k in range(8)]
    return CompoundEyeSensor(tuple(units), photodiode=photodiode or PhotodiodeModel())


def ring_configuration(n_units: int = 8, elevation_deg: float = 45.0,
                       photodiodes=FOUR_ANGLES_DEG,
                       photodiode: PhotodiodeModel | None = None) -> CompoundEyeSensor:
    """A ring of ``n_units`` units at ``elevation_deg``, evenly in azimuth, with four
    photodiodes each (0/45/90/135 deg): a common real instrument, usually with relative yaw."""
    if isinstance(n_units, bool) or not isinstance(n_units, numbers.Integral) or n_units < 1:
        raise InvalidParameterError(f"n_units must be a whole number >= 1; got {n_units!r}")
    units = [Unit(360.0 * k / n_units, elevation_deg, tuple(photodiodes)) for k in range(n_units)]
    return CompoundEyeSensor(tuple(units), photodiode=photodiode or PhotodiodeModel())


def with_random_installation_errors(sensor: CompoundEyeSensor, max_deg: float,
                                    rng: np.random.Generator,
                                    zenith_unit: int | None = 0) -> CompoundEyeSensor:
    """Draw ``phi_1`` and every ``phi_i`` uniformly in ``[-max_deg, max_deg]`` per axis [deg].

    The ``zenith_unit`` (which defines the sensor frame) keeps a zero error; pass None to
    perturb all units.
    """
    body = rng.uniform(-max_deg, max_deg, 3)
    units = rng.uniform(-max_deg, max_deg, (sensor.n_units, 3))
    if zenith_unit is not None:
        units[zenith_unit] = 0.0
    return sensor.with_installation(body, units)
