"""`export --format uuv|gz` round trips: the target's force equations re-implemented here from
its source (uuv_simulator HydrodynamicModel.cc HMFossen; gz-sim Hydrodynamics.cc and
HydrodynamicsUtils.hh), fed with the exported file, simulated against our model.

- exact case: a dimensional vehicle with only Fossen-form terms (diagonal linear and quadratic
  damping, diagonal added mass with its Coriolis written out as monomials) must come back to
  < 1e-6 relative along a free trajectory;
- fitted case (NPS AUV II: cross-flow, fin and propeller terms): the target's damping on the
  exporter's own samples reaches the fit % the file reports, and on a held-out manoeuvre stays
  close to it.
"""
import json
from pathlib import Path
import re
import xml.etree.ElementTree as ET

import helpers
import numpy as np
import pytest

from auv_ident.analysis.export import export_model, ExportError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.vehicles import load_vehicle

A = {'u': 1.0, 'v': 30.0, 'w': 30.0, 'p': 0.05, 'q': 4.0, 'r': 4.0}   # M_A diagonal, kg...
# -C_A(nu) nu of a diagonal M_A (Fossen 2021, eq. 6.43) written out as monomials
MUNK = {'X_vr': (A['v'], 'X', 'v*r'), 'X_wq': (-A['w'], 'X', 'w*q'),
        'Y_wp': (A['w'], 'Y', 'w*p'), 'Y_ur': (-A['u'], 'Y', 'u*r'),
        'Z_uq': (A['u'], 'Z', 'u*q'), 'Z_vp': (-A['v'], 'Z', 'v*p'),
        'K_vw': (A['v'] - A['w'], 'K', 'v*w'), 'K_qr': (A['q'] - A['r'], 'K', 'q*r'),
        'M_uw': (A['w'] - A['u'], 'M', 'u*w'), 'M_pr': (A['r'] - A['p'], 'M', 'p*r'),
        'N_uv': (A['u'] - A['v'], 'N', 'u*v'), 'N_pq': (A['p'] - A['q'], 'N', 'p*q')}
DAMP = {'X_u': (-2.0, 'X', 'u'), 'X_uu': (-1.6, 'X', 'u*|u|'),
        'Y_v': (-20.0, 'Y', 'v'), 'Y_vv': (-100.0, 'Y', 'v*|v|'),
        'Z_w': (-20.0, 'Z', 'w'), 'Z_ww': (-100.0, 'Z', 'w*|w|'),
        'K_p': (-0.5, 'K', 'p'), 'K_pp': (-0.2, 'K', 'p*|p|'),
        'M_q': (-5.0, 'M', 'q'), 'M_qq': (-10.0, 'M', 'q*|q|'),
        'N_r': (-5.0, 'N', 'r'), 'N_rr': (-10.0, 'N', 'r*|r|')}
# fins move the ident manoeuvre through all six velocities; not exported (controls)
CONTROL = {'Y_dr': (20.0, 'Y', 'u*u*dr'), 'N_dr': (-10.0, 'N', 'u*u*dr'),
           'K_dr': (1.0, 'K', 'u*u*dr'), 'Z_ds': (-20.0, 'Z', 'u*u*ds'),
           'M_ds': (-10.0, 'M', 'u*u*ds')}
MASS, INERTIA = 30.0, (0.2, 3.0, 3.0)
FLU = np.array([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])


