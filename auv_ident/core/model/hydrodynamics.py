"""The 6-DOF AUV model x_dot = f(x, u_in, c) and its exact Jacobians, compiled with numba.

x = [u v w p q r x y z phi theta psi] (m/s, rad/s, m, rad; body FRD, world NED, ZYX Euler),
u_in = [delta_r delta_s delta_b delta_bp delta_bs n_rpm thrust] (rad, rpm, N), fins and shaft
saturated inside,
c = every coefficient of the vehicle file in the file's units (prime values if nondimensional).

    M nu_dot = F(nu, eta, delta, c),   eta_dot = J(eta) nu            (Fossen 2021, eq. 6.3)

F = sum of monomial terms (hydrodynamic/control coefficients and rigid-body Coriolis, see
vehicle.py; compiled per vehicle from its term table by monomials.py) + restoring g(eta) +
propulsion + cross-flow drag (+ the added mass's Coriolis forces -C_A(nu) nu computed from the
added-mass coefficients, for a file with `added_mass_coriolis: fossen`: _added_mass_coriolis).
A vehicle with fewer degrees of freedom holds the others
(core/model/planar.py). The Jacobians are analytic: each monomial is differentiated
factor by factor, and propulsion, cross-flow, restoring and kinematics have hand-derived
derivatives (all checked against finite differences in the tests).
Why analytic and compiled: the EKF needs f and both Jacobians four times per RK4 step, tens of
thousands of times per second.

Water current (Fossen 2021, sec. 10.3, an irrotational current constant in NED, v_c (3,),
m/s, where the water goes): the hydrodynamic, control, propulsion and added-mass forces act on
the velocity relative to the water nu_r = nu - [R(Theta)^T v_c; 0]. For such a current the
rigid-body terms can be written in nu_r as well (Fossen 2021, Property 10.1: with
d/dt (R^T v_c) = -omega x R^T v_c one has M_RB nu_dot + C_RB(nu) nu = M_RB nu_r_dot
+ C_RB(nu_r) nu_r, checked term by term for v_dot + omega x v and r_G x (v_dot + omega x v)),
so the whole vehicle equation is the still-water one in nu_r:

    M nu_r_dot + C(nu_r) nu_r + D(nu_r) nu_r + g(eta) = tau,                (Fossen eq. 10.18)
    nu_dot = nu_r_dot + [v_cb x omega; 0],  v_cb = R^T v_c,  eta_dot = J(eta) nu.

Which velocity the state holds is what the velocity sensor measures (so the measurement stays
a selection of states): with velocity_reference 'ground' (DVL in bottom lock) x holds nu over
ground and f applies the two lines above (the dynamics then depend on psi through v_cb); with
'water' (water-track DVL) x holds nu_r, nu_r_dot is the still-water f and the position rate
gains the current, eta_dot = J(eta) nu_r + [v_c; 0]. The current's components come after the
vehicle coefficients in c (c[n_coef:n_coef + 3] = v_c north, east, down), so an identified
component is one more entry of theta and df/dv_c a column of Bt (chain rule through nu_r).
Still water with no current identified (cm.current == CURRENT_NONE) runs none of this.

Domain: the kernels return a status code instead of NaN (see STATUS_TEXT).
"""
from collections import namedtuple
from collections.abc import Sequence
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from auv_ident.core.compiled_cache import cached_njit
from auv_ident.core.errors import DimensionError, DomainError
from auv_ident.core.model.current_terms import (
    CURRENT_GROUND,
    current_ground,
    current_in_body,
    CURRENT_NONE,
    CURRENT_WATER,
    ZZ_LEN,
    ZZ_VCB,
    ZZ_XH,
    ZZ_XR,
)
from auv_ident.core.model.monomials import kernel_at, monomial_kernel, NZ, Z_EPS, Z_THRUST
from auv_ident.core.model.planar import held_at_zero, hold_states, speed_factor
from auv_ident.core.model.state import (
    CURRENT_NAMES,
    Input,
    N_CURRENT,
    N_FINS,
    N_INPUT,
    N_NU,
    N_STATE,
    State,
    VELOCITY_REFERENCES,
)
from auv_ident.core.model.thrusters import (
    T_CMAX,
    T_CURVE,
    T_DEAD,
    T_FMAX_FWD,
    T_FMAX_REV,
    T_FWD1,
    T_FWD2,
    T_NEUTRAL,
    T_NTAB,
    T_REV1,
    T_REV2,
    THR_COLS,
)
from auv_ident.core.model.vehicle import (
    COS_THETA_MIN,
    FACTOR_INDEX,
    P_B,
    P_CF,
    P_CF_CY,
    P_CF_CZ,
    P_CF_N,
    P_FIN,
    P_L,
    P_NMAX,
    P_PROP,
    P_PROP_A,
    P_PROP_B,
    P_PROP_C,
    P_RHO,
    P_SPEED_FACTOR,
    P_U_MIN,
    P_W,
    P_XB,
    P_XG,
    P_YB,
    P_YG,
    P_ZB,
    P_ZG,
    Vehicle,
)

# State and input indices, and the places in the factor vector z (vehicle.FACTORS), as plain
# ints: numba freezes them into the same constants as the literals they replace
_U, _V, _W, _P, _Q, _R, _X, _Y, _Z, _PHI, _THETA, _PSI = (int(s) for s in State)
_N_RPM = int(Input.N_RPM)
_THRUST = int(Input.THRUST)
_Z_ABS = FACTOR_INDEX['|u|']        # |u| .. |r|
_Z_FINS = FACTOR_INDEX['dr']        # dr ds db dbp dbs
_Z_DBP, _Z_DBS, _Z_DB2 = FACTOR_INDEX['dbp'], FACTOR_INDEX['dbs'], FACTOR_INDEX['db2']


