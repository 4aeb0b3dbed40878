"""``export --format python``: the identified model as a self-contained numpy module.

For users who work in the MSS / PythonVehicleSimulator style: one file with the state
derivative f(x, u_in) and an RK4 ``simulate`` helper, importing nothing but numpy and math.
The module is generated from the vehicle's own term table, so it is our model written out, not
a fit: every monomial term (coefficient times its factors, the rigid-body Coriolis terms), the
propulsion model (Healey-Lienard or quadratic in n), the cross-flow strip sum, the restoring
forces, the Euler kinematics, the held degrees of freedom of a planar vehicle and M^-1 as the
model forms it (MSS's literal inverse for NPS AUV II), with every constant written to the last
bit (repr). A thruster vehicle's thrust curves and configuration (core/model/thrusters.py) are
written out too, their commands after the seven inputs. The exported f equals
core/model/hydrodynamics.py's to rounding (test/analysis/test_export_python.py: < 1e-6
relative along held-out manoeuvres of every shipped vehicle, measured ~1e-13).

A water current constant in NED is an argument of f and simulate (the identified one, if any,
is IDENTIFIED_CURRENT), with the velocities over ground or through the water, as our model
takes it. Not in the file: the sensors, the identification's uncertainty (the header gives
each identified coefficient's 1-sigma).
"""
import datetime
import math
import textwrap

import numpy as np

from auv_ident.analysis.export_fossen import identified_values
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.monomials import Z_EPS, Z_SPEED
from auv_ident.core.model.state import INPUT_NAMES, STATE_NAMES
from auv_ident.core.model.vehicle import (
    COS_THETA_MIN,
    EQUATIONS,
    FACTORS,
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
    P_U_MIN,
    P_W,
    P_XB,
    P_XG,
    P_YB,
    P_YG,
    P_ZB,
    P_ZG,
)

# the Python name of each factor of vehicle.FACTORS inside the generated f
FACTOR_CODE = {'u': 'u', 'v': 'v', 'w': 'w', 'p': 'p', 'q': 'q', 'r': 'r',
               '|u|': 'au', '|v|': 'av', '|w|': 'aw', '|p|': 'ap', '|q|': 'aq', '|r|': 'ar',
               'dr': 'dr', 'ds': 'ds', 'db': 'db', 'dbp': 'dbp', 'dbs': 'dbs',
               'db2': 'db2', 'eps': 'eps', 'U': 'U', 'thrust': 'thrust'}


def _r(x):
    """The shortest literal that reads back as exactly this float; no -0.0; an infinite
    limit (none given) as math.inf."""
    x = float(x) + 0.0
    if math.isinf(x):
        return 'math.inf' if x > 0 else '-math.inf'
    return repr(x)


def _matrix(name, a):
    rows = ',\n'.join('    [' + ', '.join(_r(x) for x in row) + ']' for row in np.asarray(a))
    return f'{name} = np.array([\n{rows},\n])'


def identified_model(saved):
    """Our Model (core/model/hydrodynamics.py) of a SavedModel: the vehicle file with the
    identified values in place, M^-1 formed as the identification formed it."""
    return Model(saved.vehicle, (), mass_inverse=saved.mass_inverse,
                 coefficient_values=identified_values(saved))


def _term_lines(v, c):
    """The monomial terms as source lines `F[eq] += k * z * z`, in the table's order (the
    coefficient's name as a comment; rigid-body terms so named)."""
    lines = []
    for row, s in zip(v.terms_i, v.terms_s):
        eq, ci = int(row[0]), int(row[1])
        k = float(s) * float(c[ci]) if ci >= 0 else float(s)
        if k == 0.0:
            continue
        fs = [FACTOR_CODE[FACTORS[int(f)]] for f in row[2:] if f >= 0]
        what = v.coefficients[ci].name if ci >= 0 else 'rigid-body Coriolis'
        lines.append(f'    F[{eq}] += {_r(k)}' + ''.join(f' * {f}' for f in fs)
                     + f'   # {EQUATIONS[eq]}: {what}')
    return lines