def _fossen_vehicle(tmp_path):
    lines = ['name: fossen_test', 'title: Fossen-form test vehicle', 'scaling: dimensional',
             'rho: 1025.0', 'L: 1.5', f'mass: {MASS}', 'W: 294.3', 'B: 294.3',
             'r_G: [0.0, 0.0, 0.0]', 'r_B: [0.0, 0.0, 0.0]',
             'inertia: {Ix: %r, Iy: %r, Iz: %r, Ixy: 0.0, Iyz: 0.0, Ixz: 0.0}' % INERTIA,
             'limits: {fin_rad: 0.35, n_rpm: 1500.0}', 'cruise_rpm: 1500.0',
             'mass_inverse: exact',
             'propulsion: {model: quadratic_thrust, X_prop: 10.0, K_prop: 0.0, '
             'n_nominal_rpm: 1500.0}',
             'crossflow: {model: none}', 'coefficients:']
    for eq, s in zip('XYZKMN', 'uvwpqr'):
        lines.append(f'  {eq}_{s}dot: [{-A[s]!r}, {eq}, 3, {s}dot]')
    for name, (val, eq, mult) in {**MUNK, **DAMP, **CONTROL}.items():
        lines.append(f'  {name}: [{val!r}, {eq}, 2, {mult}]')
    lines.append('identify_default: [Y_v, N_r]')
    path = tmp_path / 'fossen_test.yaml'
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def _model_json(path, vehicle, estimates):
    doc = {'vehicle': str(vehicle), 'source': 'test',
           'coefficients': {n: {'estimate': v, 'std': abs(v) * 0.01}
                            for n, v in estimates.items()}}
    path.write_text(json.dumps(doc), encoding='utf-8')
    return path


def _coriolis(M, nu):
    """C(nu) nu of Fossen 2021 eqs. 3.57/6.43 for a symmetric M (rigid body or added mass)."""
    a = M @ nu
    return np.concatenate([-np.cross(a[:3], nu[3:]),
                           -np.cross(a[:3], nu[:3]) - np.cross(a[3:], nu[3:])])


def _rk4(f, x0, dt, n):
    x, out = np.array(x0, float), [np.array(x0, float)]
    for _ in range(n):
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(x)
    return np.array(out)


def _floats(text):
    return np.array([float(t) for t in text.split()])


# ------------------------------------------------------------------ uuv_simulator HMFossen

def _uuv_params(path):
    root = ET.parse(path).getroot()
    hm = root.find('.//hydrodynamic_model')
    assert hm.findtext('type') == 'fossen'
    Ma = _floats(hm.findtext('added_mass')).reshape(6, 6)
    DL = _floats(hm.findtext('linear_damping')).reshape(6, 6)
    DLf = _floats(hm.findtext('linear_damping_forward_speed')).reshape(6, 6)
    DQ = np.diag(_floats(hm.findtext('quadratic_damping')))
    return Ma, DL, DLf, DQ


def _uuv_damping(DL, DLf, DQ, nu):
    """HMFossen::ComputeDampingMatrix then damping = -D nu (FRD, after ToNED)."""
    D = -DL - nu[0] * DLf
    D = D - np.diag(np.diag(DQ) * np.abs(nu))
    return -D @ nu


def _uuv_nudot(M_RB, Ma, DL, DLf, DQ):
    M = M_RB + Ma

    def f(nu):
        tau = _uuv_damping(DL, DLf, DQ, nu) - _coriolis(Ma, nu) + THRUST
        return np.linalg.solve(M, tau - _coriolis(M_RB, nu))
    return f


# ------------------------------------------------- ROS 2 hydrodynamics (auv_controllers)

def _skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _hyd_params(path):
    """parse_model_from_xml (hydrodynamics.cpp, 2025-04): <inertial> mass value, inertia ixx
    iyy izz (products into the upper triangle only), center_of_gravity, added_mass Xdu..;
    <damping> linear Xu.., quadratic Xuu..; <hydrostatics> buoyancy value, center_of_buoyancy;
    weight = mass * 9.81. Returns (m, I (3, 3), added (6,), lin (6,), quad (6,), r_G, r_B, W,
    B)."""
    h = ET.parse(path).getroot().find('hydrodynamics')
    ine, damp, stat = h.find('inertial'), h.find('damping'), h.find('hydrostatics')

    def six(el, keys):
        return np.array([float(el.attrib[k]) for k in keys])

    def xyz(el):
        return np.array([float(el.attrib.get(k, 0.0)) for k in 'xyz'])

    m = float(ine.find('mass').get('value'))
    ia = ine.find('inertia').attrib
    I = np.diag([float(ia['ixx']), float(ia['iyy']), float(ia['izz'])])
    I[0, 1], I[0, 2], I[1, 2] = (float(ia.get(k, 0.0)) for k in ('ixy', 'ixz', 'iyz'))
    add = six(ine.find('added_mass'), ('Xdu', 'Ydv', 'Zdw', 'Kdp', 'Mdq', 'Ndr'))
    lin = six(damp.find('linear'), ('Xu', 'Yv', 'Zw', 'Kp', 'Mq', 'Nr'))
    quad = six(damp.find('quadratic'), ('Xuu', 'Yvv', 'Zww', 'Kpp', 'Mqq', 'Nrr'))
    return (m, I, add, lin, quad, xyz(ine.find('center_of_gravity')),
            xyz(stat.find('center_of_buoyancy')), m * 9.81,
            float(stat.find('buoyancy').get('value')))


