"""The HSVA KVLCC2 free-running model tests (SIMMAN 2008) read into our state and input layout.

The data are public but not ours to commit: they are read from ../shared/realdata/kvlcc2_hsva
relative to the repository root (REALDATA), and a test skips with a reason when they are absent
(:func:`require_runs`). A file ``HSVA_CPMC_KVLCC2_<run>.dat``: four header lines (ISO-8859-1),
then 20 Hz rows of

    t [s], x0 [m], y0 [m], psi [deg], x0_dot [m/s], y0_dot [m/s], r [deg/s], phi [deg],
    delta [deg], n [rps], thrust [N], torque [N m]

x0, y0 and their rates are earth-fixed (x0 along the approach course, y0 to starboard of it:
psi is positive to starboard, so (x0, y0, psi) are a NED-style north, east, yaw); the body
velocities are u = x0_dot cos psi + y0_dot sin psi, v = -x0_dot sin psi + y0_dot cos psi. The
rudder angle delta is positive to port (trailing edge to port, the ship turns to port), which
is the sign of our delta_r (Y_dr > 0, N_dr < 0 as in the captive tests, config/kvlcc2_hsva.yaml).
The t = 0 row is data. The lead will move this reading to the importer (`auv_ident import
--format hsva`); until then tests and tools/kvlcc2_identify.py use it.
"""
from pathlib import Path

import numpy as np

from auv_ident.core.model.state import Input, N_INPUT, N_STATE, State

REALDATA = Path(__file__).resolve().parents[1] / '..' / 'shared' / 'realdata' / 'kvlcc2_hsva'
RUNS = ('Z_10_10_S', 'Z_10_10_P', 'Z_20_10_S', 'Z_20_10_P')
HEADER_LINES = 4


def run_path(run, folder=REALDATA):
    return Path(folder) / f'HSVA_CPMC_KVLCC2_{run}.dat'


def available(runs=RUNS, folder=REALDATA):
    """True if every run's file is there."""
    return all(run_path(r, folder).is_file() for r in runs)


def require_runs(runs=RUNS, folder=REALDATA):
    """Skip the calling test (pytest) with the reason when a run's file is absent."""
    import pytest
    missing = [str(run_path(r, folder)) for r in runs if not run_path(r, folder).is_file()]
    if missing:
        pytest.skip('KVLCC2 free-running data not found (not part of the repository; expected '
                    'in ../shared/realdata/kvlcc2_hsva): ' + ', '.join(missing))


def load_run(run, folder=REALDATA):
    """(t (N,) s, Y (N, 12) measured states, U (N, 7) inputs) of one run.

    Y holds u, v, r, x, y, psi (m/s, rad/s, m, rad; the others NaN: a planar vehicle holds
    them); U the rudder (rad, our sign), the shaft speed (rpm) and the measured thrust (N)."""
    path = run_path(run, folder)
    with open(path, encoding='iso-8859-1') as fh:
        lines = fh.read().splitlines()[HEADER_LINES:]
    a = np.array([[float(v) for v in ln.split()] for ln in lines if ln.strip()])
    if a.ndim != 2 or a.shape[1] != 12:
        raise ValueError(f'{path}: expected 12 columns after {HEADER_LINES} header lines, got '
                         f'{a.shape}')
    t, x0, y0, psi_deg, xd, yd, r_deg, _phi, delta_deg, n_rps, thrust, _torque = a.T
    psi = np.deg2rad(psi_deg)
    Y = np.full((len(t), N_STATE), np.nan)
    Y[:, State.U] = xd * np.cos(psi) + yd * np.sin(psi)
    Y[:, State.V] = -xd * np.sin(psi) + yd * np.cos(psi)
    Y[:, State.R] = np.deg2rad(r_deg)
    Y[:, State.X] = x0
    Y[:, State.Y] = y0
    Y[:, State.PSI] = np.angle(np.exp(1j * psi))
    U = np.zeros((len(t), N_INPUT))
    U[:, Input.DELTA_R] = np.deg2rad(delta_deg)
    U[:, Input.N_RPM] = 60.0 * n_rps
    U[:, Input.THRUST] = thrust
    return t - t[0], Y, U
