"""The state and input layouts, named once: use these instead of bare indices.

Vehicle state (SNAME/Fossen, body FRD, world NED)::

    x = [u v w p q r x y z phi theta psi]
         nu (body velocities)   eta (position, ZYX Euler angles)

- ``u v w`` (m/s): linear body velocity; ``p q r`` (rad/s): angular body velocity;
- ``x y z`` (m): NED position; ``phi theta psi`` (rad): roll, pitch, yaw.

Augmented filter state ``x* = [x (12), theta_1 .. theta_p]``: the identified coefficients follow
the vehicle state (:data:`COEFFICIENTS`).

Input (actuator) vector::

    u = [delta_r delta_s delta_b delta_bp delta_bs n_rpm thrust]

rudder, stern planes, top/bottom bow planes, port and starboard bow planes (rad), shaft speed
(rpm), measured propeller thrust (N). The thrust is an input of vehicles whose propulsion is
`measured_thrust` (a ship model with a thrust dynamometer, core/model/vehicle.py); the others
ignore it (0 in their runs and bags).
"""
from enum import IntEnum


class State(IntEnum):
    """Index of each vehicle state in x (and in the augmented x*)."""

    U = 0
    V = 1
    W = 2
    P = 3
    Q = 4
    R = 5
    X = 6
    Y = 7
    Z = 8
    PHI = 9
    THETA = 10
    PSI = 11


class Input(IntEnum):
    """Index of each actuator in the input vector u."""

    DELTA_R = 0
    DELTA_S = 1
    DELTA_B = 2
    DELTA_BP = 3
    DELTA_BS = 4
    N_RPM = 5
    THRUST = 6


N_STATE = 12                # vehicle states
N_NU = 6                    # body velocities
N_INPUT = 7                 # actuator channels (the thrust last)
N_FINS = 5                  # fin channels (the inputs before the shaft speed)

NU = slice(0, 6)            # u v w p q r
LINEAR = slice(0, 3)        # u v w (m/s)
ANGULAR = slice(3, 6)       # p q r (rad/s)
ETA = slice(6, 12)          # x y z phi theta psi
POSITION = slice(6, 9)      # x y z (m)
EULER = slice(9, 12)        # phi theta psi (rad)
VEHICLE = slice(0, N_STATE)     # the vehicle part of the augmented state
COEFFICIENTS = slice(N_STATE, None)  # the identified coefficients in the augmented state
FINS = slice(0, N_FINS)     # fin deflections in u (rad)

STATE_NAMES = tuple(s.name.lower() for s in State)
STATE_UNITS = ('m/s',) * 3 + ('rad/s',) * 3 + ('m',) * 3 + ('rad',) * 3
INPUT_NAMES = tuple(i.name.lower() for i in Input)
INPUT_UNITS = ('rad',) * 5 + ('rpm', 'N')
NU_NAMES = STATE_NAMES[NU]
ANGLE_STATES = (State.PHI, State.THETA, State.PSI)  # innovations of these are wrapped to (-pi, pi]

# The water current (core/model/hydrodynamics.py), NED, m/s: its components as parameters of the
# augmented vector are named CURRENT_NAMES and come after the coefficients
N_CURRENT = 3
CURRENT_NAMES = ('current_n', 'current_e', 'current_d')
# what the velocity sensor measures, hence what the state's u v w are: 'ground' (DVL in bottom
# lock: nu over ground) or 'water' (water-track DVL: nu_r, the velocity through the water)
VELOCITY_REFERENCES = ('ground', 'water')

# Degrees of freedom a vehicle file may declare (`dofs:`, core/model/vehicle.py): each names its
# body velocity and the position or angle it moves. A vehicle without some of them holds those
# states (rates zero, core/model/planar.py); all six by default.
DOF_STATES = {'surge': (State.U, State.X), 'sway': (State.V, State.Y),
              'heave': (State.W, State.Z), 'roll': (State.P, State.PHI),
              'pitch': (State.Q, State.THETA), 'yaw': (State.R, State.PSI)}
