"""The water current's terms of the compiled model (model/hydrodynamics.py has the equations): the
current in the body frame with its derivatives, and what a current adds to f and its Jacobians
when the state's velocities are over ground. Kept apart from hydrodynamics.py, which calls
them, so that each module stays readable; nothing here allocates (the kernels of
hydrodynamics.py's kind).
"""
import math

from auv_ident.core.compiled_cache import cached_njit
from auv_ident.core.model.monomials import ZZ_DU_DV
from auv_ident.core.model.state import N_CURRENT, N_NU, N_STATE, State

kernel = cached_njit(_nrt=False)     # as hydrodynamics.kernel (no reference counting)

_U, _V, _W, _P, _Q, _R = (int(s) for s in (State.U, State.V, State.W, State.P, State.Q, State.R))
_PHI = int(State.PHI)

# How the water current enters f (CompiledModel.current): not at all (still water, nothing
# identified), with the state's velocities over ground, or through the water
# (core/model/hydrodynamics.py)
CURRENT_NONE, CURRENT_GROUND, CURRENT_WATER = 0, 1, 2
# Scratch zz (ZZ_LEN,): [z (NZ), dz/dx (NZ), dU/dv (1), x_r (12), v_cb (3),
# d v_cb / d(phi, theta, psi) (3 x 3, column per angle), R^T (3 x 3, row-major), x with the
# held states at 0 (12, core/model/planar.py)]
ZZ_XR = ZZ_DU_DV + 1
ZZ_VCB = ZZ_XR + N_STATE
ZZ_DV = ZZ_VCB + 3
ZZ_RT = ZZ_DV + 9
ZZ_XH = ZZ_RT + 9
ZZ_LEN = ZZ_XH + N_STATE


@kernel
def current_in_body(vc, sph, cph, sth, cth, psi, zz):
    """v_cb = R(Theta)^T v_c (the current in the body frame, m/s) into zz[ZZ_VCB:], its
    derivatives by phi, theta, psi into zz[ZZ_DV:] (3 per angle) and R^T into zz[ZZ_RT:]
    (row-major). R^T = Rx(phi)^T Ry(theta)^T Rz(psi)^T (Fossen eq. 2.18) applied in three
    steps, each differentiated by its own angle."""
    spsi = math.sin(psi)
    cpsi = math.cos(psi)
    n = vc[0]
    e = vc[1]
    d = vc[2]
    v1x = cpsi * n + spsi * e          # Rz^T v_c
    v1y = -spsi * n + cpsi * e
    v2x = cth * v1x - sth * d          # Ry^T (.)
    v2z = sth * v1x + cth * d
    v3y = cph * v1y + sph * v2z        # Rx^T (.)
    v3z = -sph * v1y + cph * v2z
    zz[ZZ_VCB] = v2x
    zz[ZZ_VCB + 1] = v3y
    zz[ZZ_VCB + 2] = v3z
    # d/dphi
    zz[ZZ_DV] = 0.0
    zz[ZZ_DV + 1] = v3z
    zz[ZZ_DV + 2] = -v3y
    # d/dtheta: d(Ry^T v1) = (-v2z, 0, v2x), then Rx^T
    zz[ZZ_DV + 3] = -v2z
    zz[ZZ_DV + 4] = sph * v2x
    zz[ZZ_DV + 5] = cph * v2x
    # d/dpsi: d(Rz^T v_c) = (v1y, -v1x, 0), then Ry^T and Rx^T
    ax = cth * v1y
    az = sth * v1y
    zz[ZZ_DV + 6] = ax
    zz[ZZ_DV + 7] = -cph * v1x + sph * az
    zz[ZZ_DV + 8] = sph * v1x + cph * az
    # R^T[i, j] = R[j, i] (R as in model._kinematics)
    zz[ZZ_RT] = cpsi * cth
    zz[ZZ_RT + 1] = spsi * cth
    zz[ZZ_RT + 2] = -sth
    zz[ZZ_RT + 3] = -spsi * cph + cpsi * sth * sph
    zz[ZZ_RT + 4] = cpsi * cph + sph * sth * spsi
    zz[ZZ_RT + 5] = cth * sph
    zz[ZZ_RT + 6] = spsi * sph + cpsi * cph * sth
    zz[ZZ_RT + 7] = -cpsi * sph + sth * spsi * cph
    zz[ZZ_RT + 8] = cth * cph


@kernel
def current_ground(x, cm, want_jac, xdot, A, Bt, zz):
    """The current's terms for a state over ground (module docstring), after the dynamics
    were evaluated at nu_r: xdot[0:6] = nu_r_dot and A[0:6] = d nu_r_dot / d x_r on entry.
    Adds v_cb x omega to the linear rates and the chain rule through nu_r = nu - [v_cb; 0]:
    d/d(phi, theta, psi) gains -G dv_cb/dangle (G = A[0:6, u:w]) and, in the linear rows,
    dv_cb/dangle x omega; d/d(p, q, r) gains S(v_cb) in the linear rows; d/dv_c (Bt, for an
    identified component k) is -G R^T e_k plus R^T e_k x omega."""
    p = x[_P]
    q = x[_Q]
    r = x[_R]
    vx = zz[ZZ_VCB]
    vy = zz[ZZ_VCB + 1]
    vz = zz[ZZ_VCB + 2]
    xdot[_U] += vy * r - vz * q
    xdot[_V] += vz * p - vx * r
    xdot[_W] += vx * q - vy * p
    if not want_jac:
        return
    for a in range(3):                     # phi, theta, psi
        col = _PHI + a
        dx = zz[ZZ_DV + 3 * a]
        dy = zz[ZZ_DV + 3 * a + 1]
        dz = zz[ZZ_DV + 3 * a + 2]
        for i in range(N_NU):
            A[i, col] -= A[i, _U] * dx + A[i, _V] * dy + A[i, _W] * dz
        A[_U, col] += dy * r - dz * q
        A[_V, col] += dz * p - dx * r
        A[_W, col] += dx * q - dy * p
    A[_U, _Q] -= vz
    A[_U, _R] += vy
    A[_V, _P] += vz
    A[_V, _R] -= vx
    A[_W, _P] -= vy
    A[_W, _Q] += vx
    nc = cm.n_coef
    for k in range(N_CURRENT):
        j = cm.theta_pos[nc + k]
        if j < 0:
            continue
        ex = zz[ZZ_RT + k]                  # column k of R^T
        ey = zz[ZZ_RT + 3 + k]
        ez = zz[ZZ_RT + 6 + k]
        for i in range(N_NU):
            Bt[i, j] -= A[i, _U] * ex + A[i, _V] * ey + A[i, _W] * ez
        Bt[_U, j] += ey * r - ez * q
        Bt[_V, j] += ez * p - ex * r
        Bt[_W, j] += ex * q - ey * p
