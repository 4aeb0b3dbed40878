"""The raw sensors' measurement models (core/model/raw_sensors.py): analytic Jacobians against
central finite differences, and the attitude innovation's sign and frame."""
import math

import numpy as np
import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.model import raw_sensors as rs
from auv_ident.core.model.state import N_STATE

THETA = ['Z_w', 'M_q', 'current_n', 'current_e']


def _layout():
    return rs.Layout.of(THETA, list(rs.ERROR_NAMES))


def _state(rng, lay):
    xf = rng.normal(size=lay.n) * 0.3
    xf[0] = 1.5
    xf[9:12] = (0.2, -0.3, 2.5)
    for name, i in lay.errors.items():
        xf[i] = {'dvl_misalignment': 0.03, 'dvl_scale': 0.01}.get(name, 0.002)
    return xf


def _mount(rng):
    R, _ = rs.rotation_and_derivatives(0.1, -0.05, 0.7)
    return rs.Mounting(lever_arm=np.array([0.4, -0.1, 0.2]), rotation=R)


def _numeric(fun, xf, eps=1e-6):
    cols = []
    for i in range(xf.shape[0]):
        a, b = xf.copy(), xf.copy()
        a[i] += eps
        b[i] -= eps
        cols.append((fun(a) - fun(b)) / (2 * eps))
    return np.array(cols).T


def _models(lay, mount):
    cur = np.array([0.1, -0.2, 0.01])
    return {
        'gyro': lambda x: rs.gyro(x, mount, lay),
        'dvl_ground_ground': lambda x: rs.dvl(x, mount, lay, 'ground', 'ground', cur),
        'dvl_water_ground': lambda x: rs.dvl(x, mount, lay, 'water', 'ground', cur),
        'dvl_ground_water': lambda x: rs.dvl(x, mount, lay, 'ground', 'water', cur),
        'depth': lambda x: rs.depth(x, mount, lay),
        'pressure': lambda x: rs.pressure(x, mount, lay, 1025.0, 9.81, 101325.0),
        'position2': lambda x: rs.position(x, mount, lay, 2),
        'position3': lambda x: rs.position(x, mount, lay, 3),
    }


@pytest.mark.parametrize('name', list(_models(_layout(), rs.Mounting())))
def test_jacobians_match_finite_differences(name):
    rng = np.random.default_rng(3)
    lay = _layout()
    xf = _state(rng, lay)
    fun = _models(lay, _mount(rng))[name]
    h, H = fun(xf)
    num = _numeric(lambda x: fun(x)[0], xf)
    scale = max(1.0, np.abs(num).max())
    np.testing.assert_allclose(H, num, atol=1e-6 * scale, rtol=1e-6)
    # every model sees only some states: the test must cover non-zero columns
    assert np.count_nonzero(H) > 0


def test_attitude_innovation_is_first_order_in_the_euler_error():
    rng = np.random.default_rng(4)
    lay = _layout()
    xf = _state(rng, lay)
    mount = _mount(rng)
    de = np.array([1e-4, -2e-4, 3e-4])
    truth = xf.copy()
    truth[9:12] += de
    R_true, _ = rs.rotation_and_derivatives(*truth[9:12])
    # the quaternion the sensor reports: of R_true R_s (sensor -> NED)
    Rq = R_true @ mount.rotation
    w = math.sqrt(max(0.0, 1 + np.trace(Rq))) / 2
    q = np.array([(Rq[2, 1] - Rq[1, 2]) / (4 * w), (Rq[0, 2] - Rq[2, 0]) / (4 * w),
                  (Rq[1, 0] - Rq[0, 1]) / (4 * w), w])
    nu, H = rs.attitude_innovation(xf, q, mount, lay.n)
    np.testing.assert_allclose(nu, H @ (truth - xf), atol=1e-7)
    np.testing.assert_allclose(rs.euler_of_rotation(R_true), truth[9:12], atol=1e-12)


def test_dvl_misalignment_turns_forward_speed_into_sway():
    lay = rs.Layout.of([], ['dvl_misalignment'])
    xf = np.zeros(lay.n)
    xf[0] = 2.0
    xf[lay.errors['dvl_misalignment']] = math.radians(2.0)
    h, _ = rs.dvl(xf, rs.Mounting(), lay, 'ground', 'ground', np.zeros(3))
    # the DVL's x axis turned 2 deg to starboard sees the forward motion 2 deg to port
    np.testing.assert_allclose(h, [2 * math.cos(math.radians(2)), -2 * math.sin(math.radians(2)),
                                   0.0], atol=1e-12)


def test_rotation_log_near_pi():
    for angle in (math.pi - 1e-9, math.pi - 1e-3, 1.0, 1e-10):
        axis = np.array([0.3, -0.4, 0.866])
        axis /= np.linalg.norm(axis)
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        R = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
        v = rs.rotation_log(R)
        assert np.linalg.norm(v) == pytest.approx(angle, abs=1e-6)
        assert abs(abs(v @ axis) - angle) < 1e-5


def test_mounting_rejects_a_non_rotation():
    with pytest.raises(ConfigError, match='rotation'):
        rs.Mounting(rotation=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ConfigError, match='lever_arm'):
        rs.Mounting(lever_arm=np.array([0.0, np.nan, 0.0]))


def test_layout_places_current_and_errors_after_the_parameters():
    lay = rs.Layout.of(['Z_w', 'current_e'], ['gyro_bias_r', 'depth_offset'])
    assert lay.current == (-1, N_STATE + 1, -1)
    assert lay.errors == {'gyro_bias_r': N_STATE + 2, 'depth_offset': N_STATE + 3}
    assert lay.n == N_STATE + 4
