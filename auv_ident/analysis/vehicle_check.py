"""``python -m auv_ident vehicle check FILE``: is this vehicle file ready to simulate and to be
identified with? Every problem of its entries at once (the loader collects them,
core/model/vehicle.py VehicleFileProblems), then what a model engineer looks at before the first
run: the straight run's trim, the stability of the velocity dynamics there, the static
stability in roll and pitch, the net buoyancy, damping derivatives with the sign physics
forbids (core/identification/plausibility.py), and for a thruster vehicle which of its degrees
of freedom the thrusters can push alone (core/model/thrusters.py).

A glider's file (``kind: glider``, config/slocum_comet.yaml) is checked as what it is: its keys
(core/glider/vehicle.py), the water density it is neutral in and its best glide; the 6-DOF
checks (trim, eigenvalues, thrusters) do not apply to it and are said not to.

Findings are ``error`` (the file does not load, or the vehicle has no straight run: nothing can
be simulated) or ``warning`` (it loads and flies, but a value is unusual: read it again).
"""
from dataclasses import dataclass, field
import math

import numpy as np

from auv_ident.core.errors import ConfigError, DomainError
from auv_ident.core.glider.vehicle import glider_from_file
from auv_ident.core.identification.plausibility import is_self_damping
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import DOF_STATES, Input, NU_NAMES, State
from auv_ident.core.model.thrusters import configuration_matrix, curve_text
from auv_ident.core.model.trim import initial_state, rest_inputs, trim_speed
from auv_ident.core.model.vehicle import P_ZB, P_ZG, vehicle_from_file
from auv_ident.core.vehicle_files import file_kind, read_yaml_file, VehicleFileProblems
from auv_ident.vehicles import resolve_vehicle_path

# a degree of freedom is pushed alone when its unit wrench is T a for some thrusts a: the
# least-squares residual of T a = e_k below this (relative; T's columns are O(1) by the unit d)
ACTUATED_TOL = 1e-9
NET_BUOYANCY_WARN = 0.05    # |B - W| / W above this: a vehicle that surfaces or sinks hard
# kg/m^3: the water a glider can be ballasted for, from fresh water to the densest ocean water
# at depth; a glider neutral outside it has its mass or its volume in the wrong unit
GLIDER_NEUTRAL_DENSITY = (995.0, 1060.0)


@dataclass
class VehicleCheck:
    """What ``vehicle check`` found: ``errors`` and ``warnings`` (texts), ``facts`` (what was
    measured: trim speed, eigenvalues, ...) and the vehicle's name ('' if it did not load)."""

    path: str
    name: str = ''
    errors: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    facts: list = field(default_factory=list)

    @property
    def ok(self):
        return not self.errors

    def lines(self):
        head = (f'{self.path}: vehicle {self.name!r} loads' if self.name
                else f'{self.path}: does not load')
        verdict = ('ready' if self.ok and not self.warnings else
                   f'{len(self.warnings)} warning(s)' if self.ok else
                   f'{len(self.errors)} error(s)')
        out = [f'{head}: {verdict}']
        out += [f'  error: {e}' for e in self.errors]
        out += [f'  warning: {w}' for w in self.warnings]
        out += [f'  {f}' for f in self.facts]
        return out


def _static_checks(vehicle, check):
    raw = vehicle.raw
    W, B = float(raw['W']), float(raw['B'])
    net = (B - W) / W
    check.facts.append(f'net buoyancy (B - W) / W = {net:+.2%}')
    if abs(net) > NET_BUOYANCY_WARN:
        check.warnings.append(f'B and W differ by {net:+.1%} of W: the vehicle '
                              f'{"rises" if net > 0 else "sinks"} hard (check both, in N)')
    z_g, z_b = float(vehicle.par[P_ZG]), float(vehicle.par[P_ZB])
    bg = z_g - z_b
    check.facts.append(f'BG (z_G - z_B, down) = {bg:+.4g} m')
    if vehicle.free_states[State.P] or vehicle.free_states[State.Q]:
        if bg <= 0:
            check.warnings.append(f'the centre of gravity is not below the centre of buoyancy '
                                  f'(z_G - z_B = {bg:+.3g} m, FRD): no restoring moment in '
                                  'roll and pitch (check the signs of r_G and r_B: z is down)')
    wrong = [c.name for c in vehicle.coefficients if is_self_damping(c) and c.value > 0]
    if wrong:
        check.warnings.append('damping derivatives with a positive value (they take energy '
                              'out of their own motion, so negative): ' + ', '.join(wrong))


