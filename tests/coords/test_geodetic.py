"""WGS-84 / ECEF / ENU against pymap3d (passing copies) and spec spot values (C3.1, C3.2)."""

import numpy as np
import pymap3d as pm
import pytest
from hypothesis import given
from hypothesis import strategies as st

from adaptrack.coords import (
    ecef_to_enu,
    ecef_to_geodetic,
    enu_to_ecef,
    enu_to_ecef_rotation,
    geodetic_to_ecef,
    rotate_cov,
)
from adaptrack.coords.geodetic import WGS84_A, WGS84_B


def test_c3_1_spot_values():
    np.testing.assert_allclose(geodetic_to_ecef(0.0, 0.0, 0.0), [WGS84_A, 0, 0], atol=1e-9)
    np.testing.assert_allclose(geodetic_to_ecef(np.pi / 2, 0.0, 0.0), [0, 0, WGS84_B], atol=1e-9)
    assert WGS84_B == pytest.approx(6356752.314245, abs=1e-6)


def test_c3_2_rotation_columns_are_east_north_up():
    for lat, lon in ((0.3, -1.2), (-1.1, 2.5), (np.pi / 2 - 1e-9, 0.4)):
        r = enu_to_ecef_rotation(lat, lon)
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-15)
        assert np.linalg.det(r) == pytest.approx(1.0)
        up = geodetic_to_ecef(lat, lon, 1.0) - geodetic_to_ecef(lat, lon, 0.0)
        np.testing.assert_allclose(r[:, 2], up, atol=1e-9)


@pytest.mark.crosscheck
def test_against_pymap3d():
    rng = np.random.default_rng(3)
    lat = rng.uniform(-1.5, 1.5, 200)
    lon = rng.uniform(-3.1, 3.1, 200)
    h = rng.uniform(-500, 2e5, 200)
    mine = geodetic_to_ecef(lat, lon, h)
    ref = np.stack(pm.geodetic2ecef(lat.copy(), lon.copy(), h.copy(), deg=False), -1)
    np.testing.assert_allclose(mine, ref, rtol=0, atol=1e-6)
    la, lo, hh = ecef_to_geodetic(mine)
    rla, rlo, rh = pm.ecef2geodetic(*mine.T.copy(), deg=False)
    np.testing.assert_allclose(la, rla, atol=1e-11)
    np.testing.assert_allclose(lo, rlo, atol=1e-11)
    np.testing.assert_allclose(hh, rh, atol=1e-5)
    site = (0.8, 0.1, 120.0)
    enu = rng.normal(size=(50, 3)) * 5e4
    ecef = enu_to_ecef(enu, *site)
    ref = np.stack(pm.enu2ecef(*enu.T.copy(), *site, deg=False), -1)
    np.testing.assert_allclose(ecef, ref, rtol=0, atol=1e-6)
    np.testing.assert_allclose(ecef_to_enu(ecef, *site), enu, rtol=0, atol=1e-6)


@given(st.floats(-1.55, 1.55), st.floats(-3.14, 3.14), st.floats(-1e4, 1e7))
def test_geodetic_round_trip(lat, lon, h):
    la, lo, hh = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h))
    assert abs(la - lat) < 1e-11 and abs(hh - h) < 1e-5
    assert abs(np.angle(np.exp(1j * (lo - lon)))) < 1e-11


def test_covariance_rotation_and_degree_error():
    r = enu_to_ecef_rotation(0.7, 0.2)
    c = np.diag([1.0, 4.0, 9.0])
    rc = rotate_cov(c, r)
    np.testing.assert_allclose(np.linalg.eigvalsh(rc), [1, 4, 9])
    with pytest.raises(ValueError, match="degrees passed where radians are expected"):
        geodetic_to_ecef(48.0, 2.0, 0.0)
