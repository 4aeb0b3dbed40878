"""Fossen-form simulator exports (``export --format gz|uuv|urdf-hydrodynamics``: docs/export.md
and the pages export_gz.md, export_uuv.md, export_urdf_hydrodynamics.md).

Both targets hold M_RB nu_dot + M_A nu_dot + C_A(nu) nu + D(nu) nu + ... = tau with a few fixed
damping terms; our model (core/model/hydrodynamics.py) has others (cross-flow integrals, fin
and speed-scaled terms, lumped Munk moments). So:

- added mass: our M_A = M - M_RB exactly (the vehicle file's added-mass coefficients,
  dimensional, Fossen's positive sign);
- damping: the target's terms fitted by least squares to our model's hydrodynamic force on the
  velocities, H(nu) = F(nu) + g(0) - F_RB(nu) (F = M nu_dot of the model at zero attitude, fins
  and shaft speed; g the restoring force; F_RB the rigid-body Coriolis monomials; at zero shaft
  speed the Healey-Lienard propeller leaves the hull's axial drag -(rho/2) L^2 Cd0 u^2, which is
  damping and stays), minus what the target's own added-
  mass Coriolis term already applies. The samples: the measured velocities of the
  identification's bags when the model records them, else a noise-free 200 s zig-zag of the
  identified model (simulate.py, the `ident` manoeuvre: rudder zig-zag and plane steps; a
  hovering thruster vehicle: a 900 s tank session), plus 2000 uniform points (seed 0) in the
  box of those velocities.
  The fit % per DOF, 100 (1 - |y - y_fit| / |y - mean y|) with y = H and y_fit the target's
  damping plus its own added-mass Coriolis term, goes in the file and on the console;
  a DOF whose force never changes over the samples (not excited: its damping is fitted as
  nothing) is said so instead of a number.
  A file whose hydrodynamics is already of the target's form comes out exact (fit 100 %).
"""
from dataclasses import dataclass
import math
import os

import numpy as np

from auv_ident.analysis import export_gz_thrusters
from auv_ident.core.errors import AuvIdentError, DomainError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.trim import rest_inputs
from auv_ident.core.model.vehicle import rigid_body_terms
from auv_ident.core.simulation.simulate import simulate

DOF = 'XYZKMN'
FIT_GOAL = 95.0     # %, below this a DOF's fit is warned of (file header and console)
N_BOX = 2000
# FRD -> FLU (x forward, y left, z up): y, z and their rotations change sign
FLU = np.array([1.0, -1.0, -1.0, 1.0, -1.0, -1.0])


def skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def coriolis_vector(Ma, nu):
    """C_A(nu) nu of Fossen (2021, eq. 6.43) for a symmetric M_A (6, 6) at nu (6,)."""
    a = Ma @ nu
    return np.concatenate([np.cross(a[:3], nu[3:]) * -1.0,
                           -np.cross(a[:3], nu[:3]) - np.cross(a[3:], nu[3:])])


class ExportError(AuvIdentError):
    """An export that cannot be made faithfully (named culprit)."""


@dataclass
class FossenParts:
    """M_A (6, 6) kg, kg m, kg m^2 FRD; nu (N, 6) the samples; H (N, 6) N, N m our model's
    hydrodynamic force on them (see the module docstring); run_name: where nu came from;
    bags: the bags read for it (empty: a simulated run)."""

    M_A: np.ndarray
    nu: np.ndarray
    H: np.ndarray
    run_name: str
    bags: list      # the bags whose velocities are the envelope (empty: a simulated run)


def identified_values(saved):
    """(n_coef,) the vehicle file's coefficient values with the identified ones of a
    SavedModel in place (the file's units)."""
    v = saved.vehicle
    c = v.values.copy()
    for n, e in zip(saved.names, saved.estimate):
        c[v.index(n)] = e
    return c


def exported_thrusters(saved):
    """(thrusters, header lines): the vehicle's thrusters with the model's thrust gains (the
    identified ones in place) folded into their curves (export_gz_thrusters.with_gains)."""
    v = saved.vehicle
    if not v.thrusters:
        return [], []
    try:
        return export_gz_thrusters.with_gains(v, identified_values(saved))
    except export_gz_thrusters.GainError as exc:
        raise ExportError(str(exc)) from None


