"""A thruster vehicle's thrusters as gz-sim Thruster systems (``export --format gz``).

gz-sim's Thruster system (src/systems/thruster/Thruster.cc) takes, per propeller joint, a
command that is either the thrust in N (default) or the propeller's angular velocity omega in
rad/s (``use_angvel_cmd``), clamps it to [min_thrust_cmd, max_thrust_cmd] (default +-1000),
zeroes a thrust below ``deadband`` (N), turns an angular velocity into thrust with
``thrust = thrust_coefficient fluid_density propeller_diameter^4 |omega| omega`` and applies
the thrust along the joint axis (rotated into the world) at the origin of the joint's child
link (``Link::AddWorldWrench`` at the link origin). So the body wrench of one thruster is
[d f; r x d f] with r the child link's origin and d the joint axis, as ours
(core/model/thrusters.py), once both are in the link frame (FLU: y, z negated).

Ours is a thrust curve of the command (PWM, setpoint, rpm, or the force itself): a dead band,
then a1 e + a2 e^2 on each side, saturated. gz has no such curve:

- thrust commands (the export): gz applies exactly the thrust it is sent, clamped to the
  limits written here (our curve at +-command_max, within thrust_max_*), so the wrench is
  exact when the controller sends our curve's thrust for its command (the curve is written in
  the comment next to each thruster);
- angular-velocity commands: gz's thrust is c |e| e in any quantity e proportional to omega.
  The best such law (c fitted by least squares over the command range, both sides: gz has
  one coefficient) is reported with its fit % to our curve; a thrust_coefficient and
  propeller_diameter are written only for an `rpm` thruster whose file entry gives
  `propeller_diameter` (m), where omega = 2 pi rpm / 60 is known, so Ct = c / (rho D^4
  (2 pi / 60)^2). A PWM or setpoint thruster's command-to-omega map is not in the file.
"""
import dataclasses
import math

import numpy as np

from auv_ident.core.errors import AuvIdentError
from auv_ident.core.model.thrusters import curve_text

N_CURVE = 801       # samples of the command range for the quadratic-law fit
FLU3 = np.array([1.0, -1.0, -1.0])


class GainError(AuvIdentError):
    """A thrust gain that no per-thruster curve can carry (named)."""


def with_gains(v, c):
    """The vehicle's thrusters with its thrust gains (values c, the file's coefficient order:
    the identified ones in place) folded into their curves, and the file's `thruster_lag`
    coefficient (c's value) as each one's time_constant: the model applies gain * f per
    equation and curve side (core/model/hydrodynamics.py _thrusters), which is one thruster's
    curve side times the gain when that gain is the same in every equation the thruster
    pushes in (a gain of all six, or of XYN with horizontal thrusters only). Since
    g sat(f, f_max) = sat(g f, g f_max) for g > 0, the scaled curve is
    (g a1, g a2) with its saturation g f_max: exact. GainError naming the gain otherwise."""
    out = []
    for t in v.thrusters:
        sides = {}
        rows = [e for e in range(6) if t.column[e] != 0.0]
        for side in (0, 1):
            g = dict.fromkeys(rows, 1.0)
            names = {}
            for ci, co in enumerate(v.coefficients):
                if co.is_thrust_gain and side in co.gain_sides:
                    for e in co.gain_rows:
                        if e in g:
                            g[e], names[e] = float(c[ci]), co.name
            values = set(g.values())
            if len(values) > 1:
                raise GainError(
                    f'thrust gain {", ".join(sorted(set(names.values())))}: thruster {t.name} '
                    f'pushes in {"".join("XYZKMN"[e] for e in rows)} but the gain scales only '
                    'some of those equations; a simulator thruster has one curve, so this '
                    'model cannot be exported exactly (identify one gain per side of all six)')
            value = values.pop() if values else 1.0
            if value <= 0.0:
                raise GainError(f'thrust gain {names.get(rows[0], "?")} = {value!r}: not '
                                'positive, so no thrust curve carries it')
            sides[side] = value
        gf, gr = sides[0], sides[1]
        out.append(dataclasses.replace(
            t, forward=(gf * t.forward[0], gf * t.forward[1]),
            reverse=(gr * t.reverse[0], gr * t.reverse[1]),
            table=None if t.table is None else _scaled_table(t.table, gf, gr),
            thrust_max_forward=gf * t.thrust_max_forward,
            thrust_max_reverse=gr * t.thrust_max_reverse,
            # the shared time constant (multiplier thruster_lag), identified or the file's
            time_constant=float(c[v.lag_idx]) if v.lag_idx >= 0 else t.time_constant))
    return out, sides_text(v, c)


