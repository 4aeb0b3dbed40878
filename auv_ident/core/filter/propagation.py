"""Compiled kernels that carry many states through the model's RK4 step (ekf.rk4_step_into
without its Jacobian: the discretisation of the EKF's time update): the sigma points of the
unscented filter (ukf.py) and the shooting segments of the output error (output_error.py).

Kept apart from those modules so that the numba cache's group of compiled sources
(core/__init__.py COMPILED_SOURCES) holds only this file and what it imports.
"""
import numpy as np

from auv_ident.core.compiled_cache import cached_njit
from auv_ident.core.filter import ekf
from auv_ident.core.model.hydrodynamics import OK
from auv_ident.core.model.state import N_STATE
from auv_ident.core.model.thruster_lag import lag_advance


@cached_njit()
def propagate_sigma_points(X, ui, cm, h, X_out, ws):
    """X_out[i] = one RK4 step of h seconds of sigma point X[i] ((2n+1, n) rows, augmented
    states) with the inputs ui held; cm the model's CompiledModel, ws its ekf.Workspace (a
    lagged vehicle's thrust: every point starts from ws.lag, carried on by the caller).
    Returns OK or the first failing point's status code."""
    for i in range(X.shape[0]):
        st = ekf.rk4_step_into(X[i], ui, cm, h, False, X_out[i], ws.Fa, ws)
        if st != OK:
            return st
    return OK


@cached_njit()
def simulate_segments(theta, X0, U, seg, n_sub, h, cm, X):
    """Free run of each segment: X[k] (12,) the model's state at sample k. Segment s starts at
    the first sample k with seg[k] = s, from X0[s] (12,); seg[k] = -1 before the first start.
    NaN after a failed step until the next start. theta (p,) the parameters (the augmented
    model cm reads them from the state's tail); n_sub[k], h[k] the RK4 steps crossing
    [t_{k-1}, t_k] (timing.time_steps) with U[k-1] held. Returns the number of segments that
    left the model's domain."""
    p = theta.shape[0]
    n = N_STATE + p
    ws = ekf.new_workspace(n, cm.c0.shape[0], cm.thr.shape[0] if cm.lagged else 0)
    xa = np.empty(n)
    xb = np.empty(n)
    for j in range(p):
        xa[N_STATE + j] = theta[j]
    active = False
    failed = 0
    current = -1
    for k in range(X.shape[0]):
        if seg[k] != current:
            current = seg[k]
            if current >= 0:
                for i in range(N_STATE):
                    xa[i] = X0[current, i]
                ws.lag_ok[0] = 0        # a lagged thrust settles at the segment's command
            active = current >= 0
        elif active:
            for s in range(n_sub[k]):
                st = ekf.rk4_step_into(xa, U[k - 1], cm, h[k], False, xb, ws.Fa, ws)
                if st != OK:
                    active = False
                    failed += 1
                    break
                if cm.lagged:
                    lag_advance(cm, ws.c, U[k - 1], ws.lag, ws.lag_ok, h[k])
                xa, xb = xb, xa
        for i in range(N_STATE):
            X[k, i] = xa[i] if active else np.nan
    return failed