def _coriolis_lines(v, c):
    """The added-mass Coriolis terms the model computes from the added mass (a vehicle file's
    `added_mass_coriolis: fossen`, vehicle.ca_i) as source lines, in the kernel's order."""
    lines = []
    for (eq, ci, a, b), s in zip(getattr(v, 'ca_i', ()), getattr(v, 'ca_s', ())):
        lines.append(f'    F[{int(eq)}] += {_r(float(s) * float(c[int(ci)]))} * '
                     f'{FACTOR_CODE[FACTORS[int(a)]]} * {FACTOR_CODE[FACTORS[int(b)]]}'
                     f'   # {EQUATIONS[int(eq)]}: added-mass Coriolis of '
                     f'{v.coefficients[int(ci)].name}')
    return lines


def _used_factors(v):
    return {FACTORS[int(f)] for row in v.terms_i for f in row[2:] if f >= 0}


def _propulsion_lines(par):
    pm = int(par[P_PROP])
    if pm == 1:
        return [
            '    # Healey & Lienard propeller as in MSS npsauv.m: eta = eta_gain n / u',
            '    # (n rad/s), X += (rho/2) L^2 Cd0 u^2 (|eta| eta - 1),',
            '    # eps = -1 + sign(n) / sign(u) (sqrt(Ct + 1) - 1)',
            '    #       / (sqrt(Ct_gain L^2 / 2 + 1) - 1),',
            '    # Ct = Ct_gain L^2 |eta| eta / 2',
            f'    if abs(u) < {_r(par[P_U_MIN])}:',
            "        raise ValueError('u ~ 0: the Healey-Lienard propeller is singular there')",
            '    n_rad = n_rpm * 2.0 * math.pi / 60.0',
            f'    eta = {_r(par[P_PROP_B])} * n_rad / u',
            '    ee = abs(eta) * eta',
            f'    F[0] += {_r(0.5 * par[P_RHO] * par[P_L] * par[P_L])} * u * u * '
            f'{_r(par[P_PROP_A])} * (ee - 1.0)',
            f'    ct = {_r(par[P_PROP_C] * par[P_L] * par[P_L] / 2.0)} * ee',
            '    if ct + 1.0 < 0.0:',
            "        raise ValueError('n and u of opposite sign: the propeller epsilon would be "
            "complex')",
            '    eps = -1.0 + _sign(n_rad) / _sign(u) * (math.sqrt(ct + 1.0) - 1.0) / '
            f'{_r(np.sqrt(par[P_PROP_C] * par[P_L] * par[P_L] / 2.0 + 1.0) - 1.0)}']
    if pm == 2:
        return ['    # propeller thrust and torque quadratic in n (constant at n0, Prestero)',
                f'    s = n_rpm / {_r(par[P_PROP_C])}',
                f'    F[0] += {_r(par[P_PROP_A])} * s * abs(s)',
                f'    F[3] += {_r(par[P_PROP_B])} * s * abs(s)']
    return []


def _crossflow_lines(par):
    if int(par[P_CF]) != 1:
        return []
    L, ns = float(par[P_L]), int(par[P_CF_N])
    dx = L / (ns - 1)
    xl = [-L / 2.0 + i * dx for i in range(ns)]
    return [
        '    # cross-flow drag, MSS classic strip sum (skipped at v = w = 0, as MSS): per strip',
        '    # a = v + x r, b = w - x q, g = (Cy a^2 + Cz b^2) / sqrt(a^2 + b^2);',
        '    # Y -= rho/2 dx sum g a, Z += .. g b, M -= .. g (w + x q) x (sic, as MSS),',
        '    # N -= .. g a x',
        '    if v * v + w * w != 0.0:',
        f'        xs = np.array([{", ".join(_r(x) for x in xl)}])',
        '        a = v + xs * r',
        '        b = w - xs * q',
        '        U2 = a * a + b * b',
        '        iU = np.divide(1.0, np.sqrt(U2), out=np.zeros_like(U2), where=U2 > 0.0)',
        f'        g = ({_r(par[P_CF_CY])} * a * a + {_r(par[P_CF_CZ])} * b * b) * iU',
        f'        h = {_r(0.5 * par[P_RHO] * dx)}',
        '        F[1] -= h * np.sum(g * a)',
        '        F[2] += h * np.sum(g * b)',
        '        F[4] -= h * np.sum(g * (w + xs * q) * xs)',
        '        F[5] -= h * np.sum(g * a * xs)']


