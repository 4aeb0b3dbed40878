"""Augmented-state EKF (Zare Ernani et al. 2015, Eqs. 5-15) with adaptive Q and R (Eqs. 16-20).

Augmented state x* = [u v w p q r x y z phi theta psi, theta_1 .. theta_p] (Eq. 22): the 12
vehicle states (m/s, rad/s, m, rad) and the chosen coefficients in the vehicle file's units.

Time update (Eqs. 9-10): x*_{k+1}^- = Phi(x*_k^+) with Phi one RK4 step of length T and the
inputs u_k held (zero-order hold); P^- = F P^+ F^T + Q with F = dPhi/dx* the EXACT Jacobian of
the RK4 map (chain rule through the four stages, using the model's analytic Jacobians).

Measurement update (Eqs. 11-13): y = H x* + v, H selects the measured channels (all 12 by
default, Eq. 23); a NaN in y marks a missing sample of that channel, which is skipped. Angle
innovations are wrapped to (-pi, pi]. The covariance update uses the Joseph form
P = (I-KH) P (I-KH)^T + K R K^T and is symmetrised, so P stays symmetric positive definite.

Noise adaptation (`mode`), gamma = 1 - exp(-T/tau) (Eq. 20, "t" read as the sample time T):

- MODE_FIXED: Q and R stay as given.
- MODE_PAPER (Eqs. 16-19 as published): omega_k = (theta_{k+1} - theta_k)/T (Eq. 18) adapts the
  PARAMETER block of Q, Q_th <- (1-gamma) Q_th + gamma lambda^2 omega omega^T (Eq. 16): omega is
  built from theta only, so it can only speak for the parameters' random walk eta_k of Eq. 7;
  v_k, the one-step prediction error y_k - h(x*_k^-) (Eq. 19, read as the innovation), adapts the
  measured block of R, R <- (1-gamma) R + gamma lambda^2 v v^T (Eq. 17). Read literally this
  drives R towards lambda^2 E[v v^T] (lambda = 2e-3: 4e-6 of the innovation power), far below
  the real sensor noise: the filter becomes over-confident (see the README's figures).
- MODE_PAPER_Q: Eq. 16 only (R fixed).
- MODE_MATCHING (ours): innovation-based covariance matching (Mehra 1972; Mohamed & Schwarz
  1999) on the diagonal of R, R_jj <- (1-gamma) R_jj + gamma (v_j^2 - (H P^- H^T)_jj), clipped to
  [R0_jj / r_bound, R0_jj * r_bound] so a burst can neither silence nor swamp a sensor; and the
  parameter block of Q annealed with the observed parameter motion,
  Q_th,ii <- (1-gamma) Q_th,ii + gamma (theta_{k+1} - theta_k)_i^2, clipped to
  [q_floor * Q0_th,ii, Q0_th,ii]: large while the estimates move, small once they settle.
"""
from collections import namedtuple
import math
from typing import Any

from numba import uint64
import numpy as np

from auv_ident.core.compiled_cache import cached_njit
from auv_ident.core.model.hydrodynamics import (
    CURRENT_GROUND,
    kernel,
    mass_inverse_into,
    OK,
    state_derivative,
    ZZ_LEN,
)
from auv_ident.core.model.state import N_CURRENT, N_INPUT, N_NU, N_STATE, State
from auv_ident.core.model.thruster_lag import (
    lag_advance,
    lag_correct,
    lag_inputs,
    lag_settle,
    N_LAG_ROWS,
)

MODE_FIXED, MODE_PAPER, MODE_PAPER_Q, MODE_MATCHING = 0, 1, 2, 3
MODES = {'fixed': MODE_FIXED, 'paper': MODE_PAPER, 'paper_q': MODE_PAPER_Q,
         'matching': MODE_MATCHING}
ERR_NOT_PD = 10
ERR_NAN_STATE = 11