def _thruster_checks(vehicle, check):
    T = configuration_matrix(vehicle.thrusters)
    dofs = [d for d, (vel, _) in DOF_STATES.items() if vehicle.free_states[vel]]
    alone = []
    for d in dofs:
        e = np.zeros(6)
        e[DOF_STATES[d][0]] = 1.0
        a = np.linalg.lstsq(T, e, rcond=None)[0]
        if np.linalg.norm(T @ a - e) < ACTUATED_TOL:
            alone.append(d)
    check.facts.append(f'{len(vehicle.thrusters)} thrusters, configuration matrix of rank '
                       f'{np.linalg.matrix_rank(T)}; they push alone: {" ".join(alone) or "none"}')
    curves: dict = {}          # one line per distinct curve, naming its thrusters
    for t in vehicle.thrusters:
        limits = (f', thrust within -{t.thrust_max_reverse:g}..{t.thrust_max_forward:g} N'
                  if max(t.thrust_max_reverse, t.thrust_max_forward) < math.inf else '')
        curves.setdefault(curve_text(t) + limits, []).append(t.name)
    check.facts += [f'thrust curves: {" ".join(names)}: {text}' for text, names in curves.items()]
    check.facts.append(_lag_text(vehicle))
    torque = [f'{t.name} {t.torque_ratio:+g}' for t in vehicle.thrusters if t.torque_ratio]
    if torque:
        check.facts.append('propeller torque about each axis, N m per N (torque_ratio): '
                           + ', '.join(torque))
    missing = [d for d in dofs if d not in alone]
    if missing:
        check.warnings.append(f'the thrusters cannot push {" ".join(missing)} alone (each '
                              'only with other motion): check r and d of each thruster (FRD) '
                              'if the vehicle is meant to')


def _lag_text(vehicle):
    """One line saying the thrusters' lag (core/model/thruster_lag.py)."""
    if vehicle.lag_idx >= 0:
        c = vehicle.coefficients[vehicle.lag_idx]
        return (f'thruster lag: first order, tau = {c.value:g} s for every thruster (coefficient '
                f'{c.name}, identifiable)')
    own = [f'{t.name} {t.time_constant:g}' for t in vehicle.thrusters if t.time_constant > 0]
    if own:
        return f'thruster lag: first order, fixed time constants (s): {", ".join(own)}'
    return 'thruster lag: none (the thrust follows the commands at once)'


def _eigen_text(eig):
    return ', '.join(f'{e.real:.3g}' + (f'{e.imag:+.3g}j' if abs(e.imag) > 1e-9 else '')
                     for e in sorted(eig, key=lambda e: e.real))


def _hover_checks(vehicle, check):
    """A thruster vehicle has no straight run: its trim is hovering at rest, thrusters at
    neutral; the net weight is what the vertical thrusters hold, and the dynamics at rest
    (velocities and roll, pitch: their restoring) are linearised there."""
    model = Model(vehicle)
    x = initial_state(model, 0.0)
    u = rest_inputs(model)
    xdot, A, _ = model.jacobians(x, u)
    force = np.asarray(model.vehicle.mass_matrix() @ xdot[:6])
    T = configuration_matrix(vehicle.thrusters)
    f_max = np.array([min(t.thrust_max_forward, t.thrust(t.neutral + t.command_max))
                      for t in vehicle.thrusters])
    reach = np.abs(T[:3]) @ f_max
    check.facts.append(f'at rest, thrusters neutral: net force X Y Z = {force[0]:+.3g} '
                       f'{force[1]:+.3g} {force[2]:+.3g} N (the thrusters reach '
                       f'{reach[0]:.3g} {reach[1]:.3g} {reach[2]:.3g} N)')
    if np.any(np.abs(force[:3]) > 0.5 * reach):
        check.errors.append('the thrusters cannot hold the vehicle at rest (its net weight is '
                            'more than half their reach): check W, B and the thrust curves')
    keep = [i for i in range(6) if vehicle.free_states[i]]
    keep += [i for i in (State.PHI, State.THETA) if vehicle.free_states[i]]
    eig = np.linalg.eigvals(A[np.ix_(keep, keep)])
    names = ' '.join(NU_NAMES[i] if i < 6 else ('phi', 'theta')[i - State.PHI] for i in keep)
    check.facts.append(f'eigenvalues at rest ({names}), 1/s: {_eigen_text(eig)}')
    unstable = [e for e in eig if e.real > 1e-9]
    if unstable:
        check.warnings.append(f'{len(unstable)} unstable mode(s) at rest (largest real part '
                              f'{max(e.real for e in unstable):.3g} 1/s): check the damping '
                              'signs and BG')


