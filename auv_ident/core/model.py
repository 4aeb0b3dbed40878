"""The 6-DOF AUV model x_dot = f(x, u_in, c) and its exact Jacobians, compiled with numba.

x = [u v w p q r x y z phi theta psi] (m/s, rad/s, m, rad; body FRD, world NED, ZYX Euler),
u_in = [delta_r delta_s delta_b delta_bp delta_bs n_rpm] (rad, rpm), saturated inside,
c = every coefficient of the vehicle file in the file's units (prime values if nondimensional).

    M nu_dot = F(nu, eta, delta, c),   eta_dot = J(eta) nu            (Fossen 2021, eq. 6.3)

F = sum of monomial terms (hydrodynamic/control coefficients and rigid-body Coriolis, see
vehicle.py) + restoring g(eta) + propulsion + cross-flow drag. The Jacobians are analytic:
each monomial is differentiated factor by factor, and propulsion, cross-flow, restoring and
kinematics have hand-derived derivatives (all checked against finite differences in the tests).
Why analytic and compiled: the EKF needs f and both Jacobians four times per RK4 step, tens of
thousands of times per second.

Domain: the kernels return a status code instead of NaN (see STATUS_TEXT).
"""
import math

import numpy as np
from numba import njit

from .errors import DomainError
from .vehicle import (COS_THETA_MIN, MAX_FACTORS, P_B, P_CF, P_CF_CY, P_CF_CZ, P_CF_N, P_FIN,
                      P_L, P_NMAX, P_PROP, P_PROP_A, P_PROP_B, P_PROP_C, P_RHO, P_U_MIN, P_W,
                      P_XB, P_XG, P_YB, P_YG, P_ZB, P_ZG)

NZ = 19          # length of the factor vector z (vehicle.FACTORS)
Z_EPS = 18       # index of the propeller epsilon in z

OK, ERR_NONFINITE, ERR_U_ZERO, ERR_EPS_COMPLEX, ERR_THETA_90 = 0, 1, 2, 3, 4
STATUS_TEXT = {
    ERR_NONFINITE: 'NaN or Inf in the state, the inputs or the coefficients',
    ERR_U_ZERO: 'surge speed u is ~0: the Healey-Lienard propeller ratio eta = 0.012 n/u is '
                'singular (|u| < 1e-6 m/s)',
    ERR_EPS_COMPLEX: 'n and u of opposite sign with |eta| too large: the propeller epsilon '
                     'would be complex (Ct < -1)',
    ERR_THETA_90: 'pitch theta is at +-90 deg: the Euler-angle kinematics are singular',
}


@njit(cache=True)
def saturate(u_in, par, out):
    """Fins to +-fin limit (rad), shaft speed to +-n limit (rpm); out may alias u_in."""
    fl = par[P_FIN]
    for i in range(5):
        out[i] = min(max(u_in[i], -fl), fl)
    nl = par[P_NMAX]
    out[5] = min(max(u_in[5], -nl), nl)


@njit(cache=True)
def _sign(a):
    return 1.0 if a > 0.0 else (-1.0 if a < 0.0 else 0.0)