# State indices as plain ints: numba freezes them into the same constants as the literals
_U, _V, _W, _P, _Q, _R, _X, _Y, _Z, _PHI, _THETA, _PSI = (int(s) for s in State)
# the columns of df/dx that can be nonzero in the rows of the body-velocity rates (f depends
# on neither the position nor psi; psi too with a current over ground, added apart), and in
# the rows of the position and Euler-angle rates
_DYNAMICS_COLUMNS = (_U, _V, _W, _P, _Q, _R, _PHI, _THETA)
_KINEMATICS_COLUMNS = (_U, _V, _W, _P, _Q, _R, _PHI, _THETA, _PSI)

# The noise settings of one filter run (run_filter): measured (12,) bool channels the sensor
# suite provides; Q0 (n, n), R0 (12, 12) the initial process and measurement noise; mode
# (MODE_*), gamma, lam, r_bound, q_floor of the adaptation (module docstring); T (s) the nominal
# sample time (of gamma and of omega = dtheta / T in MODE_PAPER).
FilterSettings = namedtuple('FilterSettings', 'measured Q0 R0 mode gamma lam T r_bound q_floor')

# How run_filter crosses the time from sample k-1 to sample k (timing.py has the rules):
# n_sub[k] RK4 steps of h[k] seconds with the inputs U[k-1] held, or, where n_sub[k] = 0 (k > 0),
# a restart of the vehicle states from x0[r], sd0[r] (the r-th restart; rows (R, 12), the
# states and their 1-sigma before the measurement at k); entry 0 is not used.
Timeline = namedtuple('Timeline', 'n_sub h x0 sd0')

# What run_filter writes (arrays filled in place): theta, std (H, p), nis (H, 2) and rq
# (H, 12 + p) the histories every hist_every samples (H = 0: none); white (N, 12) the whitened
# innovations if want_white; xa (n,), P, Q (n, n), R (12, 12) the final estimate, covariance and
# noise matrices; stats (5,) [status, steps done, sum NIS, sum dof, NIS samples].
FilterOutputs = namedtuple('FilterOutputs', 'hist_every theta std nis rq want_white white '
                                            'xa P Q R stats')


def new_outputs(n: int, N: int, hist_every: int = 0, want_white: bool = False) -> Any:
    """FilterOutputs for an augmented state of size n over N samples (histories every
    hist_every samples, 0: none; the whitened innovations if want_white)."""
    p = n - N_STATE
    nh = (N + hist_every - 1) // hist_every if hist_every > 0 else 0
    return FilterOutputs(hist_every, np.full((nh, p), np.nan), np.full((nh, p), np.nan),
                         np.full((nh, 2), np.nan), np.full((nh, N_STATE + p), np.nan),
                         bool(want_white), np.full((N if want_white else 0, N_STATE), np.nan),
                         np.empty(n), np.empty((n, n)), np.empty((n, n)),
                         np.empty((N_STATE, N_STATE)), np.zeros(5))


# Scratch arrays of one filter, allocated once and reused at every step (allocating them per
# step cost about a tenth of the step; a fresh n x n Fa per step made the BLAS products slower).
# lag (4, n_thr), lag_ok (1,): a lagged vehicle's delivered thrust at the start of the next
# step (core/model/thruster_lag.py), ui_ext the extended inputs of one RK4 stage.
Workspace = namedtuple('Workspace', 'c dprod Minv M6 zz xs k acc A Bt dk dk_new Fa M O idx kpg '
                                    'lag lag_ok ui_ext')


@cached_njit()
def new_workspace(n, n_coef, n_thr=0):
    """Workspace for an augmented state of size n and a vehicle with n_coef coefficients (the
    coefficient arrays hold the water current after them; a caller may pass n_coef + 3) and
    n_thr thrusters (their lag state; 0 for a vehicle without a lag)."""
    p = n - N_STATE
    return Workspace(np.empty(n_coef + N_CURRENT), np.empty(n_coef + N_CURRENT),
                     np.empty((N_NU, N_NU)), np.empty((N_NU, N_NU)), np.empty(ZZ_LEN),
                     np.empty(N_STATE),
                     np.empty(N_STATE), np.empty(N_STATE), np.empty((N_STATE, N_STATE)),
                     np.empty((N_STATE, p)), np.empty((N_STATE, n)), np.empty((N_STATE, n)),
                     np.empty((n, n)), np.empty((N_STATE, n)), np.empty((N_STATE, N_STATE)),
                     np.empty(N_STATE, dtype=np.int64), np.empty((3, n)),
                     np.zeros((N_LAG_ROWS, n_thr)), np.zeros(1, dtype=np.int64),
                     np.zeros(N_INPUT + (N_LAG_ROWS + 1) * n_thr))