def _restoring_lines(par):
    W, B = float(par[P_W]), float(par[P_B])
    gx = par[P_XG] * W - par[P_XB] * B
    gy = par[P_YG] * W - par[P_YB] * B
    gz = par[P_ZG] * W - par[P_ZB] * B
    WB = W - B
    return [
        '    # restoring forces -g(eta) (Fossen 2021, eq. 4.6): W - B and r_G W - r_B B',
        f'    F[0] += {_r(-WB)} * sth',
        f'    F[1] += {_r(WB)} * cth * sph',
        f'    F[2] += {_r(WB)} * cth * cph',
        f'    F[3] += {_r(gy)} * cth * cph - {_r(gz)} * cth * sph',
        f'    F[4] += -{_r(gz)} * sth - {_r(gx)} * cth * cph',
        f'    F[5] += {_r(gx)} * cth * sph + {_r(gy)} * sth']


def _thruster_lines(v, c):
    """The thrusters (core/model/thrusters.py) as data and their steady wrench in F: per
    equation the forward and the reverse thrusts' parts, times a thrust gain where the file
    has one (a vehicle file's `thrusters` multiplier)."""
    ts = tuple(getattr(v, 'thrusters', ()))
    if not ts:
        return [], []
    data = ['# thrusters (core/model/thrusters.py): name, command unit, neutral, command_max,',
            '# dead_band, forward (a1, a2), reverse (a1, a2), thrust_max_forward,',
            '# thrust_max_reverse (N), configuration column [d; r x d] (FRD), and the table',
            '# (commands, thrusts N, slopes N per unit) or None (the polynomial)',
            'THRUSTERS = (']
    for t in ts:
        data.append(f'    ({t.name!r}, {t.command!r}, {_r(t.neutral)}, {_r(t.command_max)}, '
                    f'{_r(t.dead_band)}, ({_r(t.forward[0])}, {_r(t.forward[1])}), '
                    f'({_r(t.reverse[0])}, {_r(t.reverse[1])}), {_r(t.thrust_max_forward)}, '
                    f'{_r(t.thrust_max_reverse)},')
        data.append('     np.array([' + ', '.join(_r(x) for x in t.column) + ']),')
        data.append('     None),' if t.table is None else
                    '     np.array([' + ',\n               '.join(
                        '[' + ', '.join(_r(x) for x in row) + ']' for row in t.table) + '])),')
    data.append(')')
    gain_idx = getattr(v, 'gain_idx', None)
    gains = np.ones((2, 6))
    if gain_idx is not None:
        for side in range(2):
            for e in range(6):
                if gain_idx[side, e] >= 0:
                    gains[side, e] = c[gain_idx[side, e]]
    data.append(_matrix('THRUST_GAIN', gains) + '   # [forward, reverse] x [X..N]')
    code = ['    # thrusters: their commands follow the seven inputs, in THRUSTERS order',
            '    tau_f = np.zeros(6)',
            '    tau_r = np.zeros(6)',
            '    for i, th in enumerate(THRUSTERS):',
            f'        f_i = thruster_force(i, u_in[{len(INPUT_NAMES)} + i])',
            '        if f_i > 0.0:',
            '            tau_f += th[9] * f_i',
            '        else:',
            '            tau_r += th[9] * f_i',
            '    F += THRUST_GAIN[0] * tau_f + THRUST_GAIN[1] * tau_r']
    return data, code