@njit(cache=True)
def nu_dot_and_jac(x, ui, c, par, terms_i, terms_s, am_i, am_s, Minv, recompute_minv, M_RB,
                   theta_pos, p, want_jac, nudot, A6, B6):
    """nu_dot = M^-1 F; with want_jac, A6 = d nu_dot / dx (6x12), B6 = d nu_dot / d theta (6xp).

    theta_pos[ci] is the position of coefficient ci in theta, or -1. Returns a status code.
    """
    for i in range(12):
        if not math.isfinite(x[i]):
            return ERR_NONFINITE
    for i in range(6):
        if not math.isfinite(ui[i]):
            return ERR_NONFINITE
    phi = x[9]
    th = x[10]
    cth = math.cos(th)
    if abs(cth) < COS_THETA_MIN:
        return ERR_THETA_90
    d = np.empty(6)
    saturate(ui, par, d)
    u = x[0]
    v = x[1]
    w = x[2]
    q = x[4]
    r = x[5]
    rho = par[P_RHO]
    L = par[P_L]

    z = np.zeros(NZ)
    dz = np.zeros(NZ)    # dz/du only matters for eps; velocity factors handled by index
    for i in range(6):
        z[i] = x[i]
        z[6 + i] = abs(x[i])
    z[12] = d[0]
    z[13] = d[1]
    z[14] = d[2]
    z[15] = d[3]
    z[16] = d[4]
    z[17] = d[3] + d[4]

    F = np.zeros(6)
    dF = np.zeros((6, 12))     # dF/dx (x: 12 states)
    G = np.zeros((6, p))       # dF/dtheta

    # --- propulsion
    pm = int(par[P_PROP])
    n_rad = d[5] * 2.0 * math.pi / 60.0
    if pm == 1:   # Healey & Lienard (MSS npsauv.m)
        if abs(u) < par[P_U_MIN]:
            return ERR_U_ZERO
        Cd0 = par[P_PROP_A]
        a = par[P_PROP_B] * n_rad                 # eta = a / u
        eta = a / u
        ee = abs(eta) * eta
        h2 = 0.5 * rho * L * L
        # u^2 Cd0 (|eta| eta - 1) = Cd0 (|a| a sign(u) - u^2): thrust does not depend on u
        F[0] += h2 * u * u * Cd0 * (ee - 1.0)
        dF[0, 0] += h2 * Cd0 * (-2.0 * u)
        ctg = par[P_PROP_C] * L * L / 2.0
        Ct = ctg * ee
        Ct1 = ctg
        if Ct + 1.0 < 0.0:
            return ERR_EPS_COMPLEX
        den = math.sqrt(Ct1 + 1.0) - 1.0
        sgn = _sign(n_rad) / _sign(u)
        sq = math.sqrt(Ct + 1.0)
        z[Z_EPS] = -1.0 + sgn * (sq - 1.0) / den
        dee_du = -2.0 * abs(a) * a / (abs(u) ** 3)
        dz[Z_EPS] = sgn * (0.5 / sq) * ctg * dee_du / den
    elif pm == 2:  # thrust and torque quadratic in n (Prestero's constant Xprop, Kprop at n0)
        s = d[5] / par[P_PROP_C]
        F[0] += par[P_PROP_A] * s * abs(s)
        F[3] += par[P_PROP_B] * s * abs(s)

    # --- monomial terms: coefficients and rigid-body Coriolis
    nt = terms_i.shape[0]
    for t in range(nt):
        eq = terms_i[t, 0]
        ci = terms_i[t, 1]
        k = terms_s[t]
        if ci >= 0:
            k = k * c[ci]
        prod = 1.0
        nf = 0
        for j in range(MAX_FACTORS):
            fj = terms_i[t, 2 + j]
            if fj < 0:
                break
            prod *= z[fj]
            nf += 1
        F[eq] += k * prod
        if want_jac:
            if ci >= 0 and theta_pos[ci] >= 0:
                G[eq, theta_pos[ci]] += terms_s[t] * prod
            for j in range(nf):
                fj = terms_i[t, 2 + j]
                if fj >= 12 and fj != Z_EPS:
                    continue       # fins: inputs, not states
                rest = k
                for jj in range(nf):
                    if jj != j:
                        rest *= z[terms_i[t, 2 + jj]]
                if fj < 6:
                    dF[eq, fj] += rest
                elif fj < 12:
                    dF[eq, fj - 6] += rest * _sign(x[fj - 6])
                else:
                    dF[eq, 0] += rest * dz[Z_EPS]

    # --- restoring forces g(eta), sign flipped to the right-hand side
    W = par[P_W]
    B = par[P_B]
    sph = math.sin(phi)
    cph = math.cos(phi)
    sth = math.sin(th)
    WB = W - B
    gx = par[P_XG] * W - par[P_XB] * B
    gy = par[P_YG] * W - par[P_YB] * B
    gz = par[P_ZG] * W - par[P_ZB] * B
    F[0] += -WB * sth
    F[1] += WB * cth * sph
    F[2] += WB * cth * cph
    F[3] += gy * cth * cph - gz * cth * sph
    F[4] += -gz * sth - gx * cth * cph
    F[5] += gx * cth * sph + gy * sth
    if want_jac:
        dF[0, 10] += -WB * cth
        dF[1, 9] += WB * cth * cph
        dF[1, 10] += -WB * sth * sph
        dF[2, 9] += -WB * cth * sph
        dF[2, 10] += -WB * sth * cph
        dF[3, 9] += -gy * cth * sph - gz * cth * cph
        dF[3, 10] += -gy * sth * cph + gz * sth * sph
        dF[4, 9] += gx * cth * sph
        dF[4, 10] += -gz * cth + gx * sth * cph
        dF[5, 9] += gx * cth * cph
        dF[5, 10] += -gx * sth * sph + gy * cth

    # --- cross-flow drag, MSS classic strip sum (skipped when v = w = 0, as MSS does)
    if int(par[P_CF]) == 1 and (v * v + w * w) != 0.0:
        ns = int(par[P_CF_N])
        dx = L / (ns - 1)
        cy = par[P_CF_CY]
        cz = par[P_CF_CZ]
        Sy = 0.0
        Sz = 0.0
        Sm = 0.0
        Sn = 0.0
        # derivatives of the sums w.r.t. (v, w, q, r)
        dSy = np.zeros(4)
        dSz = np.zeros(4)
        dSm = np.zeros(4)
        dSn = np.zeros(4)
        for i in range(ns):
            xl = -L / 2.0 + i * dx
            aa = v + xl * r
            bb = w - xl * q
            U = math.sqrt(aa * aa + bb * bb)
            if U == 0.0:
                continue          # integrand -> 0 as U -> 0 (it is O(U)); avoid 0/0
            N_ = cy * aa * aa + cz * bb * bb
            g = N_ / U
            cc = w + xl * q       # '+' as in MSS (sic)
            Sy += dx * g * aa
            Sz += dx * g * bb
            Sm += dx * g * cc * xl
            Sn += dx * g * aa * xl
            if want_jac:
                ga = 2.0 * cy * aa / U - N_ * aa / U ** 3
                gb = 2.0 * cz * bb / U - N_ * bb / U ** 3
                # d(a)/d(v,w,q,r) = (1, 0, 0, xl); d(b)/d(...) = (0, 1, -xl, 0)
                da = (1.0, 0.0, 0.0, xl)
                db = (0.0, 1.0, -xl, 0.0)
                dc = (0.0, 1.0, xl, 0.0)
                for m in range(4):
                    dg = ga * da[m] + gb * db[m]
                    dSy[m] += dx * (dg * aa + g * da[m])
                    dSz[m] += dx * (dg * bb + g * db[m])
                    dSm[m] += dx * (dg * cc + g * dc[m]) * xl
                    dSn[m] += dx * (dg * aa + g * da[m]) * xl
        h = 0.5 * rho
        F[1] -= h * Sy
        F[2] += h * Sz
        F[4] -= h * Sm
        F[5] -= h * Sn
        if want_jac:
            cols = (1, 2, 4, 5)
            for m in range(4):
                dF[1, cols[m]] -= h * dSy[m]
                dF[2, cols[m]] += h * dSz[m]
                dF[4, cols[m]] -= h * dSm[m]
                dF[5, cols[m]] -= h * dSn[m]

    # --- nu_dot = M^-1 F
    Mi = Minv
    if recompute_minv:
        M = M_RB.copy()
        for a_ in range(am_i.shape[0]):
            M[am_i[a_, 0], am_i[a_, 1]] -= am_s[a_] * c[am_i[a_, 2]]
        Mi = np.linalg.inv(M)
    for i in range(6):
        s = 0.0
        for j in range(6):
            s += Mi[i, j] * F[j]
        nudot[i] = s
    if want_jac:
        for i in range(6):
            for j in range(12):
                s = 0.0
                for kk in range(6):
                    s += Mi[i, kk] * dF[kk, j]
                A6[i, j] = s
            for j in range(p):
                s = 0.0
                for kk in range(6):
                    s += Mi[i, kk] * G[kk, j]
                B6[i, j] = s
        # added-mass coefficients in theta: d(M^-1 F)/da = -M^-1 (dM/da) nu_dot,
        # dM/da = -scale at (equation, column)
        for a_ in range(am_i.shape[0]):
            ci = am_i[a_, 2]
            if theta_pos[ci] >= 0:
                col = am_i[a_, 1]
                eq = am_i[a_, 0]
                for i in range(6):
                    B6[i, theta_pos[ci]] += Mi[i, eq] * am_s[a_] * nudot[col]
    for i in range(6):
        if not math.isfinite(nudot[i]):
            return ERR_NONFINITE
    return OK