def workspace_for(n: int, cm: Any) -> Any:
    """new_workspace for an augmented state of size n and the model cm (CompiledModel): the
    lag state sized when its thrusters lag."""
    return new_workspace(n, cm.c0.shape[0], cm.thr.shape[0] if cm.lagged else 0)


@cached_njit()
def rk4_jacobian_step(xa, ui, cm, T, want_jac, xa_next, Fa):
    """x*_{k+1} = Phi(x*_k) and Fa = dPhi/dx* with scratch of its own (see rk4_step_into; a
    lagged vehicle's thrust settled at ui)."""
    ws = new_workspace(xa.shape[0], cm.c0.shape[0], cm.thr.shape[0] if cm.lagged else 0)
    return rk4_step_into(xa, ui, cm, T, want_jac, xa_next, Fa, ws)


@kernel
def rk4_step_into(xa, ui, cm, T, want_jac, xa_next, Fa, ws):  # noqa: C901
    """x*_{k+1} = Phi(x*_k) (one RK4 step of T seconds, inputs ui held) and Fa = dPhi/dx*
    ((12+p)x(12+p)); cm is the model's CompiledModel, scratch from the Workspace ws.

    Chain rule through the stages: k_s = f(x + a_s k_{s-1}) with a_s = (0, T/2, T/2, T), so
    dk_s/dx* = [A_s | B_s] + a_s A_s dk_{s-1}/dx* (A_s = df/dx, B_s = df/dtheta at stage s) and
    Fa = I + T/6 sum_s w_s dk_s/dx* on the vehicle rows (the parameter rows are [0 I]). f does
    not depend on the position x, y, z (no depth effects in the model), so those columns of A_s
    are zero and the product skips them; then Fa's position columns are identity columns.
    A lagged vehicle's stages read the delivered thrust from ws.lag (its start of step,
    settled at ui if the record has just started; the caller carries it on with
    thruster_lag.lag_advance once the step is taken).
    """
    c0 = cm.c0
    theta_idx = cm.theta_idx
    p = theta_idx.shape[0]
    n = N_STATE + p
    c = ws.c
    for j in range(c0.shape[0]):
        c[j] = c0[j]
    for j in range(p):
        c[theta_idx[j]] = xa[N_STATE + j]
    Mi = ws.Minv                  # M^-1 for this step's coefficients (fixed over the step)
    if cm.recompute_minv:
        st = mass_inverse_into(c, cm.M_RB, cm.am_i, cm.am_s, ws.M6, Mi)
        if st != OK:
            return st
    else:
        Minv = cm.Minv
        for i in range(N_NU):
            for j in range(N_NU):
                Mi[i, j] = Minv[i, j]
    zz = ws.zz
    xs = ws.xs
    k = ws.k
    acc = ws.acc
    for i in range(N_STATE):
        k[i] = 0.0
        acc[i] = 0.0
    A = ws.A
    Bt = ws.Bt
    dk = ws.dk
    dk_new = ws.dk_new
    if want_jac:
        for i in range(N_STATE):
            for j in range(n):
                Fa[i, j] = 0.0
    for s in range(4):
        a = T * (0.0, 0.5, 0.5, 1.0)[s]
        wt = (1.0, 2.0, 2.0, 1.0)[s]
        for i in range(N_STATE):
            xs[i] = xa[i] + a * k[i]
        if cm.lagged:
            if ws.lag_ok[0] == 0:
                lag_settle(cm, ui, ws.lag, ws.lag_ok)
            lag_inputs(cm, c, ui, ws.lag, a, ws.ui_ext)
            st = state_derivative(xs, ws.ui_ext, c, Mi, cm, want_jac, k, A, Bt, zz, ws.dprod)
        else:
            st = state_derivative(xs, ui, c, Mi, cm, want_jac, k, A, Bt, zz, ws.dprod)
        if st != OK:
            return st
        for i in range(N_STATE):
            acc[i] += wt * k[i]
        if want_jac:
            # dk_new = [A | Bt] + a A dk as sums of rows of dk, one pass over a row of dk for
            # several rows of dk_new (a loop per element of A cost more in loop overhead than
            # in arithmetic at this size). Only the columns where A can be nonzero are used:
            # F depends on neither the position nor psi (dynamics rows: u..r, phi, theta),
            # the position rates on u, v, w and the Euler angles, the Euler-angle rates on
            # p, q, r, phi, theta (the Jacobian tests check this against finite differences).
            for i in range(N_STATE):
                for j in range(N_STATE):
                    dk_new[i, j] = A[i, j]
                for j in range(p):
                    dk_new[i, N_STATE + j] = Bt[i, j]
            if s > 0:
                # dynamics rows u..r, all six per pass
                for kk in _DYNAMICS_COLUMNS:
                    fu = a * A[_U, kk]
                    fv = a * A[_V, kk]
                    fw = a * A[_W, kk]
                    fp = a * A[_P, kk]
                    fq = a * A[_Q, kk]
                    fr = a * A[_R, kk]
                    for j in range(n):
                        d = dk[kk, j]
                        dk_new[_U, j] += fu * d
                        dk_new[_V, j] += fv * d
                        dk_new[_W, j] += fw * d
                        dk_new[_P, j] += fp * d
                        dk_new[_Q, j] += fq * d
                        dk_new[_R, j] += fr * d
                if cm.current == CURRENT_GROUND:
                    # the current in the body frame turns with psi: the dynamics depend on it
                    fu = a * A[_U, _PSI]
                    fv = a * A[_V, _PSI]
                    fw = a * A[_W, _PSI]
                    fp = a * A[_P, _PSI]
                    fq = a * A[_Q, _PSI]
                    fr = a * A[_R, _PSI]
                    for j in range(n):
                        d = dk[_PSI, j]
                        dk_new[_U, j] += fu * d
                        dk_new[_V, j] += fv * d
                        dk_new[_W, j] += fw * d
                        dk_new[_P, j] += fp * d
                        dk_new[_Q, j] += fq * d
                        dk_new[_R, j] += fr * d
                # position rows x, y, z and Euler-angle rows phi, theta, psi, three per pass
                # (over the union of their columns: the position rates use u, v, w, phi,
                # theta, psi, the Euler-angle rates p, q, r, phi, theta; the other terms add
                # exact zeros)
                for r in (_X, _PHI):
                    for kk in _KINEMATICS_COLUMNS:
                        f0 = a * A[r, kk]
                        f1 = a * A[r + 1, kk]
                        f2 = a * A[r + 2, kk]
                        for j in range(n):
                            d = dk[kk, j]
                            dk_new[r, j] += f0 * d
                            dk_new[r + 1, j] += f1 * d
                            dk_new[r + 2, j] += f2 * d
            dk, dk_new = dk_new, dk
            w_T = T / 6.0 * wt
            for i in range(N_STATE):
                for j in range(n):
                    Fa[i, j] += w_T * dk[i, j]
    for i in range(N_STATE):
        xa_next[i] = xa[i] + T / 6.0 * acc[i]
    for j in range(p):
        xa_next[N_STATE + j] = xa[N_STATE + j]
    if want_jac:
        for i in range(N_STATE):
            Fa[i, i] += 1.0
        for i in range(N_STATE, n):
            for j in range(n):
                Fa[i, j] = 0.0
            Fa[i, i] = 1.0
    return OK