THRUST_FUNCTION = '''

def thruster_force(i, command):
    """Steady thrust (N, along the thruster's direction) of THRUSTERS[i] for its command (in
    its unit): dead band around neutral, then a1 e + a2 e^2 (forward) or a1 e - a2 e^2
    (reverse) of the command's distance e beyond it, saturated; or its table's monotone cubic
    Hermite curve (PCHIP) at the command, the table's end values beyond its ends."""
    _, unit, neutral, cmax, dead, fwd, rev, fmax_f, fmax_r, _, table = THRUSTERS[i]
    if unit == 'force':
        f = float(command)
    elif table is not None:
        x, fs, d = table
        c = min(max(float(command), neutral - cmax), neutral + cmax)
        if c <= x[0]:
            f = fs[0]
        elif c >= x[-1]:
            f = fs[-1]
        else:
            k = int(np.searchsorted(x, c, side='right')) - 1
            h = x[k + 1] - x[k]
            t = (c - x[k]) / h
            t2, t3 = t * t, t * t * t
            f = ((2 * t3 - 3 * t2 + 1) * fs[k] + (t3 - 2 * t2 + t) * h * d[k]
                 + (-2 * t3 + 3 * t2) * fs[k + 1] + (t3 - t2) * h * d[k + 1])
    else:
        e = min(max(float(command) - neutral, -cmax), cmax)
        if abs(e) <= dead:
            return 0.0
        if e > 0.0:
            e -= dead
            f = fwd[0] * e + fwd[1] * e * e
        else:
            e += dead
            f = rev[0] * e - rev[1] * e * e
    return min(max(f, -fmax_r), fmax_f)
'''


def _header(saved, model, day):
    v = saved.vehicle
    ident = ', '.join(f'{n} = {float(e)!r} (1-sigma {float(s):.3g})'
                      for n, e, s in zip(saved.names, saved.estimate, saved.std))
    held = [STATE_NAMES[i] for i in model.held]
    ts = tuple(getattr(v, 'thrusters', ()))
    inputs = list(INPUT_NAMES) + [f'{t.name} ({t.command})' for t in ts]
    cur = ('' if saved.current is None else
           'The identification also estimated a water current (north, east, down) = '
           f'{", ".join(f"{x:.4g}" for x in saved.current)} m/s: IDENTIFIED_CURRENT, for f\'s '
           "and simulate's current argument (still water without it).")
    lines = [
        f'{v.name}: the identified model, exported by `python -m auv_ident export` on {day}',
        *textwrap.wrap(f'from {saved.path} (vehicle file {v.path}; {v.title}).', 88),
        *textwrap.wrap(f"Identified: {ident}. Every other coefficient is the vehicle file's.",
                       88),
        '',
        "Generated from the vehicle's term table: our model written out term by term, not a",
        'fit. Needs numpy only. Units SI (m, s, kg, N, rad; the shaft speed in rpm).',
        'Frames: body FRD (x forward, y starboard, z down), world NED, ZYX Euler angles',
        '(Fossen 2021). Signs: SNAME (Y_v < 0 is damping; a positive rudder deflection dr',
        'turns the vehicle as the vehicle file defines).',
        '',
        'State x = [u v w p q r x y z phi theta psi]: body velocities (m/s, rad/s),',
        'NED position (m), roll pitch yaw (rad).',
        'Input u_in = [' + ' '.join(inputs) + ']: fins (rad), shaft speed (rpm),',
        'measured thrust (N; measured_thrust propulsion only)'
        + (', then one command per thruster' if ts else '') + '.',
        'Fins are saturated to +-FIN_LIMIT, the shaft speed to +-N_MAX inside f.',
        '',
        'Equations (Fossen 2021, eq. 6.3):',
        '  M nu_dot = F(nu, eta, u_in),   eta_dot = J(eta) nu',
        'F = the monomial terms (hydrodynamic and control coefficients, dimensional, and the',
        'rigid-body Coriolis terms) + propulsion + cross-flow drag + restoring forces'
        + (' + thrusters' if ts else '') + ';',
        'nu_dot = MINV F, MINV the inverse the identification used (M = M_RB + M_A is given',
        *(('too). Added mass enters through M and its Coriolis terms -C_A(nu) nu (Fossen',
           '2021, eq. 6.43), which F computes from it (the lines "added-mass Coriolis").')
          if len(getattr(v, 'ca_i', ())) else
          ('too). Added mass enters through M only: its Coriolis part is in the monomial terms',
           'where the vehicle file has it.')),
    ]
    if held:
        lines += [f'Degrees of freedom: the states {", ".join(held)} are held (read as 0, their',
                  'rates 0): a planar vehicle.']
    if cur:
        lines.append(cur)
    return lines