def _scaled_table(table, gf, gr):
    """A thrust table (rows command, thrust N, slope N per unit) with its forward points
    (thrust > 0) times gf and its reverse points times gr, slopes alike: the model's gain
    times the table's cubic on every interval within one side, so exact where no interval
    runs from reverse to forward thrust directly (a table with a dead band: its zero-thrust
    points have zero slope, as the monotone cubic makes them at a plateau's ends)."""
    out = np.array(table, dtype=float)
    f = out[1]
    gain = np.where(f > 0.0, gf, np.where(f < 0.0, gr, 1.0))
    out[1] = f * gain
    out[2] = out[2] * gain
    return out


def sides_text(v, c):
    """Header lines naming the thrust gains folded into the exported curves."""
    gains = [(co.name, float(c[ci])) for ci, co in enumerate(v.coefficients)
             if co.is_thrust_gain]
    if not gains:
        return []
    return ["Thrust gains folded into the curves below (gain times the file's curve side and",
            'its saturation): ' + ', '.join(f'{n} = {g!r}' for n, g in gains) + '.']


def _r(x):
    return repr(float(x) + 0.0)


def command_range(t):
    """(lo, hi) of the thruster's command (its unit): neutral -+ command_max."""
    return t.neutral - t.command_max, t.neutral + t.command_max


def quadratic_law_fit(t):
    """(c, fit %) of gz's angular-velocity law f = c |e| e (e = command - neutral, c in N per
    unit^2) to our curve over the command range; (nan, nan) for a force thruster or one
    without a finite range."""
    lo, hi = command_range(t)
    if t.command == 'force' or not (math.isfinite(lo) and math.isfinite(hi)):
        return math.nan, math.nan
    cmd = np.linspace(lo, hi, N_CURVE)
    f = np.array([t.thrust(c) for c in cmd])
    e = cmd - t.neutral
    x = np.abs(e) * e
    c = float(x @ f / (x @ x))
    fit = 100.0 * (1.0 - np.linalg.norm(f - c * x) / np.linalg.norm(f - f.mean()))
    return c, float(fit)


def limits(t):
    """(min_thrust_cmd, max_thrust_cmd) N: our curve at the ends of its command range (the
    force thruster: its thrust limits); None where infinite (gz's default +-1000 N applies)."""
    lo, hi = command_range(t)
    fmin, fmax = t.thrust(lo), t.thrust(hi)
    return (fmin if math.isfinite(fmin) else None), (fmax if math.isfinite(fmax) else None)


def thruster_header(thrusters):
    """Header lines for the thrusters (what is exact, the fit of gz's quadratic law)."""
    lines = ['Thrusters: gz-sim Thruster systems (src/systems/thruster/Thruster.cc), one per',
             'thruster of the vehicle file: a revolute joint <NAME>_joint from base_link to',
             'the propeller link <NAME>_propeller at the thruster position r (FLU), axis d',
             '(FLU). gz applies the commanded thrust (N) along the axis at the propeller',
             "link's origin: exactly our [d f; r x d f] when the controller sends our curve's",
             'thrust for its command. gz has no PWM/setpoint curve; with use_angvel_cmd its',
             'thrust is Ct rho D^4 |omega| omega, a quadratic law whose best fit to our curve',
             'is given per thruster (fit %). velocity_control true: the propeller joint is',
             'driven at the commanded speed, no PID torque on the link. Give each propeller',
             "link your propeller's <inertial> (SDF's default is 1 kg).",
             'thrust_max_forward/-reverse and the curve at the command range become',
             'max/min_thrust_cmd.']
    for t in thrusters:
        c, fit = quadratic_law_fit(t)
        law = ('exact (a force command)' if not math.isfinite(fit) else
               f'quadratic law f = {c:.6g} |e| e fits our curve to {fit:.2f} %')
        lines.append(f'  {t.name}: {curve_text(t)}; {law}')
    return lines