def bag_velocities(paths, vehicle, input_map=None):
    """(N, 6) the measured body velocities u..r (m/s, rad/s, FRD) of the bags' samples that
    measure all six, read as the data are (offline/replay.py read_bag_run: screened, no
    filter), through ``input_map`` (None: what each bag names, else the default). ExportError
    naming a bag that cannot be read or measures none."""
    from auv_ident.offline.replay import read_bag_run
    from auv_ident.session.settings import IdentifierSettings
    settings = IdentifierSettings.from_values(vehicle=vehicle.path, input_map=input_map)
    out = []
    for path in paths:
        try:
            Y = read_bag_run(path, settings).Y[:, :6]
        except AuvIdentError as exc:
            raise ExportError(f'--bag {path}: {exc}') from None
        Y = Y[np.all(np.isfinite(Y), axis=1)]
        if not len(Y):
            raise ExportError(f'--bag {path}: no sample measures all six body velocities u..r; '
                              'the fit needs them (leave the bag out to fit over a simulated '
                              'run)')
        out.append(Y)
    return np.vstack(out)


def _envelope_bags(saved, bags):
    """The bags the fit's envelope comes from: those given, else the model's own when all of
    them are here to read, else none (a simulated run)."""
    if bags:
        return list(bags), 'given'
    if saved.bags and all(os.path.exists(b) for b in saved.bags):
        return list(saved.bags), 'recorded in the model file'
    return [], ''


# s, the simulated envelope of a hovering thruster vehicle: its `ident` tank session flies one
# stick for 180 s at a time (surge, sway, heave, yaw), then two at once; 200 s would be surge
# alone, and the sway, heave and yaw damping fitted over nothing
HOVER_ENVELOPE_S = 900.0


def fossen_parts(saved, duration=None, bags=None):
    """FossenParts of a SavedModel (module docstring). bags: the runs whose measured
    velocities are the fit's envelope (None: the model's identification bags when it records
    them and they exist, else a simulated `ident` run of the identified model, `duration` s:
    None for 200 s, HOVER_ENVELOPE_S for a hovering thruster vehicle)."""
    v = saved.vehicle
    if duration is None:
        duration = HOVER_ENVELOPE_S if v.hovers else 200.0
    c = identified_values(saved)
    model = Model(v, (), coefficient_values=c)
    M = v.mass_matrix(c)
    # from the file's added-mass terms, not M - M_RB: the exported values to the last bit
    M_A = np.zeros((6, 6))
    for (eq, col, ci), sc in zip(v.am_i, v.am_s):
        M_A[eq, col] -= sc * c[ci]
    paths, why = _envelope_bags(saved, bags)
    if paths:
        nu_run = bag_velocities(paths, v, saved.input_map)
        run_name = (f"the measured velocities of the identification's bags ({why}: "
                    f'{", ".join(paths)}; {len(nu_run)} samples)')
    else:
        try:
            run = simulate(model, 'ident', duration=duration, noise_std=np.zeros(12))
        except DomainError as exc:
            raise ExportError(f'the fit envelope: the identified model cannot fly the ident '
                              f'manoeuvre ({exc}); give the runs to fit over with --bag') \
                from None
        nu_run = run.x[:, :6]
        run_name = (f'a noise-free {duration:g} s ident manoeuvre of the identified model '
                    '(the model file records no bag here to read)')
    lo, hi = nu_run.min(axis=0), nu_run.max(axis=0)
    box = np.random.default_rng(0).uniform(lo, hi, size=(N_BOX, 6))
    nu = np.vstack([nu_run, box])
    rb = rigid_body_terms(float(v.raw['mass']), np.asarray(v.raw['r_G'], float),
                          [float(v.raw['inertia'][k]) for k in
                           ('Ix', 'Iy', 'Iz', 'Ixy', 'Iyz', 'Ixz')])
    ui = rest_inputs(model)     # fins, shaft at 0; a thruster vehicle's thrusters at neutral
    x = np.zeros(12)
    F0 = _restoring_at_rest(v.raw)
    H = np.empty_like(nu)
    for i, s in enumerate(nu):
        x[:6] = s
        F = M @ model.f(x, ui)[:6]
        Frb = np.zeros(6)
        for eq, k, fac in rb:
            Frb[eq] += k * s[fac[0]] * s[fac[1]]
        H[i] = F - F0 - Frb
    return FossenParts(M_A=M_A, nu=nu, H=H, run_name=run_name, bags=paths)