@cached_njit()
def propagate_covariance(Fa, P, Q, P_out, M, O):
    """P_out = Fa P Fa^T + Q, symmetric, for Fa = [[Phi, Psi], [0, I]] (parameters constant).

    With F12 = Fa[:12, :] and M = F12 P: P_out[:12, :12] = M F12^T, P_out[:12, 12:] = M[:, 12:]
    and P_out[12:, 12:] = P[12:, 12:] (plus Q): two products of 12 rows instead of the full
    n x n ones. M (12 x n) and O (12 x 12) are scratch.
    """
    n = P.shape[0]
    F12 = Fa[:N_STATE]
    np.dot(F12, P, M)
    np.dot(M, F12.T, O)
    for i in range(N_STATE):
        for j in range(i + 1):
            v = 0.5 * (O[i, j] + O[j, i] + Q[i, j] + Q[j, i])
            P_out[i, j] = v
            P_out[j, i] = v
    for i in range(N_STATE, n):
        for j in range(N_STATE):
            v = M[j, i] + 0.5 * (Q[i, j] + Q[j, i])
            P_out[i, j] = v
            P_out[j, i] = v
        for j in range(N_STATE, i + 1):
            v = 0.5 * (P[i, j] + P[j, i] + Q[i, j] + Q[j, i])
            P_out[i, j] = v
            P_out[j, i] = v


