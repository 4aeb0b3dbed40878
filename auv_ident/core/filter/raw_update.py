"""The compiled steps of the raw-sensor filter (raw.py): the measurement update of one message's
m channels (m <= 6) fused jointly, Joseph form; the time update over several RK4 steps; the
IMU's attitude and rate update whole (with a 100 Hz IMU these run for most messages, and the
numpy version cost about ten times the arithmetic in call overhead).

Kept apart from raw.py so that the numba cache's group of compiled sources
(core/__init__.py COMPILED_SOURCES) holds only this file and what it imports.
"""
import math

import numpy as np

from auv_ident.core.compiled_cache import cached_njit
from auv_ident.core.filter import ekf
from auv_ident.core.filter.timing import time_step
from auv_ident.core.model.raw_sensors import rotation, rotation_of_quaternion
from auv_ident.core.model.state import COEFFICIENTS, N_STATE, State
from auv_ident.core.model.thruster_lag import lag_advance

OK = 0
ERR_NOT_PD = 1
_PHI = int(State.PHI)
_P = int(State.P)
_PSI = int(State.PSI)
_COEF = int(COEFFICIENTS.start)


@cached_njit()
def joseph_update(xf, P, nu, H, Rm, P_out, w, gain):  # noqa: C901
    """x_f += K nu and P_out = (I - K H) P (I - K H)^T + K Rm K^T with K = P H^T S^-1,
    S = H P H^T + Rm; xf (n,) in place, P (n, n), nu (m,), H (m, n), Rm (m, m). w (m,) gets the
    innovation whitened by the Cholesky factor of S, gain (n,) 1/P_out_ii - 1/P_ii (the
    information the update gave each state). Returns (status, NIS)."""
    n = xf.shape[0]
    m = nu.shape[0]
    PHt = np.dot(P, H.T)
    S = np.dot(H, PHt) + Rm
    L = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            s = 0.5 * (S[i, j] + S[j, i])
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if not (s > 0.0) or not math.isfinite(s):
                    return ERR_NOT_PD, np.nan
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    # K^T = S^-1 H P: forward and back substitution per column
    Kt = np.empty((m, n))
    z = np.empty(m)
    for col in range(n):
        for i in range(m):
            s = PHt[col, i]
            for k in range(i):
                s -= L[i, k] * z[k]
            z[i] = s / L[i, i]
        for i in range(m - 1, -1, -1):
            s = z[i]
            for k in range(i + 1, m):
                s -= L[k, i] * Kt[k, col]
            Kt[i, col] = s / L[i, i]
    nis = 0.0
    for i in range(m):
        s = nu[i]
        for k in range(i):
            s -= L[i, k] * w[k]
        w[i] = s / L[i, i]
        nis += w[i] * w[i]
    for i in range(n):
        s = 0.0
        for a in range(m):
            s += Kt[a, i] * nu[a]
        xf[i] += s
    A = -np.dot(Kt.T, H)
    for i in range(n):
        A[i, i] += 1.0
    KR = np.dot(Kt.T, Rm)
    Pn = np.dot(np.dot(A, P), A.T) + np.dot(KR, Kt)
    for i in range(n):
        for j in range(i + 1):
            v = 0.5 * (Pn[i, j] + Pn[j, i])
            P_out[i, j] = v
            P_out[j, i] = v
        if not (P_out[i, i] > 0.0) or not math.isfinite(xf[i]):
            return ERR_NOT_PD, nis
        gain[i] = 1.0 / P_out[i, i] - 1.0 / P[i, i]
    return OK, nis


@cached_njit()
def propagate_steps(xf, P, ui, cm, h, steps, Q, xb, F12, M, O, P_out, ws):
    """`steps` RK4 time updates of h s with the inputs ui held, in place: the model's part of
    xf (its first ws.Fa.shape[0] entries: vehicle states and parameters) through
    ekf.rk4_step_into, P through ekf.propagate_covariance with F12 (12, n) the vehicle rows of
    the whole state's transition (the sensor errors' columns stay 0: they do not enter the
    dynamics) and Q (n, n) per step. Returns the model's status code (ekf.OK = 0)."""
    nb = ws.Fa.shape[0]
    n = xf.shape[0]
    for _ in range(steps):
        st = ekf.rk4_step_into(xf[:nb], ui, cm, h, True, xb, ws.Fa, ws)
        if st != ekf.OK:
            return st
        if cm.lagged:       # the delivered thrust at the end of the step (thruster_lag.py)
            lag_advance(cm, ws.c, ui, ws.lag, ws.lag_ok, h)
        for i in range(N_STATE):
            for j in range(nb):
                F12[i, j] = ws.Fa[i, j]
        ekf.propagate_covariance(F12, P, Q, P_out, M, O)
        for i in range(nb):
            xf[i] = xb[i]
        for i in range(n):
            for j in range(n):
                P[i, j] = P_out[i, j]
    return ekf.OK