def _restoring_at_rest(raw):
    """-g(0) (Fossen 2021, eq. 4.6, zero roll and pitch), N and N m FRD: what F holds at rest
    besides the (excluded) propulsion. Not F(nu = 0): the Healey-Lienard propeller is singular
    at u = 0."""
    W, B = float(raw['W']), float(raw['B'])
    rg, rb = np.asarray(raw['r_G'], float), np.asarray(raw['r_B'], float)
    return np.array([0.0, 0.0, W - B, rg[1] * W - rb[1] * B, -(rg[0] * W - rb[0] * B), 0.0])


def fit_percent(y, y_fit):
    """100 (1 - |y - y_fit| / |y - mean y|) per column; NaN where y does not vary (the DOF
    is not excited by the samples: there is nothing to fit)."""
    out = []
    for a, b in zip(np.asarray(y).T, np.asarray(y_fit).T):
        den = np.linalg.norm(a - a.mean())
        scale = max(np.abs(a).max(), 1e-300)
        out.append(math.nan if den <= 1e-12 * scale
                   else 100.0 * (1.0 - np.linalg.norm(a - b) / den))
    return np.array(out)


def least_squares(columns, y):
    """Coefficients (ncol, m) of y (N, m) ~ columns (N, ncol)."""
    coef, *_ = np.linalg.lstsq(columns, y, rcond=None)
    # exact zeros where a term does not matter to the last digit keep the files readable
    coef[np.abs(coef) < 1e-12 * max(1.0, np.abs(coef).max())] = 0.0
    return coef


def fit_lines(fit, what):
    """The fit % line, and a warning line naming the DOFs below FIT_GOAL."""
    lines = [f'fit of {what}, % per DOF: ' + ', '.join(
        f'{d} {f:.4f}' if math.isfinite(f) else f'{d} not excited (exported as no damping)'
        for d, f in zip(DOF, fit))]
    low = [d for d, f in zip(DOF, fit) if math.isfinite(f) and f < FIT_GOAL]
    if low:
        lines.append(f'WARNING: below {FIT_GOAL:g} % in {", ".join(low)}: there this export '
                     "does not reproduce our model's damping; simulate with care")
    return lines


# ------------------------------------------------------------------------------------ uuv

def uuv_fit(parts):
    """uuv_simulator HMFossen damping (FRD): tau_D = (L + u L_f) nu + diag(Q) |nu| nu, fitted
    to H + C_A(nu) nu (the plugin applies Fossen's -C_A(nu) nu itself). Returns
    L (6, 6), L_f (6, 6), Q (6,), fit % (6,)."""
    nu = parts.nu
    ca = np.array([coriolis_vector(parts.M_A, s) for s in nu])
    y = parts.H + ca
    L, Lf, Q, fit = np.zeros((6, 6)), np.zeros((6, 6)), np.zeros(6), np.zeros(6)
    for i in range(6):
        cols = np.hstack([nu, nu[:, :1] * nu, (np.abs(nu[:, i]) * nu[:, i])[:, None]])
        if i == 0:
            cols[:, 6] = 0.0    # u u: the quadratic u |u| holds it (same for u > 0)
        coef = least_squares(cols, y[:, i:i + 1])
        L[i], Lf[i], Q[i] = coef[:6, 0], coef[6:12, 0], coef[12, 0]
        fit[i] = fit_percent(parts.H[:, i:i + 1], cols @ coef - ca[:, i:i + 1])[0]
    return L, Lf, Q, fit


def _xml_text(lines):
    """The file's text; a header line with '--' (not allowed inside an XML comment, a
    command-line option or a path) gets the dashes spaced."""
    start, end = lines.index('<!--'), lines.index('-->')
    fixed = [ln.replace('--', '- -') if start < i < end else ln for i, ln in enumerate(lines)]
    return '\n'.join(fixed) + '\n'