def thruster_fits(thrusters):
    """{name: fit %} of the quadratic law per thruster (NaN: exact, a force command)."""
    return {t.name: quadratic_law_fit(t)[1] for t in thrusters}


def thruster_sdf(v, rho, thrusters):
    """The SDF lines of the thrusters' links, joints and Thruster systems (inside <model>);
    thrusters: v's, with their gains (with_gains)."""
    out = []
    for t in thrusters:
        r = FLU3 * t.position
        d = FLU3 * t.direction
        fmin, fmax = limits(t)
        out += [f'    <link name="{t.name}_propeller">',
                f'      <pose relative_to="base_link">{" ".join(_r(x) for x in r)} 0 0 0</pose>',
                '    </link>',
                f'    <joint name="{t.name}_joint" type="revolute">',
                '      <parent>base_link</parent>', f'      <child>{t.name}_propeller</child>',
                f'      <axis><xyz expressed_in="base_link">{" ".join(_r(x) for x in d)}</xyz>'
                '</axis>',
                '    </joint>']
    for t in thrusters:
        fmin, fmax = limits(t)
        out += ['    <plugin filename="gz-sim-thruster-system" '
                'name="gz::sim::systems::Thruster">',
                f'      <joint_name>{t.name}_joint</joint_name>',
                f'      <fluid_density>{_r(rho)}</fluid_density>',
                '      <velocity_control>true</velocity_control>']
        if fmax is not None:
            out.append(f'      <max_thrust_cmd>{_r(fmax)}</max_thrust_cmd>')
        if fmin is not None:
            out.append(f'      <min_thrust_cmd>{_r(fmin)}</min_thrust_cmd>')
        diameter = _diameter(v, t)
        if t.command == 'rpm' and diameter is not None:
            c, _ = quadratic_law_fit(t)
            ct = c / (rho * diameter ** 4 * (2.0 * math.pi / 60.0) ** 2)
            out += [f'      <propeller_diameter>{_r(diameter)}</propeller_diameter>',
                    f'      <thrust_coefficient>{_r(ct)}</thrust_coefficient>']
        out.append('    </plugin>')
    return out


def _diameter(v, t):
    """The thruster entry's `propeller_diameter` (m) in the vehicle file, or None."""
    for entry in v.raw.get('thrusters') or ():
        if isinstance(entry, dict) and str(entry.get('name', '')) == t.name:
            d = entry.get('propeller_diameter')
            if isinstance(d, (int, float)) and not isinstance(d, bool) and d > 0:
                return float(d)
    return None


# ------------------------------------------------------------ uuv_simulator ThrusterPlugin

N_TABLE = 64     # interpolation nodes per side of the curve (uuv LinearInterp)


def uuv_table(t):
    """(inputs, outputs) of uuv_simulator's LinearInterp conversion for thruster t: our curve
    at the command range's ends, the dead band's edges and N_TABLE nodes per side between
    them (a force thruster: the identity over its thrust limits, or +-1000 N). Linear
    interpolation between nodes; the largest error is returned by uuv_table_error."""
    lo, hi = command_range(t)
    if t.command == 'force':
        a = -t.thrust_max_reverse if math.isfinite(t.thrust_max_reverse) else -1000.0
        b = t.thrust_max_forward if math.isfinite(t.thrust_max_forward) else 1000.0
        cmd = np.array([a, 0.0, b])
    else:
        n0 = t.neutral
        # a table's own points too: its dead band's edges and its kinks are among them
        own = [] if t.table is None else t.table[0]
        cmd = np.unique(np.concatenate([
            np.linspace(lo, n0 - t.dead_band, N_TABLE + 1),
            np.linspace(n0 + t.dead_band, hi, N_TABLE + 1), [n0], own]))
        if t.table is not None:
            cmd = _refined(t, cmd)
    return cmd, np.array([t.thrust(c) for c in cmd])


UUV_TABLE_TOL = 2e-3   # N: the largest linear-interpolation error a table curve is refined to


