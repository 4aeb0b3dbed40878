"""Default sensor suite and sample time: what the simulator adds and the filter assumes
when the user gives nothing.

Sensor-noise defaults (1-sigma, per output channel y = x) describe a typical small-AUV suite:

======== ============================ =========== ============================================
channel  sensor                       sigma       why
======== ============================ =========== ============================================
u v w    DVL (bottom lock)            0.01 m/s    ~0.3-1 % of speed + 2-5 mm/s at 0.5-2 m/s
p q r    MEMS/FOG gyro                0.001 rad/s ~0.06 deg/s, tactical-grade MEMS
x y      USBL/LBL fix                 0.5 m       acoustic positioning, short range
z        pressure depth sensor        0.05 m      0.05-0.1 % full scale of a 50-100 m sensor
phi th   AHRS roll/pitch              0.002 rad   ~0.1 deg
psi      AHRS/compass heading         0.005 rad   ~0.3 deg
======== ============================ =========== ============================================

Process noise (off by default) adds white accelerations to nu_dot, sigma per DOF in m/s^2 and
rad/s^2, to stand for unmodelled forces (waves, tether, currents).
"""
import numpy as np

DEFAULT_NOISE_STD = np.array([0.01, 0.01, 0.01, 0.001, 0.001, 0.001,
                              0.5, 0.5, 0.05, 0.002, 0.002, 0.005])
DEFAULT_PROCESS_STD = np.array([1e-3, 1e-3, 1e-3, 1e-4, 1e-4, 1e-4])
DEFAULT_T = 0.05        # s, sample time (the paper's T)