def _hyd_model(path):
    """(M (6, 6), rate(nu, tau, R)) of hydrodynamics.cpp forward_dynamics:
    M^-1 (tau - C nu - D nu - g(R)), M = M_RB(m, I, r_G) - diag(added); C = C_RB + C_A, each
    [[0, -S(c1)], [-S(c1), -S(c2)]] of its matrix times nu; D = -diag(lin) - diag(quad) |nu|;
    g = -[R^T (fg + fb); r_G x R^T fg + r_B x R^T fb], fg = (0, 0, W), fb = (0, 0, -B)."""
    m, I, add, lin, quad, rg, rb, W, B = _hyd_params(path)
    M_RB = np.zeros((6, 6))
    M_RB[:3, :3] = m * np.eye(3)
    M_RB[:3, 3:] = -m * _skew(rg)
    M_RB[3:, :3] = m * _skew(rg)
    M_RB[3:, 3:] = I
    M_A = -np.diag(add)
    M = M_RB + M_A

    def cor(Mx, nu):
        c1 = Mx[:3, :3] @ nu[:3] + Mx[:3, 3:] @ nu[3:]
        c2 = Mx[3:, :3] @ nu[:3] + Mx[3:, 3:] @ nu[3:]
        C = np.zeros((6, 6))
        C[:3, 3:] = -_skew(c1)
        C[3:, :3] = -_skew(c1)
        C[3:, 3:] = -_skew(c2)
        return C @ nu

    def rate(nu, tau, R=None):
        R = np.eye(3) if R is None else R
        D = -np.diag(lin) - np.diag(quad * np.abs(nu))
        fg, fb = R.T @ np.array([0.0, 0.0, W]), R.T @ np.array([0.0, 0.0, -B])
        g = -np.concatenate([fg + fb, np.cross(rg, fg) + np.cross(rb, fb)])
        return np.linalg.solve(M, tau - cor(M_RB, nu) - cor(M_A, nu) - D @ nu - g)
    return M, rate


def _hyd_nudot(path):
    """The library's forward dynamics at zero attitude with THRUST (W = B at the origin)."""
    _, rate = _hyd_model(path)
    return lambda nu: rate(nu, THRUST)


# ------------------------------------------------------------------ gz-sim Hydrodynamics

VEL, MOM = 'UVWPQR', 'xyzkmn'


def _gz_params(path):
    root = ET.parse(path).getroot()
    plugin = root.find('.//plugin')
    val = {el.tag: float(el.text) for el in plugin if el.tag not in (
        'link_name', 'water_density', 'disable_coriolis')}
    lin, qabs, quad = np.zeros(36), np.zeros(216), np.zeros(216)
    Ma = np.zeros((6, 6))
    for i in range(6):
        for j in range(6):
            pre = MOM[i] + VEL[j]
            lin[i * 6 + j] = val.pop(pre, 0.0)
            Ma[i, j] = val.pop(MOM[i] + 'Dot' + VEL[j], 0.0)
            for k in range(6):
                qabs[i * 36 + j * 6 + k] = val.pop(pre + 'abs' + VEL[k], 0.0)
                quad[i * 36 + j * 6 + k] = val.pop(pre + VEL[k], 0.0)
    assert not val, f'parameters the plugin does not read: {sorted(val)}'
    coriolis_off = plugin.findtext('disable_coriolis') == 'true'
    fam = root.find('.//fluid_added_mass')
    Mf = np.zeros((6, 6))
    if fam is not None:
        ax = 'xyzpqr'
        for el in fam:
            i, j = ax.index(el.tag[0]), ax.index(el.tag[1])
            Mf[i, j] = Mf[j, i] = float(el.text)
    return lin, qabs, quad, Ma, coriolis_off, Mf