def _refined(t, cmd, depth=8):
    """Nodes ``cmd`` with each interval halved until the straight line between its ends is
    within UUV_TABLE_TOL of our curve at its quarter points (a table's monotone cubic bends
    between the published points where their increments are uneven: up to 0.12 N off the
    chord on the T200 table; a few intervals need it, so the table stays short)."""
    for _ in range(depth):
        a, b = cmd[:-1], cmd[1:]
        fa = np.array([t.thrust(c) for c in a])
        fb = np.array([t.thrust(c) for c in b])
        bad = np.zeros(len(a), dtype=bool)
        for w in (0.25, 0.5, 0.75):
            x = a + w * (b - a)
            bad |= np.abs(np.array([t.thrust(c) for c in x]) - (fa + w * (fb - fa))) \
                > UUV_TABLE_TOL
        if not bad.any():
            break
        cmd = np.unique(np.concatenate([cmd, 0.5 * (a[bad] + b[bad])]))
    return cmd


def uuv_table_error(t):
    """Largest |table interpolation - our curve| (N) over the command range (1e4 points)."""
    cmd, out = uuv_table(t)
    x = np.linspace(cmd[0], cmd[-1], 10001)
    return float(np.max(np.abs(np.interp(x, cmd, out) - [t.thrust(c) for c in x])))


def uuv_thruster_lines(thrusters):
    """uuv_simulator thruster units (uuv_gazebo_plugins ThrusterPlugin.cc): per thruster a
    link, a continuous joint at r with axis d (the link frame, FLU) and the plugin with a
    LinearInterp conversion of our curve, clamps and the thrust limits; (header lines, xacro
    lines)."""
    header = ['Thrusters: uuv_simulator thruster units (ThrusterPlugin.cc): the command is',
              'clamped to [clampMin, clampMax] (our command range, in its unit), passed',
              'through the dynamics (ZeroOrder; FirstOrder with our time_constant, but uuv',
              'lags the command, before the curve, where ours lags the thrust: equal in',
              'steady state only), turned into thrust by LinearInterp of a table of our curve,',
              'clamped to [thrustMin, thrustMax] and applied along the joint axis on the',
              'thruster link (AddRelativeForce). Table nodes at the dead-band edges and',
              f'{N_TABLE} per side. Give each thruster link an <inertial> (Gazebo drops a',
              'link without one). The largest interpolation error per thruster:']
    lines = []
    for i, t in enumerate(thrusters):
        cmd, out = uuv_table(t)
        header.append(f'  {t.name}: {uuv_table_error(t):.3g} N')
        r, d = FLU3 * t.position, FLU3 * t.direction
        lo, hi = (cmd[0], cmd[-1])
        dyn = (['      <dynamics><type>FirstOrder</type>'
                f'<timeConstant>{_r(t.time_constant)}</timeConstant></dynamics>']
               if t.time_constant > 0 else ['      <dynamics><type>ZeroOrder</type></dynamics>'])
        lines += [f'  <link name="${{namespace}}/thruster_{i}"/>',
                  f'  <joint name="${{namespace}}/thruster_{i}_joint" type="continuous">',
                  f'    <origin xyz="{" ".join(_r(x) for x in r)}" rpy="0 0 0"/>',
                  f'    <axis xyz="{" ".join(_r(x) for x in d)}"/>',
                  '    <parent link="${namespace}/base_link"/>',
                  f'    <child link="${{namespace}}/thruster_{i}"/>',
                  '  </joint>',
                  '  <gazebo>',
                  f'    <plugin name="${{namespace}}_{i}_thruster_model" '
                  'filename="libuuv_thruster_ros_plugin.so">',
                  f'      <linkName>${{namespace}}/thruster_{i}</linkName>',
                  f'      <jointName>${{namespace}}/thruster_{i}_joint</jointName>',
                  f'      <thrusterID>{i}</thrusterID>   <!-- {t.name} ({t.command}) -->',
                  *dyn,
                  '      <conversion><type>LinearInterp</type>',
                  f'        <inputValues>{" ".join(_r(x) for x in cmd)}</inputValues>',
                  f'        <outputValues>{" ".join(_r(x) for x in out)}</outputValues>',
                  '      </conversion>',
                  f'      <clampMin>{_r(lo)}</clampMin>', f'      <clampMax>{_r(hi)}</clampMax>',
                  f'      <thrustMin>{_r(out.min())}</thrustMin>',
                  f'      <thrustMax>{_r(out.max())}</thrustMax>',
                  '    </plugin>',
                  '  </gazebo>']
    return header, lines