def python_text(saved):
    """The exported module's source (module docstring)."""
    model = identified_model(saved)
    v = saved.vehicle
    par = v.par
    day = datetime.date.today().isoformat()
    used = _used_factors(v)
    header = _header(saved, model, day)
    thr_data, thr_code = _thruster_lines(v, model.c)
    names = tuple(INPUT_NAMES) + tuple(t.name for t in getattr(v, 'thrusters', ()))
    body = ['def forces(x, u_in):',
            '    """F (6,): the generalized force in N and N m, body FRD, at state x (12,) and',
            '    inputs u_in; nu_dot = MINV F."""',
            '    x = np.asarray(x, dtype=float)',
            '    u_in = np.asarray(u_in, dtype=float)',
            '    if u_in.shape != (N_INPUTS,):',
            "        raise ValueError(f'u_in must have {N_INPUTS} entries, got {u_in.shape}')"]
    if len(model.held):
        body += ['    x = x.copy()', '    x[list(HELD)] = 0.0']
    body += ['    u, v, w, p, q, r = x[:6]',
             '    phi, theta = x[9], x[10]',
             '    sph, cph, sth, cth = math.sin(phi), math.cos(phi), math.sin(theta), '
             'math.cos(theta)']
    for f in ('u', 'v', 'w', 'p', 'q', 'r'):
        if f'|{f}|' in used:
            body.append(f'    a{f} = abs({f})')
    body += ['    dr, ds, db, dbp, dbs = np.clip(u_in[:5], -FIN_LIMIT, FIN_LIMIT)',
             '    db2 = dbp + dbs',
             '    n_rpm = min(max(u_in[5], -N_MAX), N_MAX)',
             '    thrust = u_in[6]']
    if FACTORS[Z_SPEED] in used:
        body.append('    U = math.sqrt(u * u + v * v)')
    body.append('    F = np.zeros(6)')
    body += _propulsion_lines(par)
    if FACTORS[Z_EPS] in used and int(par[P_PROP]) != 1:
        body.append('    eps = 0.0   # no Healey-Lienard propeller')
    body += _term_lines(v, model.c)
    body += _coriolis_lines(v, model.c)
    body += thr_code
    body += _restoring_lines(par)
    body += _crossflow_lines(par)
    body.append('    return F')
    text = ['"""' + '\n'.join(header) + '\n"""',
            'import math', '', 'import numpy as np', '',
            f'VEHICLE = {v.name!r}',
            f'STATE_NAMES = {tuple(STATE_NAMES)!r}',
            f'INPUT_NAMES = {names!r}',
            f'N_INPUTS = {len(names)}',
            f'FIN_LIMIT = {_r(par[P_FIN])}   # rad',
            f'N_MAX = {_r(par[P_NMAX])}   # rpm',
            f'HELD = {tuple(int(i) for i in model.held)!r}   # held states (planar vehicle)',
            '# the water current the identification estimated (north, east, down m/s; None:',
            '# none estimated); f uses a current only when given one',
            'IDENTIFIED_CURRENT = ' + ('None' if saved.current is None else
                                       '(' + ', '.join(_r(x) for x in saved.current) + ')'),
            "# the coefficients in the vehicle file's units (prime values if nondimensional);",
            '# forces() holds them dimensional, (rho/2) L^k times these',
            'COEFFICIENTS = {',
            *(f'    {n!r}: {_r(x)},' for n, x in zip(v.names, model.c)),
            '}',
            _matrix('M', v.mass_matrix(model.c)) + '   # M_RB + M_A, kg, kg m, kg m^2',
            _matrix('MINV', model.Minv) + '   # the inverse the model uses',
            *thr_data, '', '',
            'def _sign(a):',
            '    return 1.0 if a > 0.0 else (-1.0 if a < 0.0 else 0.0)',
            '', '', *body]
    if thr_data:
        text.append(THRUST_FUNCTION.rstrip('\n'))
    text += ['', '', KINEMATICS.strip('\n'), '', '', F_AND_SIMULATE.strip('\n')]
    src = '\n'.join(text) + '\n'
    return src.replace('COS_THETA_MIN_VALUE', _r(COS_THETA_MIN))