# The hot kernels are compiled without numba's reference counting (its `_nrt` option; numba is
# pinned in requirements.txt). A kernel only reads and writes arrays its caller owns and
# allocates nothing (numba refuses to compile an allocation without NRT); every call of a
# compiled function with reference counting costs an atomic increment and decrement per array
# argument, which perf put at about a fifth of an EKF step (README, Speed).
kernel = cached_njit(_nrt=False)

# Everything the compiled model needs besides the state, the inputs and scratch: built in one
# place (Model.compiled, Model.compiled_fixed) and handed to the kernels as one argument. A
# namedtuple is a plain struct in compiled code (reading a field costs nothing) and, unlike a
# structref, can be read by the kernels compiled without reference counting.
CompiledModel = namedtuple('CompiledModel', 'c0 theta_idx par mono_addr theta_terms am_i am_s '
                                            'Minv recompute_minv M_RB theta_pos current n_coef '
                                            'held thr gain_idx lag_idx lagged ca_i ca_s')
CompiledModel.__doc__ = """The compiled model's data (one filter's view of a Model).

c0 : (n_coef + 3,) coefficient values (the file's units) for the coefficients not in theta,
    then the water current north, east, down (m/s, NED)
theta_idx : (p,) int, index in c0 of each identified parameter (theta's order; n_coef + i for
    a current component)
par : (N_PAR,) the vehicle's float parameters (layout vehicle.P_*)
mono_addr : int, address of the vehicle's compiled monomial kernel (monomials.kernel_at)
theta_terms : (p, 2) int, [equation, coefficient index] per identified coefficient (equation -1
    for added mass, which has no monomial)
am_i : (na, 3) int, [equation, column, coefficient index] per added-mass coefficient
am_s : (na,) scale of each added-mass coefficient
Minv : (6, 6) M^-1 for c0 (used unless recompute_minv)
recompute_minv : bool, M^-1 is recomputed from the step's coefficients (added mass in theta)
M_RB : (6, 6) rigid-body mass matrix
theta_pos : (n_coef + 3,) int, position of each entry of c0 in theta, or -1
current : int, CURRENT_NONE, CURRENT_GROUND or CURRENT_WATER (how the current enters f)
n_coef : int, number of vehicle coefficients (the current's place in c0)
held : (h,) int, the states the vehicle holds (core/model/planar.py; empty for 6 DOF)
thr : (n, thrusters.THR_COLS + 3 K_max) the thrusters and their tables (empty for a fin
    vehicle); their commands are u_in[N_INPUT:N_INPUT + n]
gain_idx : (2, 6) int, per curve side (forward, reverse) and equation the index in c0 of
    its thrust gain, or -1 (gain 1)
lag_idx : int, index in c0 of the thrusters' shared time constant (multiplier thruster_lag),
    or -1 (each thruster's own, thrusters.T_TAU)
lagged : bool, the thrusters lag (Vehicle.lagged): the filters carry the delivered thrust
    (core/model/thruster_lag.py) and give the model the extended inputs
ca_i : (nc, 4) int, the added-mass Coriolis terms the model computes (vehicle.ca_i:
    [equation, added-mass coefficient index in c0, nu factor, nu factor]; empty when the file
    writes its own)
ca_s : (nc,) the scale of each
"""

OK, ERR_NONFINITE, ERR_U_ZERO, ERR_EPS_COMPLEX, ERR_THETA_90, ERR_M_SINGULAR = 0, 1, 2, 3, 4, 5
STATUS_TEXT = {
    ERR_NONFINITE: 'NaN or Inf in the state, the inputs or the coefficients',
    ERR_U_ZERO: 'surge speed u is ~0: the Healey-Lienard propeller ratio eta = 0.012 n/u is '
                'singular (|u| < 1e-6 m/s)',
    ERR_EPS_COMPLEX: 'n and u of opposite sign with |eta| too large: the propeller epsilon '
                     'would be complex (Ct < -1)',
    ERR_THETA_90: 'pitch theta is at +-90 deg: the Euler-angle kinematics are singular',
    ERR_M_SINGULAR: 'the mass matrix M = M_RB + M_A is singular for these added-mass '
                    'coefficients',
}


@cached_njit()
def _sign(a):
    return 1.0 if a > 0.0 else (-1.0 if a < 0.0 else 0.0)


@kernel
def _propulsion(u, n_rpm, par, zz, xdot, A, want_jac):
    """Propeller force/moment into xdot[0:6] (and A), the Healey-Lienard epsilon (and its
    derivative) into zz.
    Returns a status code."""
    pm = int(par[P_PROP])
    rho = par[P_RHO]
    L = par[P_L]
    zz[Z_EPS] = 0.0
    zz[NZ + Z_EPS] = 0.0
    if pm == 1:   # Healey & Lienard (MSS npsauv.m)
        if abs(u) < par[P_U_MIN]:
            return ERR_U_ZERO
        n_rad = n_rpm * 2.0 * math.pi / 60.0
        Cd0 = par[P_PROP_A]
        a = par[P_PROP_B] * n_rad                 # eta = a / u
        eta = a / u
        ee = abs(eta) * eta
        h2 = 0.5 * rho * L * L
        # u^2 Cd0 (|eta| eta - 1) = Cd0 (|a| a sign(u) - u^2): thrust does not depend on u
        xdot[_U] += h2 * u * u * Cd0 * (ee - 1.0)
        ctg = par[P_PROP_C] * L * L / 2.0
        Ct = ctg * ee
        if Ct + 1.0 < 0.0:
            return ERR_EPS_COMPLEX
        den = math.sqrt(ctg + 1.0) - 1.0          # Ct at eta = 1
        sgn = _sign(n_rad) / _sign(u)
        sq = math.sqrt(Ct + 1.0)
        zz[Z_EPS] = -1.0 + sgn * (sq - 1.0) / den
        if want_jac:
            A[_U, _U] += h2 * Cd0 * (-2.0 * u)
            au = abs(u)
            dee_du = -2.0 * abs(a) * a / (au * au * au)
            zz[NZ + Z_EPS] = sgn * (0.5 / sq) * ctg * dee_du / den
    elif pm == 2:  # thrust and torque quadratic in n (Prestero's constant Xprop, Kprop at n0)
        s = n_rpm / par[P_PROP_C]
        xdot[_U] += par[P_PROP_A] * s * abs(s)
        xdot[_P] += par[P_PROP_B] * s * abs(s)
    return OK