@cached_njit()
def imu_update(xf, P, q, rates, Rs, Rm, bias_idx, P_out, w, gain):
    """The IMU's attitude and rates in one update (raw_sensors.attitude_innovation and gyro,
    compiled): q (4,) the sensor's orientation (x y z w), rates (3,) rad/s in the sensor frame,
    Rs (3, 3) sensor -> body, Rm (6, 6) the noise (attitude rad^2 then rates), bias_idx (3,)
    the gyro bias states' indices in xf (-1: not estimated). For rotations of the measured
    against the predicted attitude below pi/2 (an IMU message is never that far off a running
    filter; the Python path handles any). Returns joseph_update's (status, NIS)."""
    n = xf.shape[0]
    R_meas = np.dot(rotation_of_quaternion(q), Rs.T)
    phi, theta, psi = xf[_PHI], xf[_PHI + 1], xf[_PHI + 2]
    D = np.dot(R_meas, rotation(phi, theta, psi).T)
    c = max(-1.0, min(1.0, 0.5 * (D[0, 0] + D[1, 1] + D[2, 2] - 1.0)))
    angle = math.acos(c)
    f = 0.5 if angle < 1e-8 else angle / (2.0 * math.sin(angle))
    nu = np.empty(6)
    nu[0] = f * (D[2, 1] - D[1, 2])
    nu[1] = f * (D[0, 2] - D[2, 0])
    nu[2] = f * (D[1, 0] - D[0, 1])
    H = np.zeros((6, n))
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    H[0, _PHI] = cp * ct
    H[0, _PHI + 1] = -sp
    H[1, _PHI] = sp * ct
    H[1, _PHI + 1] = cp
    H[2, _PHI] = -st
    H[2, _PHI + 2] = 1.0
    for i in range(3):
        s = 0.0
        for j in range(3):
            b = xf[bias_idx[j]] if bias_idx[j] >= 0 else 0.0
            s += Rs[j, i] * (xf[_P + j] + b)
            H[3 + i, _P + j] = Rs[j, i]
            if bias_idx[j] >= 0:
                H[3 + i, bias_idx[j]] = Rs[j, i]
        nu[3 + i] = rates[i] - s
    return joseph_update(xf, P, nu, H, Rm, P_out, w, gain)


@cached_njit()
def imu_run(xf, P, ui, cm, t0, ts, qs, rates, Rs, Rm, bias_idx, q_rate, max_step, max_bridge,
            xb, F12, M, O, P_out, ws, W, gain, info, nis_sum):
    """A run of IMU messages (stamps ts (K,) s, orientations qs (K, 4), rates (K, 3)) of one
    mounting and noise, each the time update to its stamp with the command ui held
    (propagate_steps, the per-step Q diag(q_rate h)) and then imu_update, in place, as
    RawSensorFilter.process would do them one by one in Python: the arithmetic is the same,
    the per-message interpreter overhead (some 20 us of a 100 Hz IMU's 30 us) is not. The
    heading is wrapped, W[k] gets the whitened innovation, info (p,) and nis_sum (1,) the
    information and NIS summed on. It stops at the first message it leaves to Python: one
    stamped before the estimate's, a non-finite value, or a gap to bridge (> max_bridge).
    Returns (messages done, status: ekf.OK, the model's status of a failed time update, or
    -1 for a failed measurement update, the estimate's stamp after them)."""
    n = xf.shape[0]
    t = t0
    K = ts.shape[0]
    w = np.empty(6)
    Q = np.zeros((n, n))
    p = info.shape[0]
    c = _COEF
    for k in range(K):
        if ts[k] < t:
            return k, OK, t
        finite = True
        for j in range(4):
            finite = finite and math.isfinite(qs[k, j])
        for j in range(3):
            finite = finite and math.isfinite(rates[k, j])
        if not finite:
            return k, OK, t
        dt = np.rint((ts[k] - t) * 1e9) / 1e9
        if dt > 0.0:
            steps, h = time_step(dt, max_step, max_bridge)
            if steps == 0:
                return k, OK, t
            t = ts[k]
            for i in range(n):
                Q[i, i] = q_rate[i] * h
            st = propagate_steps(xf, P, ui, cm, h, steps, Q, xb, F12, M, O, P_out, ws)
            if st != ekf.OK:
                return k, st, t
        st, nis = imu_update(xf, P, qs[k], rates[k], Rs, Rm, bias_idx, P_out, w, gain)
        if st != OK:
            return k, -1, t
        xf[_PSI] = ekf.wrap(xf[_PSI])
        for i in range(n):
            for j in range(n):
                P[i, j] = P_out[i, j]
        for i in range(p):
            info[i] += gain[c + i]
        for j in range(6):
            W[k, j] = w[j]
        nis_sum[0] += nis
    return K, OK, t


@cached_njit()
def coefficient_block(xf, P, c, p):
    """The coefficients' estimate (p,), 1-sigma (p,) and covariance (p, p) at c.. of xf and P,
    as new arrays, and whether every value of the estimate and its covariance is finite: what a
    live update publishes, in one call (numpy's copies, checks and square roots cost ~15 us a
    message at 400 Hz). The 1-sigma of a negative variance is 0."""
    est = xf[c:c + p].copy()
    cov = P[c:c + p, c:c + p].copy()
    std = np.empty(p)
    finite = True
    for i in range(p):
        finite = finite and math.isfinite(est[i])
        for j in range(p):
            finite = finite and math.isfinite(cov[i, j])
        std[i] = math.sqrt(max(cov[i, i], 0.0))
    return est, std, cov, finite