@kernel
def wrap(a):
    return math.pi - ((math.pi - a) % (2.0 * math.pi))


# predict, update and adapt are inlined into run_filter (inline='always'): a call from compiled
# code costs numba two reference-count operations per array argument, some 50 arrays a step.
@cached_njit(inline='always')
def predict(xa, P, ui, Q, cm, T, xa_out, P_out, ws):
    """Time update (Eqs. 9-10) over T seconds with the inputs ui held; ws.Fa holds the
    transition Jacobian afterwards. Returns a status code."""
    st = rk4_step_into(xa, ui, cm, T, True, xa_out, ws.Fa, ws)
    if st != OK:
        return st
    propagate_covariance(ws.Fa, P, Q, P_out, ws.M, ws.O)
    return OK


@kernel
def _finish_update(xa_out, P_out, nis, m):
    """Check the posterior (positive variances, finite state) and wrap the heading."""
    for i in range(xa_out.shape[0]):
        if not (P_out[i, i] > 0.0) or not math.isfinite(xa_out[i]):
            return ERR_NOT_PD, nis, m
    xa_out[_PSI] = wrap(xa_out[_PSI])
    return OK, nis, m


@kernel
def _update_sequential(xa, P, y, R, idx, m, xa_out, P_out, innov, S_diag, white, kpg):
    """Scalar Joseph updates channel by channel (R diagonal); see update()."""
    n = xa.shape[0]
    for a in range(m):                   # prior innovations and variances, for adaptation
        ch = uint64(idx[a])              # unsigned: no negative-index test when indexing
        d = y[ch] - xa[ch]
        innov[ch] = wrap(d) if ch >= _PHI else d
        S_diag[ch] = P[ch, ch] + R[ch, ch]
    k = kpg[0]
    pj = kpg[1]
    g = kpg[2]
    nis = 0.0
    for a in range(m):
        ci = idx[a]
        ch = uint64(ci)
        r = R[ch, ch]
        # column ch of the current P; only the lower triangle of P_out is updated in the loop
        for i in range(ci):
            pj[i] = P_out[ch, i]
        for i in range(ci, n):
            pj[i] = P_out[i, ch]
        s = pj[ch] + r
        if not (s > 0.0) or not math.isfinite(s):
            return ERR_NOT_PD, np.nan, m
        d = y[ch] - xa_out[ch]
        if ch >= _PHI:
            d = wrap(d)
        inv_s = 1.0 / s
        for i in range(n):
            k[i] = pj[i] * inv_s
            xa_out[i] += k[i] * d
        white[ch] = d / math.sqrt(s)
        nis += d * d / s
        # Joseph form, P - k pj^T - pj k^T + s k k^T = P - k g^T - pj k^T with g = pj - s k.
        # Whole rows are updated (uniform loops of n vectorise; a ragged triangle loop was
        # slower), but only the lower triangle is read (pj above) and kept (mirrored below).
        for i in range(n):
            g[i] = pj[i] - s * k[i]
        for i in range(n):
            ki = k[i]
            pi = pj[i]
            for j in range(n):
                P_out[i, j] -= ki * g[j] + pi * k[j]
    for i in range(n):
        for j in range(i):
            P_out[j, i] = P_out[i, j]
    return _finish_update(xa_out, P_out, nis, m)