@kernel
def _table_thrust(thr, i, c):
    """Thruster i's table curve at command c (thrusters.hermite, compiled): the table's end
    values beyond its ends, else the cubic Hermite piece of the interval holding c (found by
    bisection over the K points stored from column THR_COLS: commands, thrusts, slopes)."""
    k_n = int(thr[i, T_NTAB])
    x0 = THR_COLS
    f0 = THR_COLS + k_n
    d0 = THR_COLS + 2 * k_n
    if c <= thr[i, x0]:
        return thr[i, f0]
    if c >= thr[i, x0 + k_n - 1]:
        return thr[i, f0 + k_n - 1]
    lo = 0
    hi = k_n - 1
    while hi - lo > 1:          # x[lo] <= c < x[hi]
        mid = (lo + hi) // 2
        if thr[i, x0 + mid] <= c:
            lo = mid
        else:
            hi = mid
    h = thr[i, x0 + hi] - thr[i, x0 + lo]
    t = (c - thr[i, x0 + lo]) / h
    t2 = t * t
    t3 = t2 * t
    return ((2.0 * t3 - 3.0 * t2 + 1.0) * thr[i, f0 + lo]
            + (t3 - 2.0 * t2 + t) * h * thr[i, d0 + lo]
            + (-2.0 * t3 + 3.0 * t2) * thr[i, f0 + hi] + (t3 - t2) * h * thr[i, d0 + hi])


@kernel
def thrust_of(thr, i, cmd):
    """Steady thrust (N, along the thruster's direction) of thruster i (row of thr) for its
    command cmd: thrusters.Thruster.thrust, compiled (the same curve, dead band and
    saturations)."""
    if thr[i, T_CURVE] == 0.0:
        f = cmd
    elif thr[i, T_NTAB] > 0.0:
        cmax = thr[i, T_CMAX]
        n0 = thr[i, T_NEUTRAL]
        f = _table_thrust(thr, i, min(max(cmd, n0 - cmax), n0 + cmax))
    else:
        cmax = thr[i, T_CMAX]
        e = min(max(cmd - thr[i, T_NEUTRAL], -cmax), cmax)
        dead = thr[i, T_DEAD]
        if abs(e) <= dead:
            return 0.0
        if e > 0.0:
            e -= dead
            f = thr[i, T_FWD1] * e + thr[i, T_FWD2] * e * e
        else:
            e += dead
            f = thr[i, T_REV1] * e - thr[i, T_REV2] * e * e
    return min(max(f, -thr[i, T_FMAX_REV]), thr[i, T_FMAX_FWD])


@kernel
def _thrusters(ui, c, cm, want_jac, xdot, Bt):  # noqa: C901 (steady and lagged, each side)
    """The thrusters' wrench tau = T f(commands) (thrusters.py) into xdot[0:6]: per equation
    the forward thrusts' part times its gain and the reverse thrusts' part times its gain
    (cm.gain_idx; 1 where none), and d/d(gain) = that part into Bt for a gain in theta. The
    commands are inputs, so there is no df/dx. An extended input vector (a lagged vehicle's,
    core/model/thruster_lag.py: u_in, then the delivered forward and reverse thrusts and their
    derivatives by the time constant) gives the delivered thrust in place of the curve's
    value, and d/d(tau) = g_fwd T S_P + g_rev T S_N into Bt for a time constant in theta; the
    plain inputs give the steady thrust (a trim, a settled state)."""
    thr = cm.thr
    n = thr.shape[0]
    lagged = ui.shape[0] > N_INPUT + n
    o = N_INPUT + n                 # the extended part: P (n), N (n), S_P (n), S_N (n)
    jl = cm.theta_pos[cm.lag_idx] if want_jac and lagged and cm.lag_idx >= 0 else -1
    for e in range(N_NU):
        tau_f = 0.0
        tau_r = 0.0
        s_f = 0.0
        s_r = 0.0
        for i in range(n):
            col = thr[i, e]
            if col != 0.0:
                if lagged:
                    tau_f += col * ui[o + i]
                    tau_r += col * ui[o + n + i]
                    s_f += col * ui[o + 2 * n + i]
                    s_r += col * ui[o + 3 * n + i]
                else:
                    f = thrust_of(thr, i, ui[N_INPUT + i])
                    if f > 0.0:
                        tau_f += col * f
                    else:
                        tau_r += col * f
        for side in range(2):
            tau = tau_f if side == 0 else tau_r
            gi = cm.gain_idx[side, e]
            g = 1.0
            if gi < 0:
                xdot[e] += tau
            else:
                g = c[gi]
                xdot[e] += g * tau
                j = cm.theta_pos[gi]
                if want_jac and j >= 0:
                    Bt[e, j] += tau
            if jl >= 0:
                Bt[e, jl] += g * (s_f if side == 0 else s_r)


@kernel
def _added_mass_coriolis(xv, c, cm, want_jac, xdot, A, Bt):
    """-C_A(nu) nu of the added-mass coefficients (vehicle.added_mass_coriolis_terms) into
    xdot[0:6]: per term s c[ci] nu_a nu_b, its derivatives by nu_a and nu_b into A and by the
    added-mass coefficient, s nu_a nu_b, into Bt when it is identified (one coefficient has
    terms in several equations, so these are not the monomial kernel's one term per
    coefficient). xv holds nu_r with a current."""
    ca_i = cm.ca_i
    ca_s = cm.ca_s
    for t in range(ca_i.shape[0]):
        eq = ca_i[t, 0]
        ci = ca_i[t, 1]
        a = xv[ca_i[t, 2]]
        b = xv[ca_i[t, 3]]
        k = ca_s[t] * c[ci]
        xdot[eq] += k * a * b
        if want_jac:
            A[eq, ca_i[t, 2]] += k * b
            A[eq, ca_i[t, 3]] += k * a
            j = cm.theta_pos[ci]
            if j >= 0:
                Bt[eq, j] += ca_s[t] * a * b