def _numbers(values):
    return ' '.join(repr(float(x) + 0.0) for x in np.ravel(values))


def uuv_text(saved, parts, header):
    L, Lf, Q, fit = uuv_fit(parts)
    v = saved.vehicle
    thrusters, gain_lines = exported_thrusters(saved)
    thr_header, thr_lines = (export_gz_thrusters.uuv_thruster_lines(thrusters) if thrusters
                             else ([], []))
    thr_header = gain_lines + thr_header
    g = float(v.raw['W']) / float(v.raw['mass'])
    volume = float(v.raw['B']) / (float(v.raw['rho']) * g)
    cob = FLU[:3] * np.asarray(v.raw['r_B'], float)
    lines = ['<?xml version="1.0"?>', '<!--'] + header + fit_lines(fit, 'the damping') + [
        'uuv_simulator HMFossen (uuv_gazebo_plugins HydrodynamicModel.cc): it turns the link',
        'velocity (FLU) into FRD (ToNED: y, z negated) and applies, in FRD,',
        '  tau = -M_A a - C_A(nu) nu + (linear_damping + u linear_damping_forward_speed) nu',
        '        + diag(quadratic_damping) |nu| nu',
        'so added_mass is our M_A (positive, FRD, row-major 6x6), the damping values are the',
        'SNAME derivatives (negative) and only the diagonal of a 36-value quadratic_damping is',
        'used by the plugin (6 values here). a is a filtered finite-difference acceleration.',
        f'volume = B / (rho g) with g = W / mass = {g:.6g} m/s^2; center_of_buoyancy is r_B in',
        'the link frame (FLU: y, z negated). The link origin must be our body origin.',
        "Weight, inertia and the link mass are the URDF's, not this snippet's.",
        *thr_header, '-->',
        f'<xacro:macro name="{v.name}_hydro_model" params="namespace"'
        ' xmlns:xacro="http://www.ros.org/wiki/xacro">',
        '  <link name="${namespace}/base_link">',
        '    <neutrally_buoyant>0</neutrally_buoyant>',
        f'    <volume>{volume!r}</volume>',
        f'    <center_of_buoyancy>{_numbers(cob)}</center_of_buoyancy>',
        '    <hydrodynamic_model>',
        '      <type>fossen</type>',
        f'      <added_mass>{_numbers(parts.M_A)}</added_mass>',
        f'      <linear_damping>{_numbers(L)}</linear_damping>',
        f'      <linear_damping_forward_speed>{_numbers(Lf)}</linear_damping_forward_speed>',
        f'      <quadratic_damping>{_numbers(Q)}</quadratic_damping>',
        '    </hydrodynamic_model>',
        '  </link>',
        '</xacro:macro>']
    if thr_lines:
        # URDF links, joints and plugins: a macro beside the hydro model, not inside it; the
        # two macros in one xacro <robot> (one XML root)
        start = lines.index('-->') + 1
        lines = (lines[:start] + ['<robot xmlns:xacro="http://www.ros.org/wiki/xacro">']
                 + lines[start:]
                 + [f'<xacro:macro name="{v.name}_thrusters" params="namespace">', *thr_lines,
                    '</xacro:macro>', '</robot>'])
    return _xml_text(lines), fit


# ------------------------------------------------------------------------------------- gz

VEL = 'UVWPQR'
MOM = 'xyzkmn'
# the non-abs products nu_j nu_k, 1 <= j <= k; with u as well (U_PAIRS) only when the samples
# have u of both signs (an ROV): for u > 0 alone nu_j |u| holds them, and both columns would be
# the same (a torpedo's envelope)
PAIRS = [(j, k) for j in range(1, 6) for k in range(j, 6)]
U_PAIRS = [(0, k) for k in range(1, 6)]


def gz_pairs(nu):
    """The non-abs products the gz fit uses for samples nu (N, 6): PAIRS, and U_PAIRS when u
    takes both signs."""
    return (U_PAIRS if nu[:, 0].min() < 0.0 < nu[:, 0].max() else []) + PAIRS