def _trim_checks(vehicle, check):
    if vehicle.hovers:
        _hover_checks(vehicle, check)
        return
    model = Model(vehicle)
    try:
        speed = trim_speed(model, vehicle.cruise_rpm)
    except DomainError as err:
        check.errors.append(f'no straight run at cruise_rpm {vehicle.cruise_rpm:g}: {err}')
        return
    check.facts.append(f'straight run at cruise_rpm {vehicle.cruise_rpm:g}: u = {speed:.3f} m/s')
    x = initial_state(model, vehicle.cruise_rpm)
    u = rest_inputs(model)
    u[Input.N_RPM] = vehicle.cruise_rpm
    u[Input.THRUST] = vehicle.cruise_thrust
    free = [i for i in range(6) if vehicle.free_states[i]]
    J = model.jacobians(x, u)[1][np.ix_(free, free)]   # d(nu_dot)/d(nu), analytic
    eig = np.linalg.eigvals(J)
    text = _eigen_text(eig)
    states = ' '.join(NU_NAMES[i] for i in free)
    check.facts.append(f'eigenvalues of the velocity dynamics ({states}) there, 1/s: {text}')
    unstable = [e for e in eig if e.real > 0]
    if unstable:
        check.warnings.append(
            f'{len(unstable)} unstable mode(s) of the straight run (largest real part '
            f'{max(e.real for e in unstable):.3g} 1/s): common in sway/yaw for slender '
            'AUVs (then steer in closed loop); elsewhere, check the damping signs')


def _glider_checks(glider, check):
    """A GliderVehicle's checks (module docstring), into check."""
    p = glider.params
    check.facts.append('a glider file (kind: glider): its flight model is core/glider '
                       '(docs/glider.md); the 6-DOF checks (trim, eigenvalues, thrusters) do '
                       'not apply')
    check.facts.append(f'prior: {glider.prior}; pitch: {glider.pitch_source}')
    neutral = p.mass / p.hull_volume
    check.facts.append(f'neutral with nothing pumped in water of m / V_g = {neutral:.1f} kg/m^3')
    lo, hi = GLIDER_NEUTRAL_DENSITY
    if not lo <= neutral <= hi:
        check.warnings.append(f'mass / hull_volume = {neutral:.4g} kg/m^3 is outside the '
                              f'waters a glider is ballasted for ({lo:g}-{hi:g}): check the '
                              'units of mass (kg) and hull_volume (m^3)')
    if p.induced_drag > 0:
        # the best glide ratio: alpha* = sqrt(C_D0 / C_D1), tan(gamma*) = 2 sqrt(C_D0 C_D1) /
        # C_La; flatter pitches have no steady glide (core/glider/flight.py angle_of_attack)
        alpha = math.sqrt(p.drag_zero_lift / p.induced_drag)
        gamma = math.atan(2.0 * math.sqrt(p.drag_zero_lift * p.induced_drag) / p.lift_slope)
        check.facts.append(f'best glide: glide angle {math.degrees(gamma):.1f} deg at an angle '
                           f'of attack of {math.degrees(alpha):.1f} deg (pitch '
                           f'{math.degrees(gamma - alpha):.1f} deg); flatter, no steady glide')
    return check


def check_vehicle(name_or_path):
    """A VehicleCheck of a vehicle name (config/) or YAML path; raises nothing for a bad file
    (its problems are the check's errors) but ConfigError for a path that does not exist."""
    path = resolve_vehicle_path(name_or_path)
    check = VehicleCheck(path=str(name_or_path))
    try:
        glider = file_kind(read_yaml_file(path)) == 'glider'
        vehicle = glider_from_file(path) if glider else vehicle_from_file(path)
    except VehicleFileProblems as err:
        check.errors.extend(err.problems)
        return check
    except ConfigError as err:
        check.errors.append(str(err))
        return check
    check.name = vehicle.name
    if glider:
        return _glider_checks(vehicle, check)
    _static_checks(vehicle, check)
    if vehicle.thrusters:
        _thruster_checks(vehicle, check)
    _trim_checks(vehicle, check)
    return check