@kernel
def _restoring(par, sph, cph, sth, cth, want_jac, xdot, A):
    """Restoring forces g(eta) (Fossen eq. 4.6), sign flipped to the right-hand side."""
    W = par[P_W]
    B = par[P_B]
    WB = W - B
    gx = par[P_XG] * W - par[P_XB] * B
    gy = par[P_YG] * W - par[P_YB] * B
    gz = par[P_ZG] * W - par[P_ZB] * B
    xdot[_U] += -WB * sth
    xdot[_V] += WB * cth * sph
    xdot[_W] += WB * cth * cph
    xdot[_P] += gy * cth * cph - gz * cth * sph
    xdot[_Q] += -gz * sth - gx * cth * cph
    xdot[_R] += gx * cth * sph + gy * sth
    if want_jac:
        A[_U, _THETA] += -WB * cth
        A[_V, _PHI] += WB * cth * cph
        A[_V, _THETA] += -WB * sth * sph
        A[_W, _PHI] += -WB * cth * sph
        A[_W, _THETA] += -WB * sth * cph
        A[_P, _PHI] += -gy * cth * sph - gz * cth * cph
        A[_P, _THETA] += -gy * sth * cph + gz * sth * sph
        A[_Q, _PHI] += gx * cth * sph
        A[_Q, _THETA] += -gz * cth + gx * sth * cph
        A[_R, _PHI] += gx * cth * cph
        A[_R, _THETA] += -gx * sth * sph + gy * cth


# The strip sum may be reordered (reassoc) and fused (contract): that lets the compiler run four
# stations at once (2x faster; the sums move by ~1e-16 relative). No-NaN/no-Inf flags are not
# given, so a NaN still reaches the finiteness checks of state_derivative.
@cached_njit(_nrt=False, fastmath={'reassoc', 'contract', 'nsz'})
def _crossflow(par, v, w, q, r, want_jac, xdot, A):
    """Cross-flow drag, MSS classic strip sum (skipped when v = w = 0, as MSS does).

    Per strip at x_l: a = v + x_l r, b = w - x_l q, U = sqrt(a^2 + b^2), g = (c_y a^2 +
    c_z b^2) / U; Y -= rho/2 sum g a dx, Z += .. g b, M -= .. g (w + x_l q) x_l ('+' as in MSS,
    sic), N -= .. g a x_l. The derivatives w.r.t. (v, w, q, r) follow from da = (1, 0, 0, x_l),
    db = (0, 1, -x_l, 0), dc = (0, 1, x_l, 0), written out term by term. A strip with U = 0
    adds nothing (the integrand is O(U)): 1/U is taken as 0 there, a select rather than a
    branch, so the loop vectorises."""
    if int(par[P_CF]) != 1 or (v * v + w * w) == 0.0:
        return
    L = par[P_L]
    ns = int(par[P_CF_N])
    dx = L / (ns - 1)
    cy = par[P_CF_CY]
    cz = par[P_CF_CZ]
    Sy = Sz = Sm = Sn = 0.0
    Yv = Yw = Yq = Yr = 0.0     # d Sy / d(v, w, q, r), and so on
    Zv = Zw = Zq = Zr = 0.0
    Mv = Mw = Mq = Mr = 0.0
    Nv = Nw = Nq = Nr = 0.0
    for i in range(ns):
        xl = -L / 2.0 + i * dx
        aa = v + xl * r
        bb = w - xl * q
        U2 = aa * aa + bb * bb
        iU = 1.0 / math.sqrt(U2) if U2 > 0.0 else 0.0
        N_ = cy * aa * aa + cz * bb * bb
        g = N_ * iU
        cc = w + xl * q
        Sy += g * aa
        Sz += g * bb
        Sm += g * cc * xl
        Sn += g * aa * xl
        if want_jac:
            iU3 = iU * iU * iU
            ga = 2.0 * cy * aa * iU - N_ * aa * iU3   # dg/da
            gb = 2.0 * cz * bb * iU - N_ * bb * iU3   # dg/db
            ya = ga * aa + g                          # d(g a)/da
            zb = gb * bb + g                          # d(g b)/db
            Yv += ya
            Yw += gb * aa
            Yq -= gb * aa * xl
            Yr += ya * xl
            Zv += ga * bb
            Zw += zb
            Zq -= zb * xl
            Zr += ga * bb * xl
            Mv += ga * cc * xl
            Mw += (gb * cc + g) * xl
            Mq += (-gb * xl * cc + g * xl) * xl
            Mr += ga * xl * cc * xl
            Nv += ya * xl
            Nw += gb * aa * xl
            Nq -= gb * aa * xl * xl
            Nr += ya * xl * xl
    h = 0.5 * par[P_RHO] * dx
    xdot[_V] -= h * Sy
    xdot[_W] += h * Sz
    xdot[_Q] -= h * Sm
    xdot[_R] -= h * Sn
    if want_jac:
        A[_V, _V] -= h * Yv
        A[_V, _W] -= h * Yw
        A[_V, _Q] -= h * Yq
        A[_V, _R] -= h * Yr
        A[_W, _V] += h * Zv
        A[_W, _W] += h * Zw
        A[_W, _Q] += h * Zq
        A[_W, _R] += h * Zr
        A[_Q, _V] -= h * Mv
        A[_Q, _W] -= h * Mw
        A[_Q, _Q] -= h * Mq
        A[_Q, _R] -= h * Mr
        A[_R, _V] -= h * Nv
        A[_R, _W] -= h * Nw
        A[_R, _Q] -= h * Nq
        A[_R, _R] -= h * Nr