def gz_columns(nu, pairs):
    """Regressors of gz-sim's damping: nu_j (xU..), nu_j |nu_k| (xUabsU..) and nu_j nu_k for
    (j, k) in pairs (xVV..: the bilinear terms, v r, w q, u w, ..., that the abs terms cannot
    hold when both factors change sign; the torpedo files' X_vr, X_wq need them, and an ROV's
    Munk moment M_uw u w, whose u changes sign, too)."""
    cols = [nu] + [nu[:, [j]] * np.abs(nu[:, [k]]) for j in range(6) for k in range(6)]
    cols += [nu[:, [j]] * nu[:, [k]] for j, k in pairs]
    return np.hstack(cols)


def gz_fit(parts, plugin_added_mass):
    """Damping parameters in FRD as {name: value} (SNAME signs, the plugin's names) and the
    fit % (6,). With <fluid_added_mass> the physics engine applies -M_A nu_dot - C_A(nu) nu,
    so the fit is to H + C_A(nu) nu; with the plugin's *Dot* terms its Coriolis is disabled
    (it applies +C_A(nu) nu, the wrong sign) and the fit is to H, whose added-mass Coriolis
    part is bilinear and held exactly by the non-abs quadratic terms (u factors: for u > 0)."""
    nu = parts.nu
    ca = (np.zeros_like(nu) if plugin_added_mass
          else np.array([coriolis_vector(parts.M_A, s) for s in nu]))
    pairs = gz_pairs(nu)
    cols = gz_columns(nu, pairs)
    coef = least_squares(cols, parts.H + ca)
    fit = fit_percent(parts.H, cols @ coef - ca)
    names = [f'{VEL[j]}' for j in range(6)] + [
        f'{VEL[j]}abs{VEL[k]}' for j in range(6) for k in range(6)]
    names += [f'{VEL[j]}{VEL[k]}' for j, k in pairs]
    return {MOM[i] + n: coef[c, i] for i in range(6) for c, n in enumerate(names)}, fit


def to_flu(name, value):
    """The FRD value of a gz parameter name in the link's FLU frame: each velocity factor
    of y, z, q, r and the force row of Y, Z, M, N change sign (an |.| factor does not)."""
    sign = FLU[MOM.index(name[0])]
    body = name[1:]
    if body.startswith('Dot'):
        return sign * FLU[VEL.index(body[3])] * value
    first, rest = body[0], body[1:]
    sign *= FLU[VEL.index(first)]
    if rest and not rest.startswith('abs'):
        sign *= FLU[VEL.index(rest)]
    return sign * value + 0.0     # + 0.0: no -0.0 in the file