def _gz_coriolis(Ma, s):
    """hydro::buildCoriolisMatrix (diagonal Ma only)."""
    C = np.zeros((6, 6))
    C[0, 4] = -Ma[2, 2] * s[2]
    C[0, 5] = Ma[1, 1] * s[1]
    C[1, 3] = Ma[2, 2] * s[2]
    C[1, 5] = -Ma[0, 0] * s[0]
    C[2, 3] = -Ma[1, 1] * s[1]
    C[2, 4] = Ma[0, 0] * s[0]
    C[3, 1] = -Ma[2, 2] * s[2]
    C[3, 2] = Ma[1, 1] * s[1]
    C[3, 4] = -Ma[5, 5] * s[5]
    C[3, 5] = Ma[4, 4] * s[4]
    C[4, 0] = Ma[2, 2] * s[2]
    C[4, 2] = -Ma[0, 0] * s[0]
    C[4, 3] = Ma[5, 5] * s[5]
    C[4, 5] = -Ma[3, 3] * s[3]
    C[5, 0] = -Ma[1, 1] * s[1]
    C[5, 1] = Ma[0, 0] * s[0]
    C[5, 3] = -Ma[4, 4] * s[4]
    C[5, 4] = Ma[3, 3] * s[3]
    return C


def _gz_damping(lin, qabs, quad, s):
    """hydro::buildDampingMatrix; the applied wrench is -(D s) (Hydrodynamics.cc)."""
    D = np.zeros((6, 6))
    for i in range(6):
        for j in range(6):
            c = -lin[i * 6 + j]
            for k in range(6):
                c -= qabs[i * 36 + j * 6 + k] * abs(s[k]) + quad[i * 36 + j * 6 + k] * s[k]
            D[i, j] = c
    return -(D @ s)


def _gz_nudot(M_RB, params):
    """FLU link velocity rate: M_RB + the added mass (the engine's <fluid_added_mass> with
    Fossen's -C_A, or the plugin's -Ma nu_dot, which moves to the left side) and the plugin's
    wrench -kTotalWrench = Ma s_dot + C s + damping."""
    lin, qabs, quad, Ma, off, Mf = params
    M = M_RB + Mf - Ma

    def f(s):
        tau = (_gz_damping(lin, qabs, quad, s) - _coriolis(Mf, s) - _coriolis(M_RB, s)
               + FLU * THRUST)
        if not off:
            tau = tau + _gz_coriolis(Ma, s) @ s
        return np.linalg.solve(M, tau)
    return f