@kernel
def _solve_minv(Mi, X, ncols):
    """X[0:6, :ncols] <- M^-1 X[0:6, :ncols] in place (one column at a time)."""
    for j in range(ncols):
        f0 = X[0, j]
        f1 = X[1, j]
        f2 = X[2, j]
        f3 = X[3, j]
        f4 = X[4, j]
        f5 = X[5, j]
        for i in range(N_NU):
            X[i, j] = (Mi[i, 0] * f0 + Mi[i, 1] * f1 + Mi[i, 2] * f2 + Mi[i, 3] * f3
                       + Mi[i, 4] * f4 + Mi[i, 5] * f5)


@kernel
def _solve_vec(Mi, v):
    """v[0:6] <- M^-1 v[0:6] in place. (The same sum as _solve_minv, written again on purpose:
    going through _solve_minv with v reshaped to a column cost 0.4 us per EKF step, numba's
    reference counting of the view.)"""
    f0 = v[0]
    f1 = v[1]
    f2 = v[2]
    f3 = v[3]
    f4 = v[4]
    f5 = v[5]
    for i in range(N_NU):
        v[i] = (Mi[i, 0] * f0 + Mi[i, 1] * f1 + Mi[i, 2] * f2 + Mi[i, 3] * f3 + Mi[i, 4] * f4
                + Mi[i, 5] * f5)


@kernel
def _kinematics(x, sph, cph, sth, cth, want_jac, xdot, A):
    """eta_dot = J(eta) nu (Fossen eq. 2.40, ZYX) into xdot[6:12], d/dx into A[6:12]."""
    u = x[_U]
    v = x[_V]
    w = x[_W]
    p = x[_P]
    q = x[_Q]
    r = x[_R]
    psi = x[_PSI]
    cp = math.cos(psi)
    sp = math.sin(psi)
    tt = sth / cth
    R00 = cp * cth
    R01 = -sp * cph + cp * sth * sph
    R02 = sp * sph + cp * cph * sth
    R10 = sp * cth
    R11 = cp * cph + sph * sth * sp
    R12 = -cp * sph + sth * sp * cph
    R20 = -sth
    R21 = cth * sph
    R22 = cth * cph
    xd = R00 * u + R01 * v + R02 * w
    yd = R10 * u + R11 * v + R12 * w
    xdot[_X] = xd
    xdot[_Y] = yd
    xdot[_Z] = R20 * u + R21 * v + R22 * w
    xdot[_PHI] = p + sph * tt * q + cph * tt * r
    xdot[_THETA] = cph * q - sph * r
    xdot[_PSI] = (sph * q + cph * r) / cth
    if want_jac:          # rows 6..11 were zeroed by the caller
        A[_X, _U] = R00
        A[_X, _V] = R01
        A[_X, _W] = R02
        A[_Y, _U] = R10
        A[_Y, _V] = R11
        A[_Y, _W] = R12
        A[_Z, _U] = R20
        A[_Z, _V] = R21
        A[_Z, _W] = R22
        # d/dphi
        A[_X, _PHI] = (sp * sph + cp * sth * cph) * v + (sp * cph - cp * sph * sth) * w
        A[_Y, _PHI] = (-cp * sph + cph * sth * sp) * v + (-cp * cph - sth * sp * sph) * w
        A[_Z, _PHI] = cth * cph * v - cth * sph * w
        # d/dtheta
        A[_X, _THETA] = -cp * sth * u + cp * cth * sph * v + cp * cph * cth * w
        A[_Y, _THETA] = -sp * sth * u + sph * cth * sp * v + cth * sp * cph * w
        A[_Z, _THETA] = -cth * u - sth * sph * v - sth * cph * w
        # d/dpsi
        A[_X, _PSI] = -yd
        A[_Y, _PSI] = xd
        # Euler-angle rates
        A[_PHI, _P] = 1.0
        A[_PHI, _Q] = sph * tt
        A[_PHI, _R] = cph * tt
        A[_THETA, _Q] = cph
        A[_THETA, _R] = -sph
        A[_PSI, _Q] = sph / cth
        A[_PSI, _R] = cph / cth
        A[_PHI, _PHI] = cph * tt * q - sph * tt * r
        A[_THETA, _PHI] = -sph * q - cph * r
        A[_PSI, _PHI] = (cph * q - sph * r) / cth
        A[_PHI, _THETA] = (sph * q + cph * r) / (cth * cth)
        A[_PSI, _THETA] = (sph * q + cph * r) * sth / (cth * cth)


@kernel
def mass_inverse_into(c, M_RB, am_i, am_s, M, Minv):  # noqa: C901
    """Minv <- M(c)^-1 with M = M_RB + M_A and the added-mass coefficients taken from c (when
    added-mass coefficients are identified, M changes with theta). M (6x6) is scratch.
    Gauss-Jordan with partial pivoting, written out because a kernel cannot call
    np.linalg.inv (it allocates). Returns OK or ERR_M_SINGULAR."""
    for i in range(N_NU):
        for j in range(N_NU):
            M[i, j] = M_RB[i, j]
            Minv[i, j] = 1.0 if i == j else 0.0
    for a_ in range(am_i.shape[0]):
        M[am_i[a_, 0], am_i[a_, 1]] -= am_s[a_] * c[am_i[a_, 2]]
    scale = 0.0
    for i in range(N_NU):
        for j in range(N_NU):
            if not math.isfinite(M[i, j]):
                return ERR_NONFINITE
            scale = max(scale, abs(M[i, j]))
    for col in range(N_NU):
        piv = col
        for i in range(col + 1, N_NU):
            if abs(M[i, col]) > abs(M[piv, col]):
                piv = i
        if not abs(M[piv, col]) > 1e-12 * scale:
            return ERR_M_SINGULAR
        for j in range(N_NU):
            M[col, j], M[piv, j] = M[piv, j], M[col, j]
            Minv[col, j], Minv[piv, j] = Minv[piv, j], Minv[col, j]
        d = 1.0 / M[col, col]
        for j in range(N_NU):
            M[col, j] *= d
            Minv[col, j] *= d
        for i in range(N_NU):
            if i != col:
                f = M[i, col]
                for j in range(N_NU):
                    M[i, j] -= f * M[col, j]
                    Minv[i, j] -= f * Minv[col, j]
    return OK