def gz_text(saved, parts, header, added_mass='link'):
    plugin = added_mass == 'plugin'
    params, fit = gz_fit(parts, plugin)
    Ma = parts.M_A * np.outer(FLU, FLU)   # FLU
    if plugin:
        params.update({f'{MOM[i]}Dot{VEL[j]}': -parts.M_A[i, j]
                       for i in range(6) for j in range(6)})
    v = saved.vehicle
    lines = ['<?xml version="1.0"?>', '<!--'] + header + fit_lines(fit, 'the damping') + [
        'gz-sim Hydrodynamics system (src/systems/hydrodynamics/Hydrodynamics.cc). Frame: the',
        'link frame, FLU (x forward, y left, z up); our FRD values were turned into it here',
        '(T = diag(1, -1, -1) on the linear and the angular parts). The link origin must be our',
        'body origin. Signs: SNAME (xU = X_u < 0). The plugin applies to the link',
        '  tau = -Ma nu_dot + C(nu) nu + sum_j (xU_ij + sum_k xUabsU_ijk |nu_k|',
        '        + sum_k xUU_ijk nu_k) nu_j            (Ma = its *Dot* terms, negative)',
        'where C(nu) (HydrodynamicsUtils.hh buildCoriolisMatrix, diagonal Ma only) equals',
        "Fossen's C_A(nu) with M_A = -Ma: the plugin applies +C_A(nu) nu, not -C_A(nu) nu.",
        'C_A is skew, so this does no work, but it flips every Munk moment (the pitch Munk',
        'moment (Z_wdot - X_udot) u w becomes stabilising).',
        'The non-abs quadratic terms (xVR, ...) hold our bilinear terms (X_vr v r, ...);',
        'gz-sim warns that they "may cause instabilities" (they are not dissipative).',
    ]
    if plugin:
        lines += [
            "Here (option gz-added-mass plugin): the added mass as the plugin's *Dot* terms, its",
            'Coriolis disabled, and our added-mass Coriolis -C_A(nu) nu (bilinear) carried by',
            "the xVR-style quadratic terms. The plugin's added-mass force uses a one-step",
            'finite-difference acceleration (explicit: it can go unstable when M_A is large',
            'against the link mass).']
    else:
        lines += [
            'Here (option gz-added-mass link, the default; Gazebo Ionic+ with DART): the',
            'added mass as <fluid_added_mass> (21 elements of our M_A, positive, FLU, about the',
            "link origin); DART applies -M_A nu_dot - C_A(nu) nu itself (Fossen's sign, as",
            "the plugin's current correction assumes), so the plugin holds only damping.",
            'Why this is the default: the engine integrates the added mass implicitly (no',
            "finite-difference acceleration) with Fossen's Coriolis; the damping fit is the",
            'same either way.']
    thrusters, gain_lines = exported_thrusters(saved)
    if thrusters:
        lines += gain_lines + export_gz_thrusters.thruster_header(thrusters)
    lines += ["Weight, buoyancy (gz Buoyancy system), mass and inertia are the SDF's, not",
              "this snippet's.", '-->',
              '<sdf version="1.11">', f'  <model name="{v.name}">',
              '    <link name="base_link">']
    if not plugin:
        el = [(a + b, i, j) for i, a in enumerate('xyzpqr') for j, b in enumerate('xyzpqr')
              if j >= i]
        lines += ['      <inertial>', '        <fluid_added_mass>']
        lines += [f'          <{n}>{float(Ma[i, j]) + 0.0!r}</{n}>' for n, i, j in el]
        lines += ['        </fluid_added_mass>', '      </inertial>']
    lines += ['    </link>',
              '    <plugin filename="gz-sim-hydrodynamics-system"'
              ' name="gz::sim::systems::Hydrodynamics">',
              '      <link_name>base_link</link_name>',
              f'      <water_density>{float(v.raw["rho"])!r}</water_density>']
    if plugin:
        lines.append('      <disable_coriolis>true</disable_coriolis>')
    for name, value in params.items():
        if value != 0.0:
            lines.append(f'      <{name}>{float(to_flu(name, value))!r}</{name}>')
    lines.append('    </plugin>')
    lines += export_gz_thrusters.thruster_sdf(v, float(v.raw['rho']), thrusters)
    lines += ['  </model>', '</sdf>']
    return _xml_text(lines), fit


# ----------------------------------------------------------------------- urdf-hydrodynamics

def hydrodynamics_fit(parts):
    """The ROS 2 `hydrodynamics` library's damping (FRD, diagonal): tau_D = L nu + Q |nu| nu,
    fitted to H + C_A(diag M_A)(nu) nu (the library applies Fossen's -C_A of the diagonal
    added mass). Returns L (6,), Q (6,), fit % (6,)."""
    nu = parts.nu
    ca = np.array([coriolis_vector(np.diag(np.diag(parts.M_A)), s) for s in nu])
    y = parts.H + ca
    L, Q, fit = np.zeros(6), np.zeros(6), np.zeros(6)
    for i in range(6):
        cols = np.stack([nu[:, i], np.abs(nu[:, i]) * nu[:, i]], axis=1)
        coef = least_squares(cols, y[:, i:i + 1])
        L[i], Q[i] = coef[0, 0], coef[1, 0]
        fit[i] = fit_percent(parts.H[:, i:i + 1], cols @ coef - ca[:, i:i + 1])[0]
    return L, Q, fit


def _attrs(names, values):
    return ' '.join(f'{n}="{float(x) + 0.0!r}"' for n, x in zip(names, values))


LIB_G = 9.81    # m/s^2: the library's weight is mass * 9.81 (parse_model_from_xml)


def _xyz(values):
    return ' '.join(f'{a}="{float(x) + 0.0!r}"' for a, x in zip('xyz', values))