# the propeller at cruise (quadratic_thrust, X_prop at n0): a thruster the target simulator
# adds as its own system; kept here so that the free run stays forward, in the export's envelope
THRUST = np.array([10.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def _ours(vehicle, estimates, rpm=0.0):
    v = load_vehicle(str(vehicle)) if not hasattr(vehicle, 'names') else vehicle
    c = v.values.copy()
    for n, e in estimates.items():
        c[v.index(n)] = e
    model = Model(v, (), coefficient_values=c)
    x = np.zeros(12)

    def f(nu):
        x[:6] = nu
        return model.f(x, np.array([0.0, 0.0, 0.0, 0.0, 0.0, rpm, 0.0]))[:6]
    return v, model, f


NU0 = np.array([1.8, 0.15, -0.1, 0.08, 0.05, -0.12])


@pytest.mark.parametrize('fmt', ['uuv', 'gz-link', 'gz-plugin', 'urdf-hydrodynamics'])
def test_a_fossen_form_vehicle_exports_exactly(tmp_path, fmt):
    vehicle = _fossen_vehicle(tmp_path)
    est = {'Y_v': -22.0, 'N_r': -5.5, 'Z_ww': -110.0}
    model = _model_json(tmp_path / 'm.json', vehicle, est)
    out = tmp_path / 'out.xml'
    lines = []
    form, _, am = fmt.partition('-') if fmt.startswith('gz') else (fmt, '', '')
    export_model(model, out, fmt=form, gz_added_mass=am or 'link', echo=lines.append)
    v, _, ours = _ours(vehicle, est, rpm=1500.0)
    fit_line = next(ln for ln in lines if ln.startswith('fit of'))
    fit = [float(x) for x in re.findall(r'[XYZKMN] (\d+\.\d+)', fit_line)]
    assert len(fit) == 6 and min(fit) >= 99.9999, lines
    dt, n = 0.01, 2000
    want = _rk4(ours, NU0, dt, n)
    if form == 'uuv':
        got = _rk4(_uuv_nudot(v.M_RB, *_uuv_params(out)), NU0, dt, n)
    elif form == 'urdf-hydrodynamics':
        got = _rk4(_hyd_nudot(out), NU0, dt, n)
    else:
        got = _rk4(_gz_nudot(v.M_RB, _gz_params(out)), FLU * NU0, dt, n) * FLU
    assert np.all(want[:, 0] > 0.0)   # forward all along (u terms are exported for u > 0)
    err = np.abs(got - want).max() / np.abs(want).max()
    assert err < 1e-6, err


def test_the_gz_plugin_coriolis_is_fossens_with_the_opposite_sign():
    """What the header says: buildCoriolisMatrix(Ma) = C_A(nu) of M_A = -Ma, and the plugin
    applies +C s (kTotalWrench -= C s, applied = -kTotalWrench)."""
    Ma = -np.diag([1.0, 30.0, 30.0, 0.05, 4.0, 4.0])
    s = NU0
    np.testing.assert_allclose(_gz_coriolis(Ma, s) @ s, _coriolis(-Ma, s), rtol=1e-14, atol=1e-12)
    # the pitch Munk moment Fossen's -C_A gives, (a_w - a_u) u w, is destabilising (> 0 for
    # u, w > 0); the plugin's is its opposite
    s = np.array([1.0, 0.0, 0.5, 0.0, 0.0, 0.0])
    assert (-_coriolis(-Ma, s))[4] == pytest.approx(29.0 * 0.5)
    assert (_gz_coriolis(Ma, s) @ s)[4] == pytest.approx(-29.0 * 0.5)


def _header_fit(path):
    text = path.read_text(encoding='utf-8')
    line = next(ln for ln in text.splitlines() if ln.startswith('fit of the damping'))
    return {d: float(x) for d, x in re.findall(r'([XYZKMN]) (\d+\.\d+)', line)}


def _fit(y, yh):
    return 100.0 * (1.0 - np.linalg.norm(y - yh) / np.linalg.norm(y - y.mean()))


def _our_damping_force(v, model, nu):
    """Our model's hydrodynamic force on the velocities, by the same definition as the export
    (docs/export.md), here from M nu_dot minus rigid-body Coriolis and restoring."""
    raw = v.raw
    W, B = float(raw['W']), float(raw['B'])
    rg, rb = np.asarray(raw['r_G'], float), np.asarray(raw['r_B'], float)
    g0 = np.array([0.0, 0.0, -(W - B), -(rg[1] * W - rb[1] * B), rg[0] * W - rb[0] * B, 0.0])
    M = v.mass_matrix(model.c)
    x = np.zeros(12)
    out = []
    for s in nu:
        x[:6] = s
        out.append(M @ model.f(x, np.zeros(7))[:6] + g0 + _coriolis(v.M_RB, s))
    return np.array(out)


@pytest.mark.parametrize('fmt', ['uuv', 'gz'])
def test_a_torpedo_export_reaches_its_reported_fit(tmp_path, fmt):
    est = {'Z_w': -0.3}
    model = _model_json(tmp_path / 'm.json', 'nps_auv2', est)
    out = tmp_path / 'out.xml'
    export_model(model, out, fmt=fmt)
    reported = _header_fit(out)
    v, m, _ = _ours('nps_auv2', est)
    # the export's samples (docs/export.md): its 200 s ident run and 2000 points in its box;
    # then held out: a prbs manoeuvre
    run = simulate(m, 'ident', duration=200.0, noise_std=np.zeros(12)).x[:, :6]
    box = np.random.default_rng(0).uniform(run.min(axis=0), run.max(axis=0), size=(2000, 6))
    held = simulate(m, 'prbs', duration=200.0, noise_std=np.zeros(12)).x[:, :6]
    got = _target_fit(out, fmt, v, m, np.vstack([run, box]))
    held_out = _target_fit(out, fmt, v, m, held)
    print(fmt, 'reported', reported, 'held-out prbs', held_out)
    for d in 'XYZKMN':
        assert got[d] == pytest.approx(reported[d], abs=1e-3), (d, got[d], reported[d])
        if fmt == 'gz':    # the gz fit is good enough to carry over to another manoeuvre
            assert held_out[d] >= reported[d] - 2.0, (d, held_out[d], reported[d])


def _target_fit(out, fmt, v, m, nu):
    """Fit % per DOF of the target's damping force (plus its added-mass Coriolis) to ours."""
    M_A = v.mass_matrix(m.c) - v.M_RB
    H = _our_damping_force(v, m, nu)
    if fmt == 'uuv':
        _, DL, DLf, DQ = _uuv_params(out)
        target = np.array([_uuv_damping(DL, DLf, DQ, s) - _coriolis(M_A, s) for s in nu])
    else:
        lin, qabs, quad, _, _, Mf = _gz_params(out)
        target = np.array([FLU * (_gz_damping(lin, qabs, quad, FLU * s)
                                  - _coriolis(Mf, FLU * s)) for s in nu])
    return {d: _fit(H[:, i], target[:, i]) for i, d in enumerate('XYZKMN')}


def test_a_bad_gz_added_mass_is_refused(tmp_path):
    model = _model_json(tmp_path / 'm.json', 'remus100', {'Z_w': -60.0})
    with pytest.raises(ExportError, match='--gz-added-mass'):
        export_model(model, tmp_path / 'o.xml', fmt='gz', gz_added_mass='engine')


def test_the_fit_envelope_is_the_identified_bags_velocities(tmp_path, capsys):
    """A model that records its bag is fitted over that bag's measured velocities (and the
    box of them); the fit % per DOF goes next to the file, and the target's damping
    re-evaluated on those samples reaches it."""
    from auv_ident.analysis.export_fossen import bag_velocities
    from auv_ident.cli import main
    from auv_ident.offline.replay import read_bag_run
    from auv_ident.session.settings import IdentifierSettings
    bag = str(Path(helpers.REPO) / 'bags' / 'nps_auv2_ident')
    doc = {'vehicle': 'nps_auv2', 'bags': [bag],
           'coefficients': {'Z_w': {'estimate': -0.3, 'std': 1e-3}}}
    model = tmp_path / 'm.json'
    model.write_text(json.dumps(doc), encoding='utf-8')
    out = tmp_path / 'nps.sdf'
    assert main(['export', str(model), '--format', 'gz', '--out', str(out)]) == 0
    said = capsys.readouterr().out
    assert 'measured velocities' in said and bag in said
    report = json.loads((tmp_path / 'nps.sdf.fit.json').read_text(encoding='utf-8'))
    assert report['bags'] == [bag] and report['format'] == 'gz'
    assert report['fit_percent'] == pytest.approx(
        {d: round(f, 4) for d, f in _header_fit(out).items()}, abs=1e-4)
    # the samples: the bag's measured u..r (independently read here) and the box of them
    Y = read_bag_run(bag, IdentifierSettings.from_values(vehicle='nps_auv2')).Y[:, :6]
    Y = Y[np.all(np.isfinite(Y), axis=1)]
    np.testing.assert_array_equal(bag_velocities([bag], load_vehicle('nps_auv2')), Y)
    box = np.random.default_rng(0).uniform(Y.min(axis=0), Y.max(axis=0), size=(2000, 6))
    v, m, _ = _ours('nps_auv2', {'Z_w': -0.3})
    got = _target_fit(out, 'gz', v, m, np.vstack([Y, box]))
    for d in 'XYZKMN':
        assert got[d] == pytest.approx(report['fit_percent'][d], abs=2e-3), d
    # the report is an output like the file: not replaced without --force
    out.unlink()
    assert main(['export', str(model), '--format', 'gz', '--out', str(out)]) == 2
    assert 'nps.sdf.fit.json: exists already' in capsys.readouterr().err


# --------------------------------------------------------------------- gz-sim Thruster

def _gz_thrusters(path):
    """Per Thruster system of the exported SDF: (child link origin (3,), joint axis (3,),
    min, max thrust command, fluid density, use_angvel_cmd) in the link frame (FLU), read as
    Thruster.cc reads them (defaults: +-1000 N, 1000 kg/m^3, force commands)."""
    root = ET.parse(path).getroot()
    model = root.find('model')
    links = {ln.get('name'): _floats(ln.findtext('pose') or '0 0 0 0 0 0')[:3]
             for ln in model.findall('link')}
    joints = {j.get('name'): (j.findtext('child'), _floats(j.find('axis').findtext('xyz')))
              for j in model.findall('joint')}
    out = {}
    for pl in model.findall('plugin'):
        if pl.get('name') != 'gz::sim::systems::Thruster':
            continue
        child, axis = joints[pl.findtext('joint_name')]
        out[pl.findtext('joint_name')] = (
            links[child], axis / np.linalg.norm(axis),
            float(pl.findtext('min_thrust_cmd') or -1000.0),
            float(pl.findtext('max_thrust_cmd') or 1000.0),
            float(pl.findtext('fluid_density') or 1000.0),
            pl.findtext('use_angvel_cmd') == 'true')
    return out


def _thruster_export(tmp_path, fmt):
    """(vehicle, path, header text) of the test thruster vehicle's thruster units as
    export_fossen writes them into a gz SDF or a uuv xacro, wrapped in a minimal document:
    the thrusters alone, apart from the damping fit (whose simulated envelope needs a
    vehicle that can fly the ident manoeuvre)."""
    from test_export_python import THRUSTER_VEHICLE

    from auv_ident.analysis import export_gz_thrusters as gzt
    path = tmp_path / 'thruster_test.yaml'
    path.write_text(THRUSTER_VEHICLE, encoding='utf-8')
    v = load_vehicle(str(path))
    if fmt == 'gz':
        header = gzt.thruster_header(v.thrusters)
        body = (['<sdf version="1.11">', '  <model name="m">', '    <link name="base_link"/>']
                + gzt.thruster_sdf(v, float(v.raw['rho']), v.thrusters)
                + ['  </model>', '</sdf>'])
    else:
        header, lines = gzt.uuv_thruster_lines(v.thrusters)
        body = ['<robot>'] + [ln.replace('${namespace}', 'rov') for ln in lines] + ['</robot>']
    out = tmp_path / f'thrusters.{fmt}.xml'
    out.write_text('\n'.join(body) + '\n', encoding='utf-8')
    return v, out, '\n'.join(header)


def test_a_thruster_vehicles_thrusters_become_gz_thruster_systems(tmp_path):
    """Thruster.cc: the command (N) clamped to [min, max], applied along the joint axis at the
    child link's origin (AddWorldWrench at the link origin). The body wrench of the
    exported systems, for our curve's thrust, is ours (T f, FRD) after FLU -> FRD."""

    from auv_ident.analysis.export_gz_thrusters import quadratic_law_fit
    from auv_ident.core.model.thrusters import wrench
    v, out, text = _thruster_export(tmp_path, 'gz')
    systems = _gz_thrusters(out)
    assert sorted(systems) == [f'{t.name}_joint' for t in v.thrusters]
    for command in ([1500.0, 1500.0, 0.0, 0.0], [1620.0, 1380.0, 0.5, 3.0],
                    [2000.0, 1000.0, -1.0, -5.0], [1900.0, 1100.0, 1.0, 12.0]):
        tau = np.zeros(6)
        for t, cmd in zip(v.thrusters, command):
            r, d, lo, hi, rho, angvel = systems[f'{t.name}_joint']
            assert not angvel and rho == 1025.0
            f = min(max(t.thrust(cmd), lo), hi)      # what the controller sends, clamped
            tau += np.concatenate([d * f, np.cross(r, d * f)])
        np.testing.assert_allclose(FLU * tau, wrench(v.thrusters, command), atol=1e-12)
    # t1's limits are its curve at 1100 and 1900 us within thrust_max_*: the clamp is ours
    _, _, lo, hi, _, _ = systems['t1_joint']
    assert (lo, hi) == (v.thrusters[0].thrust(1100.0), v.thrusters[0].thrust(1900.0))
    # the quadratic law gz would apply from an angular velocity: its reported fit is the one
    # of c |e| e fitted here independently over the command range
    t = v.thrusters[2]                      # setpoint, no dead band: close to quadratic
    e = np.linspace(-1.0, 1.0, 2001)
    f = np.array([t.thrust(x) for x in e])
    x = np.abs(e) * e
    c = x @ f / (x @ x)
    fit = 100 * (1 - np.linalg.norm(f - c * x) / np.linalg.norm(f - f.mean()))
    c_exp, fit_exp = quadratic_law_fit(t)
    assert c_exp == pytest.approx(c, rel=1e-3) and fit_exp == pytest.approx(fit, abs=0.05)
    assert 't3: ' in text and f'fits our curve to {fit_exp:.2f} %' in text
    assert 't4: command = thrust (N); exact' in text


def _uuv_linear_interp(table, cmd):
    """ConversionFunctionLinearInterp::convert (ThrusterConversionFcn.cc): std::map
    lower_bound, the last output past the end, the first before the start."""
    keys = sorted(table)
    i = next((k for k, key in enumerate(keys) if key >= cmd), None)
    if i is None:
        return table[keys[-1]]
    if i == 0:
        return table[keys[0]]
    i0, i1 = keys[i - 1], keys[i]
    w1, w0 = cmd - i0, i1 - cmd
    return (table[i0] * w0 + table[i1] * w1) / (w0 + w1)


def test_a_thruster_vehicles_thrusters_become_uuv_thruster_units(tmp_path):
    """ThrusterPlugin.cc (ZeroOrder dynamics, gain 1): clamp the command, LinearInterp it to
    thrust, clamp the thrust, push along the joint axis at the joint origin (FLU): our wrench
    to the table's interpolation error."""
    from auv_ident.core.model.thrusters import wrench
    v, out, text = _thruster_export(tmp_path, 'uuv')
    assert 't1: 0.000772 N' in text     # the interpolation error the header gives
    root = ET.parse(out).getroot()
    joints = {j.get('name'): (_floats(j.find('origin').get('xyz')),
                              _floats(j.find('axis').get('xyz'))) for j in root.iter('joint')}
    units = []
    for pl in root.iter('plugin'):
        assert pl.find('dynamics').findtext('type') == 'ZeroOrder'
        conv = pl.find('conversion')
        assert conv.findtext('type') == 'LinearInterp'
        table = dict(zip(_floats(conv.findtext('inputValues')),
                         _floats(conv.findtext('outputValues'))))
        r, d = joints[pl.findtext('jointName')]
        units.append((table, r, d / np.linalg.norm(d),
                      *(float(pl.findtext(k)) for k in ('clampMin', 'clampMax', 'thrustMin',
                                                         'thrustMax'))))
    assert len(units) == len(v.thrusters)
    # each force component is off by at most the sum of the tables' interpolation errors (the
    # header's: t2's table, a few points far apart, bends more than t1's polynomial: 0.0099 N)
    from auv_ident.analysis.export_gz_thrusters import uuv_table_error
    tol = sum(uuv_table_error(t) for t in v.thrusters)
    assert tol < 0.012
    for command in ([1500.0, 1500.0, 0.0, 0.0], [1620.0, 1383.3, 0.537, 3.0],
                    [2000.0, 1000.0, -1.0, -5.0], [1530.1, 1100.0, 0.021, 12.0]):
        tau = np.zeros(6)
        for (table, r, d, cmin, cmax, fmin, fmax), cmd in zip(units, command):
            f = _uuv_linear_interp(table, min(max(cmd, cmin), cmax))
            f = min(max(f, fmin), fmax)
            tau += np.concatenate([d * f, np.cross(r, d * f)])
        np.testing.assert_allclose(FLU * tau, wrench(v.thrusters, command), atol=tol)
