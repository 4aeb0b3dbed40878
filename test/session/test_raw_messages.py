"""session/raw_messages.py: raw-sensor messages -> RawMeasurement in NED/FRD."""
from types import SimpleNamespace as NS

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from auv_ident.session.input_map import DVL, IMU, InputEntry, NAVSAT, POSE, PRESSURE
from auv_ident.session.messages import euler_to_quat
from auv_ident.session.raw_messages import navsat_origin, raw_record

_P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])   # NED -> ENU
_E = np.diag([1.0, -1.0, -1.0])                                      # FRD -> FLU


def _v(x):
    return NS(x=float(x[0]), y=float(x[1]), z=float(x[2]))


def _entry(typ, frame, **options):
    return InputEntry('s', '/s', typ, 'sensor', frame=frame, options=tuple(options.items()))


def _imu(q, w, frame_id=''):
    return NS(header=NS(frame_id=frame_id), orientation=NS(x=q[0], y=q[1], z=q[2], w=q[3]),
              angular_velocity=_v(w), orientation_covariance=[-1.0] + [0.0] * 8,
              angular_velocity_covariance=[0.0] * 9)


@pytest.mark.parametrize('frame,frame_id', [('enu', ''), ('auto', 'imu_link')])
def test_imu_enu_flu_is_read_as_ned_frd(frame, frame_id):
    phi, theta, psi = 0.2, -0.3, 2.5
    r_ned = Rotation.from_euler('ZYX', [psi, theta, phi]).as_matrix()
    q_enu = Rotation.from_matrix(_P @ r_ned @ _E).as_quat()     # (x, y, z, w)
    w_frd = np.array([0.01, -0.02, 0.03])
    rec = raw_record(_entry(IMU, frame), _imu(q_enu, _E @ w_frd, frame_id), 1.5)
    assert rec.kind == 'imu' and rec.t == 1.5 and rec.sensor == 's'
    q = rec.values[:4]
    q_ref = np.array(euler_to_quat(phi, theta, psi))
    assert min(np.abs(q - q_ref).max(), np.abs(q + q_ref).max()) < 1e-12
    np.testing.assert_allclose(rec.values[4:], w_frd, atol=1e-15)
    assert rec.covariance is None                 # -1: not provided -> the default noise


def test_ned_frame_id_and_covariance_pass_through():
    q = euler_to_quat(0.1, 0.2, 0.3)
    msg = _imu(q, [1.0, 2.0, 3.0], 'base_link_frd')
    msg.orientation_covariance = list(np.diag([1e-4, 2e-4, 3e-4]).ravel())
    msg.angular_velocity_covariance = list(np.diag([1e-6, 2e-6, 3e-6]).ravel())
    rec = raw_record(_entry(IMU, 'auto'), msg, 0.0)
    np.testing.assert_allclose(rec.values, list(q) + [1.0, 2.0, 3.0])
    np.testing.assert_allclose(np.diag(rec.covariance), [1e-4, 2e-4, 3e-4, 1e-6, 2e-6, 3e-6])


def test_dvl_pressure_pose():
    twist = NS(header=NS(frame_id='dvl'),
               twist=NS(twist=NS(linear=_v([1.0, 0.2, -0.1])), covariance=[0.0] * 36))
    rec = raw_record(_entry(DVL, 'enu'), twist, 2.0)
    np.testing.assert_allclose(rec.values, [1.0, -0.2, 0.1])
    assert rec.kind == 'dvl' and rec.covariance is None
    p = raw_record(_entry(PRESSURE, 'auto'),
                   NS(header=NS(frame_id=''), fluid_pressure=120000.0, variance=4.0), 3.0)
    assert p.kind == 'pressure' and p.values[0] == 120000.0 and p.covariance[0, 0] == 4.0
    cov = np.zeros(36)
    cov[0], cov[7], cov[14] = 1.0, 2.0, 3.0
    pose = NS(header=NS(frame_id='map'), pose=NS(pose=NS(position=_v([10.0, 20.0, -5.0])),
                                                 covariance=cov))
    pos = raw_record(_entry(POSE, 'enu', measures='position'), pose, 4.0)
    np.testing.assert_allclose(pos.values, [20.0, 10.0, 5.0])      # ENU -> NED
    np.testing.assert_allclose(np.diag(pos.covariance), [2.0, 1.0, 3.0])
    depth = raw_record(_entry(POSE, 'enu', measures='depth'), pose, 4.0)
    assert depth.kind == 'depth' and depth.values[0] == 5.0 and depth.covariance[0, 0] == 3.0


def _fix(lat, lon, status=0, cov_type=2, cov=(4.0, 0.0, 0.0, 0.0, 9.0, 0.0, 0.0, 0.0, 1.0)):
    return NS(header=NS(frame_id='gps'), status=NS(status=status), latitude=lat, longitude=lon,
              altitude=0.0, position_covariance=list(cov), position_covariance_type=cov_type)


def test_navsatfix_is_north_east_about_the_datum_on_the_flat_earth():
    e = _entry(NAVSAT, 'enu', datum=(36.6, -121.9))
    # 0.01 deg of latitude is 1109.8 m there, 0.01 deg of longitude 895.1 m (WGS-84 radii)
    rec = raw_record(e, _fix(36.61, -121.89), 2.0)
    assert rec.kind == 'position' and rec.t == 2.0 and rec.sensor == 's'
    np.testing.assert_allclose(rec.values, [1109.8, 895.1], atol=0.5)
    np.testing.assert_allclose(rec.covariance, [[9.0, 0.0], [0.0, 4.0]])   # ENU -> (N, E)
    assert raw_record(e, _fix(36.61, -121.89, cov_type=0), 2.0).covariance is None


def test_navsatfix_without_a_datum_is_measured_from_the_origin_given():
    e = _entry(NAVSAT, 'enu', datum=None)
    first = _fix(10.0, 20.0)
    assert navsat_origin(e, first) == (10.0, 20.0)
    np.testing.assert_allclose(raw_record(e, first, 0.0, (10.0, 20.0)).values, [0.0, 0.0])
    assert raw_record(e, _fix(10.0, 20.001), 1.0, (10.0, 20.0)).values[1] > 100.0


def test_navsatfix_without_a_fix_is_not_finite():
    e = _entry(NAVSAT, 'enu', datum=(0.0, 0.0))
    assert np.all(np.isnan(raw_record(e, _fix(1.0, 1.0, status=-1), 0.0).values))
    assert navsat_origin(_entry(NAVSAT, 'enu', datum=None), _fix(1.0, 1.0, status=-1)) is None
