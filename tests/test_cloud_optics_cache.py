"""The on-disk cache of water-cloud Mie optics (skysim.clouds.cloud_optics over
skysim.disk_cache): a later process reads back exactly what sasktran2's Lorenz-Mie
integration gave, without integrating; a damaged entry is recomputed and rewritten."""

import numpy as np
import pytest

pytest.importorskip("sasktran2")

import sasktran2.mie as sk_mie  # noqa: E402

from skysim import clouds  # noqa: E402
from skysim.clouds import CLOUD_CACHE_KIND, cloud_optics  # noqa: E402

ARGS = (550.0, 10.0, 0.1, 64)
"""A 10-um water cloud at 550 nm with 64 moments (the integration's cost is in its 1,024
quadrature radii and 1,801 angles, not the moment count: ~4 s either way)."""


@pytest.fixture
def cache_dir(empty_cache_dir):
    """An empty cache folder of this test; the in-process cache emptied before and after."""
    cloud_optics.cache_clear()
    yield empty_cache_dir
    cloud_optics.cache_clear()


def _same(a, b):
    assert a.single_scattering_albedo == b.single_scattering_albedo
    assert a.asymmetry_parameter == b.asymmetry_parameter
    for k in ("greek", "angle_deg", "p11", "p12"):
        x, y = getattr(a, k), getattr(b, k)
        assert x.dtype == y.dtype == np.float64 and np.array_equal(x, y)


def test_cloud_optics_read_back_bitwise_and_damage_recomputed(cache_dir, monkeypatch):
    first = cloud_optics(*ARGS)
    (path,) = sorted((cache_dir / CLOUD_CACHE_KIND).glob("*.npz"))
    # what is stored is what the integration gives, bit for bit
    _same(first, clouds.CloudOptics(*_fields(clouds._integrate_cloud(*ARGS))))
    # a new process: only the disk remains, and nothing is integrated
    cloud_optics.cache_clear()
    real = sk_mie.integrate_mie
    monkeypatch.setattr(sk_mie, "integrate_mie",
                        lambda *a, **k: (_ for _ in ()).throw(AssertionError("integrated")))
    _same(cloud_optics(*ARGS), first)
    # a damaged entry is recomputed and rewritten
    good = path.read_bytes()
    path.write_bytes(good[: len(good) // 2])
    cloud_optics.cache_clear()
    calls = []
    monkeypatch.setattr(sk_mie, "integrate_mie", lambda *a, **k: calls.append(1) or real(*a, **k))
    _same(cloud_optics(*ARGS), first)
    assert calls == [1] and path.read_bytes() == good
    # other parameters have their own entry
    cloud_optics(550.0, 12.0, 0.1, 64)
    assert len(list((cache_dir / CLOUD_CACHE_KIND).glob("*.npz"))) == 2


def _fields(d):
    g = d["greek"]
    return (g, min(float(d["single_scattering_albedo"]), 1.0), float(g[0, 1] / 3.0),
            d["angle_deg"], d["p11"], d["p12"])