@cached_njit(inline='always')
def update(xa, P, y, measured, R, xa_out, P_out, innov, S_diag, white, ws):  # noqa: C901
    """Measurement update (Eqs. 11-13), Joseph form.

    measured: bool (12,), channels the sensor suite provides; a NaN in y skips a channel.
    innov (12,) gets the innovations (NaN where not used), S_diag (12,) their predicted
    variances, white (12,) the innovations whitened with the Cholesky factor of S.
    Returns (status, NIS, number of channels used). ws: the filter's Workspace (scratch).

    With R diagonal on the used channels (the usual case) the channels are fused one at a
    time: for uncorrelated measurement noise this is algebraically the batch update, each
    scalar step applies the Joseph form exactly, P+ = (I - k e_j^T) P (I - k e_j^T)^T + r k k^T,
    in O(n^2), and the sequence of scalar innovations nu_j / sqrt(s_j) is the innovation
    whitened by the Cholesky factor of S (so NIS and `white` are those of the batch update).
    A full R (the paper's Eq. 17 makes one) takes the batch path.
    """
    n = xa.shape[0]
    idx = ws.idx
    m = 0
    for j in range(N_STATE):
        innov[j] = np.nan
        S_diag[j] = np.nan
        white[j] = np.nan
        if measured[j] and math.isfinite(y[j]):
            idx[m] = j
            m += 1
    for i in range(n):
        xa_out[i] = xa[i]
        for j in range(n):
            P_out[i, j] = P[i, j]
    if m == 0:
        return OK, 0.0, 0
    # R diagonal on the used channels? A whole-matrix scan (vectorised) settles the usual
    # case; only an R with off-diagonal terms needs the look at the used pairs.
    off = 0
    for i in range(N_STATE):
        for j in range(N_STATE):
            off += (R[i, j] != 0.0) & (i != j)
    diag_R = True
    for a in range(m if off > 0 else 0):
        for b in range(m):
            if a != b and R[idx[a], idx[b]] != 0.0:
                diag_R = False
    if diag_R:
        return _update_sequential(xa, P, y, R, idx, m, xa_out, P_out, innov, S_diag, white,
                                  ws.kpg)
    nu = np.empty(m)
    S = np.empty((m, m))
    PHt = np.empty((n, m))
    for a in range(m):
        ch = idx[a]
        d = y[ch] - xa[ch]
        if ch >= _PHI:
            d = wrap(d)
        nu[a] = d
        innov[ch] = d
        for b in range(m):
            S[a, b] = P[ch, idx[b]] + R[ch, idx[b]]
        for i in range(n):
            PHt[i, a] = P[i, ch]
    for a in range(m):
        S_diag[idx[a]] = S[a, a]
    # S is SPD when P and R are; Cholesky both checks it and solves
    L = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            s = S[i, j]
            for kk in range(j):
                s -= L[i, kk] * L[j, kk]
            if i == j:
                if s <= 0.0 or not math.isfinite(s):
                    return ERR_NOT_PD, np.nan, m
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    # K = P H^T S^-1: solve S K^T = H P
    Kt = np.empty((m, n))
    for col in range(n):
        zc = np.empty(m)
        for i in range(m):
            s = PHt[col, i]
            for kk in range(i):
                s -= L[i, kk] * zc[kk]
            zc[i] = s / L[i, i]
        for i in range(m - 1, -1, -1):
            s = zc[i]
            for kk in range(i + 1, m):
                s -= L[kk, i] * Kt[kk, col]
            Kt[i, col] = s / L[i, i]
    # NIS = nu^T S^-1 nu via the Cholesky factor
    zz = np.empty(m)
    nis = 0.0
    for i in range(m):
        s = nu[i]
        for kk in range(i):
            s -= L[i, kk] * zz[kk]
        zz[i] = s / L[i, i]
        white[idx[i]] = zz[i]
        nis += zz[i] * zz[i]
    for i in range(n):
        s = 0.0
        for a in range(m):
            s += Kt[a, i] * nu[a]
        xa_out[i] = xa[i] + s
    # Joseph form (I - K H) P (I - K H)^T + K R K^T. H selects channels idx, so
    # (I - K H) P = P - K P[idx, :] and M (I - K H)^T = M - M[:, idx] K^T: explicit loops,
    # no n x n identity or matrix products with it.
    A1 = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            s = P[i, j]
            for a in range(m):
                s -= Kt[a, i] * P[idx[a], j]
            A1[i, j] = s
    KR = np.empty((n, m))
    for i in range(n):
        for b in range(m):
            s = 0.0
            for a in range(m):
                s += Kt[a, i] * R[idx[a], idx[b]]
            KR[i, b] = s
    for i in range(n):
        for j in range(i + 1):
            s = A1[i, j]
            for a in range(m):
                s -= A1[i, idx[a]] * Kt[a, j]
                s += KR[i, a] * Kt[a, j]
            # A1 (I-KH)^T is symmetric in exact arithmetic: mirror the lower triangle
            P_out[i, j] = s
            P_out[j, i] = s
    return _finish_update(xa_out, P_out, nis, m)


