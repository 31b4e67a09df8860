"""The ring's forward model against its formulas written out: Malus's modulation of every
reading and the DoP-free prediction's least squares per unit and sample."""

import numpy as np
import pytest

from calibration.photodiode_diagnosis import instrument_from_photodiodes
from calibration.photodiode_diagnosis.forward import Forward
from sensor.photodiode import malus_signal
from tests.ring_sessions import ring_session


@pytest.fixture(scope="module")
def model():
    """A simulated two-sweep ring, its forward model and a parameter vector off every
    nominal value (gains, offsets, polarizer angles, pointing, headings)."""
    inst = instrument_from_photodiodes(ring_session(n_sweeps=2, per_sweep=40, seed=4))
    fwd = Forward(inst)
    L = fwd.layout
    rng = np.random.default_rng(5)
    th = np.zeros(L.size)
    th[L.lam] = rng.normal(0.0, 0.1, L.n_pd)
    th[L.off] = rng.normal(0.0, 0.01, L.n_pd)
    th[L.angle] = rng.normal(0.0, 3.0, L.n_pd)
    th[L.delta] = rng.normal(0.0, 10.0, L.n_units)
    th[L.scale] = 0.55
    th[L.pointing] = rng.normal(0.0, 1.0, 2 * L.n_units)
    th[L.heading] = rng.uniform(0.0, 360.0, L.n_heading)
    return fwd, th


def test_modulation_is_malus_law(model):
    """``1 + d cos 2(chi - a)`` (and ``cos 2(chi - a)`` alone) at every reading, against
    :func:`sensor.photodiode.malus_signal` with unit intensity: the double-angle identity
    the model evaluates agrees to 4e-15, the reference's own rounding of its argument (the
    angle difference ``2(chi - a)`` of a few hundred degrees carries 6e-14 deg, 1e-15 rad;
    measured 1.1e-15)."""
    fwd, th = model
    L, u = fwd.layout, fwd.inst.pd_unit
    obs = fwd.observe(th)
    angle = fwd.pd_angle_deg + th[L.angle] + th[L.delta][u]
    d = np.clip(0.55 * obs.dop[:, u], 0.0, 0.999)
    np.testing.assert_allclose(fwd._modulation(obs, angle, 0.55),
                               malus_signal(1.0, obs.aop_unit_deg[:, u], d, angle),
                               rtol=0, atol=4e-15)
    np.testing.assert_allclose(fwd._modulation(obs, angle),
                               np.cos(np.radians(2.0 * (obs.aop_unit_deg[:, u] - angle))),
                               rtol=0, atol=4e-15)


def test_dop_free_prediction_is_each_units_least_squares(model):
    """The DoP-free prediction solves, at each sample and unit, the least squares of its
    usable readings minus their offsets on the basis ``(g_p, g_p cos 2(chi - a_p))``: the
    same solve by :func:`numpy.linalg.lstsq` on the written-out basis agrees to 1e-12 of
    the readings' scale (the 2 x 2 normal equations square the basis' condition number,
    which lstsq's orthogonal factorisation does not: a few digits where a unit's DoP is
    small; measured 8e-16)."""
    fwd, th = model
    L, u = fwd.layout, fwd.inst.pd_unit
    fwd.dop_free = True
    try:
        obs = fwd.observe(th)
        pred, _ = fwd.predict(th, obs)
    finally:
        fwd.dop_free = False
    g = np.exp(th[L.lam])
    chi = obs.aop_unit_deg[:, u]
    angle = fwd.pd_angle_deg + th[L.angle] + th[L.delta][u]
    basis = np.stack([np.broadcast_to(g, chi.shape),
                      g * np.cos(np.radians(2.0 * (chi - angle)))], axis=-1)  # (n, P, 2)
    y = fwd.y - th[L.off]
    worst = 0.0
    for i in range(0, fwd.y.shape[0], 7):
        for k in range(fwd.inst.n_units):
            cols = (u == k) & fwd.usable[i]
            if cols.sum() < 2:
                continue
            coef = np.linalg.lstsq(basis[i, cols], y[i, cols], rcond=None)[0]
            ref = basis[i, u == k] @ coef + th[L.off][u == k]
            worst = max(worst, np.max(np.abs(pred[i, u == k] - ref)))
    assert worst < 1e-12 * np.max(np.abs(fwd.y))
