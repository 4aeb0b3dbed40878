"""The BlueROV2 Heavy file as it was before `added_mass_coriolis: fossen`: its added-mass
Coriolis forces written as fixed coefficients X_vr .. N_pq (Fossen 2021, eq. 6.51, written out
here independently of the package), for the tests that compare the two forms."""
import re

from auv_ident.vehicles import load_vehicle

ADDED_MASS = ('X_udot', 'Y_vdot', 'Z_wdot', 'K_pdot', 'M_qdot', 'N_rdot')


def munk_terms(a):
    """{name: (value, equation, k, multiplier)} of -C_A(nu) nu for A = diag(a1..a6) > 0
    (Fossen 2021, eq. 6.51): X = a2 v r - a3 w q, Y = a3 w p - a1 u r, Z = a1 u q - a2 v p,
    K = (a2 - a3) v w + (a5 - a6) q r, M = (a3 - a1) u w + (a6 - a4) p r,
    N = (a1 - a2) u v + (a4 - a5) p q."""
    a1, a2, a3, a4, a5, a6 = a
    return {'X_vr': (a2, 'X', 3, 'v*r'), 'X_wq': (-a3, 'X', 3, 'w*q'),
            'Y_wp': (a3, 'Y', 3, 'w*p'), 'Y_ur': (-a1, 'Y', 3, 'u*r'),
            'Z_uq': (a1, 'Z', 3, 'u*q'), 'Z_vp': (-a2, 'Z', 3, 'v*p'),
            'K_vw': (a2 - a3, 'K', 3, 'v*w'), 'K_qr': (a5 - a6, 'K', 5, 'q*r'),
            'M_uw': (a3 - a1, 'M', 3, 'u*w'), 'M_pr': (a6 - a4, 'M', 5, 'p*r'),
            'N_uv': (a1 - a2, 'N', 3, 'u*v'), 'N_pq': (a4 - a5, 'N', 5, 'p*q')}


def fixed_munk_file(path, added_mass=None):
    """Write the shipped BlueROV2 Heavy file to `path` with its added-mass Coriolis forces as
    fixed coefficients of the added mass `added_mass` ({name: value} in the file's sign, X_udot
    < 0; None: the file's), those added-mass values in place and no `added_mass_coriolis` key.
    Returns path."""
    text = open(load_vehicle('bluerov2_heavy').path, encoding='utf-8').read()
    assert 'added_mass_coriolis: fossen\n' in text
    text = text.replace('added_mass_coriolis: fossen\n', '')
    values = {}
    for name in ADDED_MASS:
        m = re.search(rf'^  {name}: \[([-0-9.e]+), ', text, flags=re.M)
        values[name] = float(m.group(1))
    for name, value in (added_mass or {}).items():
        value = float(value)
        text = re.sub(rf'^  {name}: \[[-0-9.e]+, ', f'  {name}: [{value!r}, ', text, flags=re.M)
        values[name] = value
    lines = ''.join(f'  {n}: [{float(v)!r}, {eq}, {k}, {mult}]\n' for n, (v, eq, k, mult)
                    in munk_terms([-values[n] for n in ADDED_MASS]).items())
    anchor = '  N_rr: [-1.500, N, 5, r*|r|]\n'
    assert anchor in text
    path.write_text(text.replace(anchor, anchor + lines), encoding='utf-8')
    return path