@njit(cache=True)
def kinematics_and_jac(x, want_jac, etadot, Ak):
    """eta_dot = J(eta) nu (Fossen eq. 2.40, ZYX); Ak = d eta_dot / dx (6x12)."""
    u = x[0]
    v = x[1]
    w = x[2]
    p = x[3]
    q = x[4]
    r = x[5]
    phi = x[9]
    th = x[10]
    psi = x[11]
    cf = math.cos(phi)
    sf = math.sin(phi)
    ct = math.cos(th)
    st = math.sin(th)
    cp = math.cos(psi)
    sp = math.sin(psi)
    tt = st / ct
    R00 = cp * ct
    R01 = -sp * cf + cp * st * sf
    R02 = sp * sf + cp * cf * st
    R10 = sp * ct
    R11 = cp * cf + sf * st * sp
    R12 = -cp * sf + st * sp * cf
    R20 = -st
    R21 = ct * sf
    R22 = ct * cf
    xd = R00 * u + R01 * v + R02 * w
    yd = R10 * u + R11 * v + R12 * w
    zd = R20 * u + R21 * v + R22 * w
    etadot[0] = xd
    etadot[1] = yd
    etadot[2] = zd
    etadot[3] = p + sf * tt * q + cf * tt * r
    etadot[4] = cf * q - sf * r
    etadot[5] = (sf * q + cf * r) / ct
    if want_jac:
        for i in range(6):
            for j in range(12):
                Ak[i, j] = 0.0
        Ak[0, 0] = R00
        Ak[0, 1] = R01
        Ak[0, 2] = R02
        Ak[1, 0] = R10
        Ak[1, 1] = R11
        Ak[1, 2] = R12
        Ak[2, 0] = R20
        Ak[2, 1] = R21
        Ak[2, 2] = R22
        # d/dphi
        Ak[0, 9] = (sp * sf + cp * st * cf) * v + (sp * cf - cp * sf * st) * w
        Ak[1, 9] = (-cp * sf + cf * st * sp) * v + (-cp * cf - st * sp * sf) * w
        Ak[2, 9] = ct * cf * v - ct * sf * w
        # d/dtheta
        Ak[0, 10] = -cp * st * u + cp * ct * sf * v + cp * cf * ct * w
        Ak[1, 10] = -sp * st * u + sf * ct * sp * v + ct * sp * cf * w
        Ak[2, 10] = -ct * u - st * sf * v - st * cf * w
        # d/dpsi
        Ak[0, 11] = -yd
        Ak[1, 11] = xd
        # Euler-angle rates
        Ak[3, 3] = 1.0
        Ak[3, 4] = sf * tt
        Ak[3, 5] = cf * tt
        Ak[4, 4] = cf
        Ak[4, 5] = -sf
        Ak[5, 4] = sf / ct
        Ak[5, 5] = cf / ct
        Ak[3, 9] = cf * tt * q - sf * tt * r
        Ak[4, 9] = -sf * q - cf * r
        Ak[5, 9] = (cf * q - sf * r) / ct
        Ak[3, 10] = (sf * q + cf * r) / (ct * ct)
        Ak[5, 10] = (sf * q + cf * r) * st / (ct * ct)