@kernel
def state_derivative(x, ui, c, Minv, cm, want_jac, xdot, A, Bt, zz, dprod):  # noqa: C901
    """x_dot = f(x, u_in, c) (12,); with want_jac A = df/dx (12x12), Bt = df/dtheta (12xp).

    c (n_coef + 3,) are this evaluation's coefficient values and water current (NED, m/s) and
    Minv (6x6) M^-1 for them (mass_inverse_into); cm (CompiledModel) gives the vehicle's data,
    which entries of c are theta (p = len(cm.theta_idx)) and how the current enters (module
    docstring). zz (ZZ_LEN,) and dprod (n_coef + 3,) are scratch. Returns a status code
    (OK = 0).
    nu_dot = M^-1 F: F and dF/dx, dF/dtheta are summed into rows 0..5 of xdot, A, Bt and M^-1
    is applied in place at the end. Nothing is allocated (this runs four times per EKF step).
    With a current over ground the dynamics are evaluated at x_r = [nu_r, eta] (in zz) and
    current_terms.current_ground adds the rest.
    """
    par = cm.par
    theta_terms = cm.theta_terms
    am_i = cm.am_i
    am_s = cm.am_s
    theta_pos = cm.theta_pos
    p = cm.theta_idx.shape[0]
    current = cm.current
    for i in range(N_STATE):
        if not math.isfinite(x[i]):
            return ERR_NONFINITE
    for i in range(ui.shape[0]):     # N_INPUT, then one command per thruster
        if not math.isfinite(ui[i]):
            return ERR_NONFINITE
    if cm.held.shape[0] > 0:         # the model reads the held states as 0 (core/model/planar.py)
        xh = zz[ZZ_XH:ZZ_XH + N_STATE]
        held_at_zero(x, cm.held, xh)
        x = xh
    th = x[_THETA]
    cth = math.cos(th)
    if abs(cth) < COS_THETA_MIN:
        return ERR_THETA_90
    sth = math.sin(th)
    sph = math.sin(x[_PHI])
    cph = math.cos(x[_PHI])
    xv = x                   # the state the dynamics see: x, or x_r with a current over ground
    if current == CURRENT_GROUND:
        vc = c[cm.n_coef:cm.n_coef + N_CURRENT]
        for i in range(N_CURRENT):
            if not math.isfinite(vc[i]):
                return ERR_NONFINITE
        current_in_body(vc, sph, cph, sth, cth, x[_PSI], zz)
        xv = zz[ZZ_XR:ZZ_XR + N_STATE]
        for i in range(N_STATE):
            xv[i] = x[i]
        for i in range(3):
            xv[i] -= zz[ZZ_VCB + i]
    for i in range(N_NU):
        xdot[i] = 0.0
    if want_jac:
        for i in range(N_STATE):
            for j in range(N_STATE):
                A[i, j] = 0.0
            for j in range(p):
                Bt[i, j] = 0.0
    # factor vector z = zz[:NZ] (vehicle.FACTORS) and zd = zz[NZ:], d z_i / d x_(i mod 6)
    for i in range(N_NU):
        zz[i] = xv[i]
        zz[_Z_ABS + i] = abs(xv[i])
        zz[NZ + i] = 1.0
        zz[NZ + _Z_ABS + i] = _sign(xv[i])
    fl = par[P_FIN]
    for i in range(N_FINS):                  # fins saturated to +-fin limit (rad)
        zz[_Z_FINS + i] = min(max(ui[i], -fl), fl)
        zz[NZ + _Z_FINS + i] = 0.0
    zz[_Z_DB2] = zz[_Z_DBP] + zz[_Z_DBS]
    zz[NZ + _Z_DB2] = 0.0
    zz[Z_THRUST] = ui[_THRUST]               # N, measured (propulsion: measured_thrust)
    zz[NZ + Z_THRUST] = 0.0
    if par[P_SPEED_FACTOR] != 0.0:
        speed_factor(xv[_U], xv[_V], zz)
    n_rpm = min(max(ui[_N_RPM], -par[P_NMAX]), par[P_NMAX])
    st = _propulsion(xv[_U], n_rpm, par, zz, xdot, A, want_jac)
    if st != OK:
        return st
    kernel_at(cm.mono_addr)(c, zz, want_jac, xdot, A, dprod)
    if want_jac:
        for j in range(p):
            eq = theta_terms[j, 0]
            if eq >= 0:
                Bt[eq, j] += dprod[theta_terms[j, 1]]
    if cm.ca_i.shape[0] > 0:
        _added_mass_coriolis(xv, c, cm, want_jac, xdot, A, Bt)
    if cm.thr.shape[0] > 0:
        _thrusters(ui, c, cm, want_jac, xdot, Bt)
    _restoring(par, sph, cph, sth, cth, want_jac, xdot, A)
    _crossflow(par, xv[_V], xv[_W], xv[_Q], xv[_R], want_jac, xdot, A)
    _solve_vec(Minv, xdot)
    if want_jac:
        _solve_minv(Minv, A, N_STATE)
        _solve_minv(Minv, Bt, p)
        # added-mass coefficients in theta: d(M^-1 F)/da = -M^-1 (dM/da) nu_dot,
        # dM/da = -scale at (equation, column)
        for a_ in range(am_i.shape[0]):
            ci = am_i[a_, 2]
            if theta_pos[ci] >= 0:
                col = am_i[a_, 1]
                eq = am_i[a_, 0]
                for i in range(N_NU):
                    Bt[i, theta_pos[ci]] += Minv[i, eq] * am_s[a_] * xdot[col]
    if current == CURRENT_GROUND:
        current_ground(x, cm, want_jac, xdot, A, Bt, zz)
    for i in range(N_NU):
        if not math.isfinite(xdot[i]):
            return ERR_NONFINITE
    _kinematics(x, sph, cph, sth, cth, want_jac, xdot, A)
    if current == CURRENT_WATER:
        # the state holds nu_r: the position rate is J nu_r + v_c (NED)
        nc = cm.n_coef
        for k in range(N_CURRENT):
            xdot[_X + k] += c[nc + k]
            j = theta_pos[nc + k]
            if want_jac and j >= 0:
                Bt[_X + k, j] += 1.0
        for k in range(N_CURRENT):
            if not math.isfinite(xdot[_X + k]):
                return ERR_NONFINITE
    if cm.held.shape[0] > 0:
        hold_states(cm.held, want_jac, p, xdot, A, Bt)
    return OK