def _products(inertia):
    """Header lines for products of inertia the export leaves out: the library's parser puts
    ixy, ixz, iyz into the upper triangle only (inertia(0, 1) = ixy, inertia(1, 0) stays 0),
    an unsymmetric inertia; none is better than that."""
    prod = {k: float(inertia[k]) for k in ('Ixy', 'Ixz', 'Iyz') if float(inertia[k]) != 0.0}
    if not prod:
        return []
    return ['Left out: the products of inertia ' + ', '.join(f'{k} {x:.6g}' for k, x in
                                                             prod.items()),
            "(the library's parser fills only the upper triangle of the inertia matrix)."]


def hydrodynamics_text(saved, parts, header):
    L, Q, fit = hydrodynamics_fit(parts)
    v = saved.vehicle
    raw = v.raw
    inertia = raw['inertia']
    mass, W = float(raw['mass']), float(raw['W'])
    off = [(f'{"XYZKMN"[i]}{"XYZKMN"[j]}', parts.M_A[i, j]) for i in range(6)
           for j in range(6) if i != j and parts.M_A[i, j] != 0.0]
    weight = ([] if abs(W - mass * LIB_G) <= 1e-9 * W else [
        f'WARNING: the library takes the weight as mass * {LIB_G:g} = {mass * LIB_G:.6g} N; this',
        f'vehicle file has W = {W:.6g} N (another g or a trim weight): the restoring force',
        f'differs by {W - mass * LIB_G:.6g} N. Set the buoyancy accordingly.'])
    lines = ['<?xml version="1.0"?>', '<!--'] + header + fit_lines(fit, 'the damping') + [
        'ROS 2 `hydrodynamics` library (Robotic-Decision-Making-Lab/hydrodynamics, src/',
        'hydrodynamics.cpp parse_model_from_xml and forward_dynamics), read by auv_controllers:',
        'FRD body, NED world, SNAME signs:',
        '  M = M_RB(m, I, r_G) - diag(Xdu .. Ndr)',
        "  C = C_RB(nu) + C_A(nu) (Fossen's, from the rigid-body and the diagonal added mass)",
        '  D = -diag(Xu .. Nr) - diag(Xuu |u| .. Nrr |r|)',
        '  g = -[R^T (f_g + f_b); r_G x R^T f_g + r_B x R^T f_b], f_g = (0, 0, m 9.81),',
        '      f_b = (0, 0, -buoyancy)',
        '  nu_dot = M^-1 (tau - C nu - D nu - g)',
        'The damping is diagonal: cross terms (Y_r, N_v, M_w, Z_q, Munk moments the diagonal',
        'C_A does not give) are fitted away. Not held by the library (left out): any',
        'off-diagonal added mass' + (': ' + ', '.join(f'{n} {x:.6g}' for n, x in off) if off
                                     else ' (none here).'),
        *weight, *_products(inertia),
        '-->',
        f'<robot name="{v.name}">',
        '  <hydrodynamics>',
        '    <inertial>',
        f'      <mass value="{mass!r}" />',
        '      <inertia ' + _attrs(('ixx', 'iyy', 'izz'),
                                   [inertia[k] for k in ('Ix', 'Iy', 'Iz')]) + ' />',
        '      <center_of_gravity ' + _xyz(raw['r_G']) + ' />',
        '      <added_mass ' + _attrs(('Xdu', 'Ydv', 'Zdw', 'Kdp', 'Mdq', 'Ndr'),
                                      -np.diag(parts.M_A)) + ' />',
        '    </inertial>',
        '    <damping>',
        '      <linear ' + _attrs(('Xu', 'Yv', 'Zw', 'Kp', 'Mq', 'Nr'), L) + ' />',
        '      <quadratic ' + _attrs(('Xuu', 'Yvv', 'Zww', 'Kpp', 'Mqq', 'Nrr'), Q) + ' />',
        '    </damping>',
        '    <hydrostatics>',
        f'      <buoyancy value="{float(raw["B"])!r}" />',
        '      <center_of_buoyancy ' + _xyz(raw['r_B']) + ' />',
        '    </hydrostatics>',
        '  </hydrodynamics>',
        '</robot>']
    return _xml_text(lines), fit