@cached_njit(inline='always')
def adapt(mode, gamma, lam, T, r_bound, q_floor, theta_prev, xa_post, innov, S_diag, P_prior,
          Q, R, Q0, R0):
    """Adapt Q and R in place after an update (see the module docstring for each mode)."""
    if mode == MODE_FIXED:
        return
    n = xa_post.shape[0]
    p = n - N_STATE
    if mode == MODE_PAPER or mode == MODE_PAPER_Q:
        for i in range(p):
            wi = (xa_post[N_STATE + i] - theta_prev[i]) / T
            ii = N_STATE + i
            for j in range(p):
                wj = (xa_post[N_STATE + j] - theta_prev[j]) / T
                jj = N_STATE + j
                Q[ii, jj] = (1.0 - gamma) * Q[ii, jj] + gamma * lam * lam * wi * wj
        if mode == MODE_PAPER:
            for a in range(N_STATE):
                if not math.isfinite(innov[a]):
                    continue
                for b in range(N_STATE):
                    if not math.isfinite(innov[b]):
                        continue
                    R[a, b] = (1.0 - gamma) * R[a, b] + gamma * lam * lam * innov[a] * innov[b]
    elif mode == MODE_MATCHING:
        for a in range(N_STATE):
            if not math.isfinite(innov[a]):
                continue
            est = innov[a] * innov[a] - P_prior[a, a]
            r = (1.0 - gamma) * R[a, a] + gamma * est
            R[a, a] = min(max(r, R0[a, a] / r_bound), R0[a, a] * r_bound)
        for i in range(p):
            d = xa_post[N_STATE + i] - theta_prev[i]
            q = (1.0 - gamma) * Q[N_STATE + i, N_STATE + i] + gamma * d * d
            q0 = Q0[N_STATE + i, N_STATE + i]
            Q[N_STATE + i, N_STATE + i] = min(max(q, q_floor * q0), q0)


@cached_njit(inline='always')
def restart_states(xa, P, x0, sd0):
    """Restart the vehicle states in place: xa[:12] = x0 (12,), their covariance diag(sd0^2)
    (sd0 (12,), 1-sigma) uncorrelated with the coefficients, whose estimate and covariance
    block stay (a gap, timing.py)."""
    n = xa.shape[0]
    for i in range(N_STATE):
        xa[i] = x0[i]
        for j in range(n):
            P[i, j] = 0.0
            P[j, i] = 0.0
    for i in range(N_STATE):
        P[i, i] = sd0[i] * sd0[i]