KINEMATICS = '''
def kinematics(x):
    """eta_dot (6,) = J(eta) nu (Fossen 2021, eq. 2.40, ZYX Euler angles)."""
    u, v, w, p, q, r = x[:6]
    phi, theta, psi = x[9], x[10], x[11]
    sph, cph, sth, cth = math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta)
    sp, cp = math.sin(psi), math.cos(psi)
    tt = sth / cth
    return np.array([
        cp * cth * u + (-sp * cph + cp * sth * sph) * v + (sp * sph + cp * cph * sth) * w,
        sp * cth * u + (cp * cph + sph * sth * sp) * v + (-cp * sph + sth * sp * cph) * w,
        -sth * u + cth * sph * v + cth * cph * w,
        p + sph * tt * q + cph * tt * r,
        cph * q - sph * r,
        (sph * q + cph * r) / cth])
'''

F_AND_SIMULATE = '''
def body_current(current, phi, theta, psi):
    """v_cb = R(Theta)^T v_c (3,), m/s: a current constant in NED (north, east, down; where
    the water goes) in the body frame."""
    sph, cph, sth, cth = math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta)
    sp, cp = math.sin(psi), math.cos(psi)
    R = np.array([[cp * cth, -sp * cph + cp * sth * sph, sp * sph + cp * cph * sth],
                  [sp * cth, cp * cph + sph * sth * sp, -cp * sph + sth * sp * cph],
                  [-sth, cth * sph, cth * cph]])
    return R.T @ np.asarray(current, dtype=float)


def f(x, u_in, current=None, velocity_reference='ground'):
    """x_dot (12,) at state x (12,) and inputs u_in (N_INPUTS,).

    current: None (still water) or a water current constant in NED, (3,) m/s (e.g.
    IDENTIFIED_CURRENT). The hydrodynamic forces act on the velocity through the water
    nu_r = nu - [R^T v_c; 0] (Fossen 2021, sec. 10.3). velocity_reference 'ground': x holds
    the velocity over ground, nu_dot = nu_r_dot + [v_cb x omega; 0]; 'water': x holds nu_r,
    whose rate is the still-water one, and the position rate gains v_c."""
    x = np.asarray(x, dtype=float)
    if HELD:
        x = x.copy()
        x[list(HELD)] = 0.0
    if abs(math.cos(x[10])) < COS_THETA_MIN_VALUE:
        raise ValueError('pitch theta at +-90 deg: the Euler-angle kinematics are singular')
    if velocity_reference not in ('ground', 'water'):
        raise ValueError(f'velocity_reference {velocity_reference!r}: ground or water')
    moving = current is not None and np.any(np.asarray(current, dtype=float) != 0.0)
    xdot = np.empty(12)
    if moving and velocity_reference == 'ground':
        vcb = body_current(current, x[9], x[10], x[11])
        xr = x.copy()
        xr[:3] -= vcb
        xdot[:6] = MINV @ forces(xr, u_in)
        xdot[:3] += np.cross(vcb, x[3:6])
    else:
        xdot[:6] = MINV @ forces(x, u_in)
    xdot[6:] = kinematics(x)
    if moving and velocity_reference == 'water':
        xdot[6:9] += np.asarray(current, dtype=float)
    if HELD:
        xdot[list(HELD)] = 0.0
    return xdot


def simulate(x0, inputs, dt, substeps=1, current=None, velocity_reference='ground'):
    """Integrate f with classical RK4 (step dt / substeps s), each row of inputs (n, N_INPUTS)
    held over one dt (zero-order hold); current and velocity_reference as for f. Returns the
    states (n + 1, 12), x0 first; psi is not wrapped."""
    inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
    x = np.empty((len(inputs) + 1, 12))
    x[0] = x0
    h = dt / substeps

    def rate(xk, uk):
        return f(xk, uk, current, velocity_reference)
    for k, uk in enumerate(inputs):
        xk = x[k]
        for _ in range(substeps):
            k1 = rate(xk, uk)
            k2 = rate(xk + 0.5 * h * k1, uk)
            k3 = rate(xk + 0.5 * h * k2, uk)
            k4 = rate(xk + h * k3, uk)
            xk = xk + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        x[k + 1] = xk
    return x
'''