@njit(cache=True)
def state_derivative(x, ui, c, par, terms_i, terms_s, am_i, am_s, Minv, recompute_minv, M_RB,
                     theta_pos, p, want_jac, xdot, A, Bt):
    """x_dot = f(x, u_in, c) (12,); with want_jac A = df/dx (12x12), Bt = df/dtheta (12xp).

    Returns a status code (OK = 0).
    """
    A6 = np.zeros((6, 12))
    B6 = np.zeros((6, p))
    nudot = np.empty(6)
    st = nu_dot_and_jac(x, ui, c, par, terms_i, terms_s, am_i, am_s, Minv, recompute_minv,
                        M_RB, theta_pos, p, want_jac, nudot, A6, B6)
    if st != OK:
        return st
    etadot = np.empty(6)
    Ak = np.zeros((6, 12))
    kinematics_and_jac(x, want_jac, etadot, Ak)
    for i in range(6):
        xdot[i] = nudot[i]
        xdot[6 + i] = etadot[i]
    if want_jac:
        for i in range(6):
            for j in range(12):
                A[i, j] = A6[i, j]
                A[6 + i, j] = Ak[i, j]
            for j in range(p):
                Bt[i, j] = B6[i, j]
                Bt[6 + i, j] = 0.0
    return OK


class Model:
    """A vehicle's model with a chosen set of coefficients theta (by name).

    Parameters
    ----------
    vehicle : core.vehicle.Vehicle
    theta_names : sequence of str
        Coefficients whose values come from `theta` in calls (the others stay at the file's
        values). Order defines theta.
    mass_inverse : {'default', 'exact', 'mss_literal'}
        'default' uses the vehicle file's choice (NPS AUV II: MSS's literal 4-digit inverse).
    coefficient_values : array, optional
        Overrides the file's values for every coefficient (same order as vehicle.names).
    """

    def __init__(self, vehicle, theta_names=(), mass_inverse='default', coefficient_values=None):
        from .errors import ConfigError
        self.vehicle = vehicle
        self.theta_names = [vehicle.names[vehicle.index(n)] for n in theta_names]
        if len(set(self.theta_names)) != len(self.theta_names):
            raise ConfigError(f'coefficient listed twice in {list(theta_names)}')
        self.theta_idx = np.array([vehicle.index(n) for n in theta_names], dtype=np.int64)
        self.p = len(self.theta_idx)
        self.theta_pos = -np.ones(len(vehicle.coefficients), dtype=np.int64)
        self.theta_pos[self.theta_idx] = np.arange(self.p)
        self.c = (vehicle.values if coefficient_values is None
                  else np.array(coefficient_values, dtype=float)).copy()
        mi = vehicle.mass_inverse if mass_inverse == 'default' else mass_inverse
        if mi not in ('exact', 'mss_literal'):
            raise ConfigError(f'mass_inverse = {mass_inverse!r}; use default, exact or '
                              'mss_literal')
        if mi == 'mss_literal' and vehicle.Minv_literal is None:
            raise ConfigError(f'vehicle {vehicle.name!r} has no MSS literal inverse')
        am_theta = [n for n in self.theta_names
                    if vehicle.coefficients[vehicle.index(n)].is_added_mass]
        if am_theta and mi == 'mss_literal':
            raise ConfigError(f'identifying added-mass coefficients {am_theta} changes M, but '
                              f'{vehicle.name} uses the fixed MSS literal inverse: choose '
                              '--mass-inverse exact')
        self.mass_inverse = mi
        self.recompute_minv = bool(am_theta)
        self.Minv = (vehicle.Minv_literal.copy() if mi == 'mss_literal'
                     else np.linalg.inv(vehicle.mass_matrix(self.c)))
        self.args = (vehicle.par, vehicle.terms_i, vehicle.terms_s, vehicle.am_i, vehicle.am_s,
                     self.Minv, self.recompute_minv, vehicle.M_RB, self.theta_pos, self.p)

    @property
    def theta_true(self):
        """The file's values of the chosen coefficients."""
        return self.c[self.theta_idx].copy()

    def coefficients_with(self, theta):
        c = self.c.copy()
        if self.p:
            c[self.theta_idx] = theta
        return c

    def check(self, status, x, ui):
        if status != OK:
            raise DomainError(f'{STATUS_TEXT[status]} (x = {np.array2string(np.asarray(x))}, '
                              f'inputs = {np.array2string(np.asarray(ui))})')

    def f(self, x, ui, theta=None):
        """x_dot (12,) at state x (12,), inputs ui (6,) (saturated inside), coefficients theta."""
        x = np.ascontiguousarray(x, dtype=float)
        ui = np.ascontiguousarray(ui, dtype=float)
        c = self.c if theta is None else self.coefficients_with(theta)
        xdot = np.empty(12)
        st = state_derivative(x, ui, c, *self.args, False, xdot, np.empty((12, 12)),
                              np.empty((12, self.p)))
        self.check(st, x, ui)
        return xdot

    def jacobians(self, x, ui, theta=None):
        """(x_dot, df/dx (12x12), df/dtheta (12xp))."""
        x = np.ascontiguousarray(x, dtype=float)
        ui = np.ascontiguousarray(ui, dtype=float)
        c = self.c if theta is None else self.coefficients_with(theta)
        xdot = np.empty(12)
        A = np.empty((12, 12))
        Bt = np.empty((12, self.p))
        st = state_derivative(x, ui, c, *self.args, True, xdot, A, Bt)
        self.check(st, x, ui)
        return xdot, A, Bt

    def status(self, x, ui):
        """Status code of f at (x, ui): OK or one of ERR_* (STATUS_TEXT explains)."""
        xdot = np.empty(12)
        return state_derivative(np.ascontiguousarray(x, dtype=float),
                                np.ascontiguousarray(ui, dtype=float), self.c, *self.args,
                                False, xdot, np.empty((12, 12)), np.empty((12, self.p)))