# nogil: the finite differences of batch.py run one filter per thread
@cached_njit(nogil=True)
def run_filter(xa0, P0, Y, U, cm, settings, timeline, out):  # noqa: C901
    """Run the filter over samples k = 0..N-1: update with Y[0], then for each k > 0 cross the
    interval as `timeline` says (time updates with U[k-1] held, or a restart of the vehicle
    states) and update with Y[k].

    xa0 (n,), P0 (n, n): the prior of sample 0; Y (N, 12) measurements (NaN: missing), U (N, 7)
    inputs; cm: the model's CompiledModel; settings: FilterSettings; timeline: Timeline; out:
    FilterOutputs, filled in place. Histories every `out.hist_every` samples (0: none):
    coefficients, their 1-sigma, NIS and its degrees of freedom, and the adapted diag(R) (12)
    and diag(Q_theta) (p) in out.rq. out.stats gets [status, steps done, sum NIS, sum dof, NIS
    samples]. Memory does not grow with N unless a history is asked for. With out.want_white,
    out.white (N, 12) gets the whitened innovations (for the batch refinement). Returns the
    status code."""
    n = xa0.shape[0]
    p = n - N_STATE
    N = Y.shape[0]
    measured = settings.measured
    Q0 = settings.Q0
    R0 = settings.R0
    mode = settings.mode
    T = settings.T
    th_hist = out.theta
    sd_hist = out.std
    nis_hist = out.nis
    rq_hist = out.rq
    hist_every = out.hist_every
    xa = xa0.copy()
    P = P0.copy()
    Q = Q0.copy()
    R = R0.copy()
    xa_b = xa0.copy()             # the prior of sample 0
    P_b = P0.copy()
    ws = new_workspace(n, cm.c0.shape[0], cm.thr.shape[0] if cm.lagged else 0)
    # a time constant in theta: its position (the lagged thrust follows its updates)
    j_lag = cm.theta_pos[cm.lag_idx] if cm.lagged and cm.lag_idx >= 0 else -1
    innov = np.empty(N_STATE)
    S_diag = np.empty(N_STATE)
    white = np.empty(N_STATE)
    theta_prev = xa0[N_STATE:].copy()
    sum_nis = 0.0
    sum_dof = 0.0
    cnt = 0
    status = OK
    n_sub = timeline.n_sub
    h_sub = timeline.h
    h = 0
    r = 0
    done = 0
    # ping-pong: predict (xa, P) -> (xa_b, P_b), update (xa_b, P_b) -> (xa, P)
    for k in range(N):
        if k > 0:
            st = OK
            if n_sub[k] == 0:
                xa_b[:] = xa
                P_b[:, :] = P
                restart_states(xa_b, P_b, timeline.x0[r], timeline.sd0[r])
                r += 1
                ws.lag_ok[0] = 0       # the thrust settled over the gap
            for s in range(n_sub[k]):
                if s > 0:              # the prior so far is the start of the next step
                    xa, xa_b = xa_b, xa
                    P, P_b = P_b, P
                st = predict(xa, P, U[k - 1], Q, cm, h_sub[k], xa_b, P_b, ws)
                if st != OK:
                    break
                if cm.lagged:
                    lag_advance(cm, ws.c, U[k - 1], ws.lag, ws.lag_ok, h_sub[k])
            if st != OK:
                status = st
                break
        for i in range(p):
            theta_prev[i] = xa_b[N_STATE + i]
        st, nis, m = update(xa_b, P_b, Y[k], measured, R, xa, P, innov, S_diag, white, ws)
        if out.want_white:
            out.white[k, :] = white
        if st != OK:
            xa[:] = xa_b          # report the prior, not a half-updated state
            P[:, :] = P_b
            status = st
            break
        adapt(mode, settings.gamma, settings.lam, T, settings.r_bound, settings.q_floor,
              theta_prev, xa, innov, S_diag, P_b, Q, R, Q0, R0)
        if j_lag >= 0:
            lag_correct(ws.lag, xa[N_STATE + j_lag] - theta_prev[j_lag])
        if m > 0:
            sum_nis += nis
            sum_dof += m
            cnt += 1
        if hist_every > 0 and k % hist_every == 0 and h < th_hist.shape[0]:
            for i in range(p):
                th_hist[h, i] = xa[N_STATE + i]
                sd_hist[h, i] = math.sqrt(P[N_STATE + i, N_STATE + i])
            nis_hist[h, 0] = nis
            nis_hist[h, 1] = m
            for i in range(N_STATE):
                rq_hist[h, i] = R[i, i]
            for i in range(p):
                rq_hist[h, N_STATE + i] = Q[N_STATE + i, N_STATE + i]
            h += 1
        done += 1
    out.xa[:] = xa
    out.P[:, :] = P
    out.Q[:, :] = Q
    out.R[:, :] = R
    stats = out.stats
    stats[0] = status
    stats[1] = done
    stats[2] = sum_nis
    stats[3] = sum_dof
    stats[4] = cnt
    return status
