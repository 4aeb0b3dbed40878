"""The KVLCC2 prior of config/kvlcc2_hsva.yaml from the static captive tests, printed.

    .venv/bin/python tools/kvlcc2_prior.py [CAPTIVE_CSV]

Reads the HMRI static captive tests (../shared/realdata/kvlcc2_hsva/captive_kvlcc2_hmri.csv,
SIMMAN 2014; not in the repository) and fits by linear least squares, in the prime system of
the vehicle file (forces / ((rho/2) L^2 U^2), moments / ((rho/2) L^3 U^2), which is the
captive file's: its linear drift slopes match Y'_v, N'_v of Clarke et al. 1983 in this
normalisation, not in the (rho/2) L T U^2 one of the MMG papers):

- the drift tests at 1.1702 m/s (beta -30..30 deg, rudder 0): v' = -sin(beta) (beta positive
  is the flow from port, sway to port; the side force is then to starboard),
  Y' = Y_0 + Y_v v' + Y_vv v'|v'|, N' = N_0 + N_v v' + N_vv v'|v'|, and the hull's surge
  force X' - (1 - t_P) T' = X_uu u'|u'| + X_vv v'^2 (u' = cos(beta), T' the file's TX');
- the rudder tests at the six speeds 0.33-1.17 m/s (9.9 rps: the thrust loading T' = TX' of
  the file grows from 0.0012 to 0.021 as the speed falls), rudder -15..25 deg, drift 0:
  Y' = Y_0 + Y_dr delta + Y_Tdr T' delta, N' likewise, X' = X_0 + X_T T' + X_dd delta^2 (per
  speed a constant, then a common X_dd), so that the rudder force grows with the propeller
  race: Y = (rho/2) L^2 U^2 Y_dr delta + Y_Tdr T delta.

The offsets (Y_0, N_0: the propeller's asymmetry) are fitted so they do not bend the slopes and
are not part of the model. Prints each coefficient with its 1-sigma from the fit.
"""
import csv
from pathlib import Path
import sys

import numpy as np

THRUST_DEDUCTION = 0.25     # t_P of KVLCC2 (Yasukawa & Yoshimura 2015; ship_data 'tdf')
DEFAULT = Path(__file__).resolve().parents[1] / '..' / 'shared' / 'realdata' / 'kvlcc2_hsva' \
    / 'captive_kvlcc2_hmri.csv'


def read(path):
    rows = []
    with open(path, newline='', encoding='utf-8') as fh:
        for row in csv.DictReader(fh):
            rows.append({k.strip(): v.strip() for k, v in row.items()})
    return rows


def lsq(A, b):
    """(coefficients, 1-sigma) of the least-squares fit A c = b."""
    c, res, rank, _ = np.linalg.lstsq(A, b, rcond=None)
    dof = max(1, len(b) - A.shape[1])
    s2 = float(np.sum((b - A @ c) ** 2)) / dof
    cov = s2 * np.linalg.inv(A.T @ A)
    return c, np.sqrt(np.diag(cov))


def fit(rows):
    out = {}
    drift = [r for r in rows if r['test type'] == 'drift angle']
    beta = np.deg2rad([float(r['beta(deg)']) for r in drift])
    v = -np.sin(beta)
    X, Yf, Nf = (np.array([float(r[k]) for r in drift]) for k in ("X'", "Y'", "N'"))
    A = np.column_stack([np.ones_like(v), v, v * np.abs(v)])
    for name, b in (('Y', Yf), ('N', Nf)):
        c, s = lsq(A, b)
        out[f'{name}_v'] = (c[1], s[1])
        out[f'{name}_vv'] = (c[2], s[2])
    # X: the hull's share, X' - (1 - t_P) T' (t_P = 0.25, ship_data_kvlcc2_hsva.yml), is
    # X_uu u'|u'| + X_vv v'^2 with u' = cos(beta)
    u = np.cos(beta)
    T = np.array([float(r["TX'"]) for r in drift])
    c, s = lsq(np.column_stack([u * np.abs(u), v * v]), X - (1.0 - THRUST_DEDUCTION) * T)
    out['X_uu'] = (c[0], s[0])
    out['X_vv'] = (c[1], s[1])
    rud = [r for r in rows if r['test type'] == 'rudder angle']
    d = np.deg2rad([float(r['delta(deg)']) for r in rud])
    T = np.array([float(r["TX'"]) for r in rud])
    speeds = np.array([float(r['Speed(m/s)']) for r in rud])
    X, Yf, Nf = (np.array([float(r[k]) for r in rud]) for k in ("X'", "Y'", "N'"))
    A = np.column_stack([np.ones_like(d), d, T * d])
    for name, b in (('Y', Yf), ('N', Nf)):
        c, s = lsq(A, b)
        out[f'{name}_dr'] = (c[1], s[1])
        out[f'{name}_Tdr'] = (c[2], s[2])
    # X: a constant per speed (resistance and thrust at that loading) and a common delta^2
    groups = sorted(set(speeds))
    A = np.column_stack([(speeds == g).astype(float) for g in groups] + [d * d])
    c, s = lsq(A, X)
    out['X_dd'] = (c[-1], s[-1])
    return out


def main(argv):
    path = Path(argv[1]) if len(argv) > 1 else DEFAULT
    if not path.is_file():
        print(f'no captive test file {path}', file=sys.stderr)
        return 2
    for name, (c, s) in fit(read(path)).items():
        print(f'{name:7s} {c:+.4e}  +- {s:.1e}')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
