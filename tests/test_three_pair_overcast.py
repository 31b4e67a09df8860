"""The three-pair sensor's cloud candidate ``overcast`` (:mod:`calibration.effects.overcast`):
a uniform cloud layer over the zenith sensor, its optical thickness fitted."""

import numpy as np
import pytest

from calibration import effects as E
from calibration.diagnosis import diagnose
from calibration.effects.overcast import zenith_signed_dop
from experiments.workflows.diagnose import simulate_session


def test_zero_thickness_is_the_base_zenith_sky():
    el = np.linspace(-5.0, 89.0, 40)
    np.testing.assert_array_equal(zenith_signed_dop(0.0, el),
                                  E.zenith_rayleigh(0.0, el, 0.0)[1])


def test_cloud_light_lowers_the_zenith_dop_and_turns_it_under_a_high_sun():
    """The droplets' own light is bright and weakly polarized: the zenith DoP falls with the
    thickness at every sun (a low sun keeps the clear-sky E-vector, perpendicular to the
    meridian); under a high sun the droplets' single scattering near 150 deg, polarized
    parallel to the scattering plane (the droplets' phase matrix, checked against miepython
    in ``tests/test_partly_cloudy.py``), outweighs the clear sky's and the E-vector turns by
    90 deg (the sign flips), as the radiative transfer of a thin overcast shows in the
    cloudy-compass reproduction (``docs/clouds.md``)."""
    low, high = 10.0, 60.0
    d = np.array([zenith_signed_dop(t, [low, high]) for t in (0.0, 0.3, 1.0, 3.0)])
    assert np.all(np.diff(d[:, 0]) < 0) and np.all(d[:, 0] > 0)
    assert d[0, 1] > 0 and np.all(d[2:, 1] < 0)
    assert np.all(np.abs(d[1:]) < np.abs(d[0]))


@pytest.mark.parametrize("tau", [0.6, 2.0])
def test_overcast_named_and_thickness_recovered(tau):
    """Blind (generator and fitter share only the effect library's forward model, as every
    three-pair effect): named against the other sky candidate and the sensor's geometric
    ones, the thickness within 4 standard errors."""
    ds = simulate_session("overcast", np.random.default_rng(31), params=[tau])
    doc = diagnose(ds["data"], ("overcast", "multiple_scattering", "tilt", "sun_motion"))
    v = doc.verdict
    assert v.effect == "overcast", v
    p = v.params["cloud_tau"]
    assert abs(p["value"] - tau) <= 4 * p["se"] + 1e-3, p