class Model:
    """A vehicle's model with a chosen set of parameters theta (by name).

    Parameters
    ----------
    vehicle : core.model.vehicle.Vehicle
    theta_names : sequence of str
        Coefficients whose values come from `theta` in calls (the others stay at the file's
        values), and any of the water current's components CURRENT_NAMES ('current_n',
        'current_e', 'current_d', m/s NED). theta is the coefficients in the given order, then
        the current's components in north, east, down order.
    mass_inverse : {'default', 'exact', 'mss_literal'}
        'default' uses the vehicle file's choice (NPS AUV II: MSS's literal 4-digit inverse).
    coefficient_values : array, optional
        Overrides the file's values for every coefficient (same order as vehicle.names).
    current : (3,) array, optional
        The water current (m/s, NED, where the water goes) for the components not in theta;
        zeros by default (still water).
    velocity_reference : {'ground', 'water'}
        What the state's u v w are (module docstring): over ground (DVL in bottom lock, the
        default) or through the water (water-track DVL).
    """

    def __init__(self, vehicle: Vehicle, theta_names: Sequence[str] = (),
                 mass_inverse: str = 'default', coefficient_values: ArrayLike | None = None,
                 current: ArrayLike | None = None, velocity_reference: str = 'ground') -> None:
        from auv_ident.core.errors import ConfigError
        self.vehicle = vehicle
        names = list(theta_names)
        cur = [n for n in CURRENT_NAMES if n in names]
        coef = [n for n in names if n not in CURRENT_NAMES]
        self.theta_names = [vehicle.names[vehicle.index(n)] for n in coef] + cur
        if len(set(self.theta_names)) != len(self.theta_names) or len(names) != len(
                self.theta_names):
            raise ConfigError(f'parameter listed twice in {names}')
        if velocity_reference not in VELOCITY_REFERENCES:
            raise ConfigError(f'velocity_reference = {velocity_reference!r}; use '
                              + ' or '.join(VELOCITY_REFERENCES))
        self.velocity_reference = velocity_reference
        n_coef = len(vehicle.coefficients)
        self.n_coef = n_coef
        self.p_coef = len(coef)                 # coefficients in theta (they come first)
        self.current_names = cur                # current components in theta (after them)
        self.theta_idx = np.array([vehicle.index(n) for n in coef]
                                  + [n_coef + CURRENT_NAMES.index(n) for n in cur],
                                  dtype=np.int64)
        self.p = len(self.theta_idx)
        self.theta_pos = -np.ones(n_coef + N_CURRENT, dtype=np.int64)
        self.theta_pos[self.theta_idx] = np.arange(self.p)
        self.c = (vehicle.values if coefficient_values is None
                  else np.array(coefficient_values, dtype=float)).copy()
        if self.c.shape != (n_coef,):
            raise ConfigError(f'coefficient_values: expected {n_coef} values, got '
                              f'{self.c.shape}')
        vc = np.zeros(N_CURRENT) if current is None else np.array(current, dtype=float)
        if vc.shape != (N_CURRENT,) or not np.all(np.isfinite(vc)):
            raise ConfigError(f'current must be 3 finite numbers (north, east, down m/s), got '
                              f'{current!r}')
        self.current = vc
        if cur or np.any(vc != 0.0):
            self.current_mode = (CURRENT_GROUND if velocity_reference == 'ground'
                                 else CURRENT_WATER)
        else:
            self.current_mode = CURRENT_NONE
        mi = vehicle.mass_inverse if mass_inverse == 'default' else mass_inverse
        if mi not in ('exact', 'mss_literal'):
            raise ConfigError(f'mass_inverse = {mass_inverse!r}; use default, exact or '
                              'mss_literal')
        if mi == 'mss_literal' and vehicle.Minv_literal is None:
            raise ConfigError(f'vehicle {vehicle.name!r} has no MSS literal inverse')
        am_theta = [n for n in coef if vehicle.coefficients[vehicle.index(n)].is_added_mass]
        if am_theta and mi == 'mss_literal':
            raise ConfigError(f'identifying added-mass coefficients {am_theta} changes M, but '
                              f'{vehicle.name} uses the fixed MSS literal inverse: choose '
                              '--mass-inverse exact')
        self.mass_inverse = mi
        self.recompute_minv = bool(am_theta)
        literal = vehicle.Minv_literal      # the file's 6x6 with mss_literal (vehicle.py)
        self.Minv = (literal.copy() if mi == 'mss_literal' and literal is not None
                     else np.linalg.inv(vehicle.mass_matrix(self.c)))
        # the vehicle's compiled monomial kernel, and per identified parameter its
        # [equation, index in c] (equation -1: added mass or current, which have no monomial)
        self.mono_addr = monomial_kernel(vehicle.terms_i, vehicle.terms_s).address
        self.held = vehicle.held
        self.theta_terms = np.array(
            [[-1 if ci >= n_coef or not vehicle.coefficients[ci].has_monomial
              else vehicle.coefficients[ci].equation, ci] for ci in self.theta_idx],
            dtype=np.int64).reshape(-1, 2)
        self.compiled = self._compiled(self._c_ext(None), self.theta_idx, self.theta_terms,
                                       self.theta_pos)

    def _compiled(self, c0: np.ndarray, theta_idx: np.ndarray, theta_terms: np.ndarray,
                  theta_pos: np.ndarray) -> CompiledModel:
        v = self.vehicle
        return CompiledModel(c0, theta_idx, v.par, self.mono_addr, theta_terms, v.am_i, v.am_s,
                             self.Minv, self.recompute_minv, v.M_RB, theta_pos,
                             self.current_mode, self.n_coef, self.held, v.thr, v.gain_idx,
                             v.lag_idx, v.lagged, v.ca_i, v.ca_s)

    def _c_ext(self, theta: ArrayLike | None) -> np.ndarray:
        """[coefficients (n_coef), current (3)] with theta (p,) in place (None: the model's)."""
        c = np.concatenate([self.c, self.current])
        if theta is not None and self.p:
            c[self.theta_idx] = theta
        return c

    @property
    def n_inputs(self) -> int:
        """Length of the input vector: N_INPUT, then one command per thruster."""
        return self.vehicle.n_inputs

    @property
    def n_inputs_lagged(self) -> int:
        """Length of the extended input vector of a lagged vehicle (u_in, then the delivered
        thrusts and their derivatives, core/model/thruster_lag.py)."""
        return self.vehicle.n_inputs + 4 * len(self.vehicle.thrusters)

    def compiled_fixed(self, theta: ArrayLike) -> CompiledModel:
        """CompiledModel of a filter over the 12 vehicle states only, with this model's
        parameters theta fixed at the given values (p,) (the batch refinement's candidates).
        M^-1 is recomputed at every step when theta holds added-mass coefficients."""
        return self._compiled(self._c_ext(theta), np.zeros(0, dtype=np.int64),
                              np.zeros((0, 2), dtype=np.int64),
                              -np.ones(self.n_coef + N_CURRENT, dtype=np.int64))

    @property
    def theta_file(self) -> np.ndarray:
        """The model's own values of the chosen parameters (p,): the vehicle file's
        coefficients and the current the model was given (the truth of a simulation, the
        prior of an identification)."""
        return self._c_ext(None)[self.theta_idx]

    # the former name, kept while branches that still read it are merged (analysis/,
    # identification/selection.py); the file's values are no truth of a measured run
    theta_true = theta_file

    def coefficients_with(self, theta: ArrayLike) -> np.ndarray:
        """The vehicle's coefficient values (n_coef,) with theta (p,) in place (a current in
        theta is left out)."""
        return self._c_ext(theta)[:self.n_coef].copy()

    def current_with(self, theta: ArrayLike) -> np.ndarray:
        """The water current (3,), m/s NED, with theta (p,) in place."""
        return self._c_ext(theta)[self.n_coef:].copy()

    def check(self, status: int, x: np.ndarray, ui: np.ndarray) -> None:
        if status != OK:
            raise DomainError(f'{STATUS_TEXT[status]} (x = {np.array2string(np.asarray(x))}, '
                              f'inputs = {np.array2string(np.asarray(ui))})')

    def _evaluate(self, x: ArrayLike, ui: ArrayLike, theta: ArrayLike | None,
                  want_jac: bool) -> tuple[int, np.ndarray, np.ndarray, Any, Any, Any]:
        x = np.ascontiguousarray(x, dtype=float)
        ui = np.ascontiguousarray(ui, dtype=float)
        if ui.shape != (self.n_inputs,) and not (
                self.vehicle.lagged and ui.shape == (self.n_inputs_lagged,)):
            # the kernel reads them unchecked
            raise DimensionError(f'inputs must have {self.n_inputs} entries (state.Input, then '
                                 f'one per thruster), got {ui.shape}')
        c = self._c_ext(theta)
        v = self.vehicle
        Minv = self.Minv
        if self.recompute_minv:
            Minv = np.empty((N_NU, N_NU))
            st = mass_inverse_into(c, v.M_RB, v.am_i, v.am_s, np.empty((N_NU, N_NU)), Minv)
            if st != OK:
                return st, x, ui, None, None, None
        xdot = np.empty(N_STATE)
        A = np.empty((N_STATE, N_STATE))
        Bt = np.empty((N_STATE, self.p))
        st = state_derivative(x, ui, c, Minv, self.compiled, want_jac, xdot, A, Bt,
                              np.empty(ZZ_LEN), np.empty(len(c)))
        return st, x, ui, xdot, A, Bt

    def f(self, x: ArrayLike, ui: ArrayLike, theta: ArrayLike | None = None) -> np.ndarray:
        """x_dot (12,) at state x (12,), inputs ui (n_inputs,: the 7 of state.Input, then the
        thruster commands; saturated inside), parameters theta."""
        st, x, ui, xdot, _, _ = self._evaluate(x, ui, theta, False)
        self.check(st, x, ui)
        return xdot

    def jacobians(self, x: ArrayLike, ui: ArrayLike,
                  theta: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x_dot, df/dx (12x12), df/dtheta (12xp))."""
        st, x, ui, xdot, A, Bt = self._evaluate(x, ui, theta, True)
        self.check(st, x, ui)
        return xdot, A, Bt

    def status(self, x: ArrayLike, ui: ArrayLike) -> int:
        """Status code of f at (x, ui): OK or one of ERR_* (STATUS_TEXT explains)."""
        return self._evaluate(x, ui, None, False)[0]
