"""Vehicle data: read a `config/<vehicle>.yaml` once and turn it into flat arrays for the model.

A vehicle is data (coefficients with their equation, length exponent and multiplier) plus a
model structure chosen by keys (`scaling`, `propulsion.model`, `crossflow.model`,
`mass_inverse`, `dofs`). The rigid-body mass matrix and Coriolis terms, restoring forces and
kinematics are built here generically from mass, r_G, inertia, W, B and r_B (Fossen 2021,
ch. 3-4), so a vehicle file holds only the hydrodynamic and control coefficients.

Units: SI; angles rad; shaft speed rpm at the interface. Frames: body FRD, world NED.
"""
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
import os
from typing import Any

import numpy as np

from auv_ident.core.errors import ConfigError
from auv_ident.core.model.state import (
    ANGULAR,
    DOF_STATES,
    INPUT_NAMES,
    LINEAR,
    N_INPUT,
    N_NU,
    N_STATE,
    NU_NAMES,
    State,
)
from auv_ident.core.model.thrusters import (
    THR_COLS,
    Thruster,
    thruster_table,
    thrusters_from_file,
)
from auv_ident.core.vehicle_files import (
    file_kind,
    finite_number,
    read_yaml_file,
    VehicleFileProblems,
)

EQUATIONS = ('X', 'Y', 'Z', 'K', 'M', 'N')

# Factor vector z (see hydrodynamics.py): index of each multiplier factor. 'U' is the speed in the
# horizontal plane sqrt(u^2 + v^2) (m/s; the total speed of a ship, whose prime system scales
# by it), 'thrust' the measured propeller thrust input (N; see _term_scale for its scaling).
FACTORS = ('u', 'v', 'w', 'p', 'q', 'r', '|u|', '|v|', '|w|', '|p|', '|q|', '|r|',
           'dr', 'ds', 'db', 'dbp', 'dbs', 'db2', 'eps', 'U', 'thrust')
FACTOR_INDEX = {name: i for i, name in enumerate(FACTORS)}
MAX_FACTORS = 5

PROPULSION_MODELS = {'none': 0, 'healey_lienard': 1, 'quadratic_thrust': 2,
                     'measured_thrust': 3}
CROSSFLOW_MODELS = {'none': 0, 'mss_classic_strip': 1}

# Layout of the float parameter vector `par` handed to the compiled model.
P_RHO, P_L, P_W, P_B, P_XG, P_YG, P_ZG, P_XB, P_YB, P_ZB = range(10)
P_FIN, P_NMAX, P_PROP, P_PROP_A, P_PROP_B, P_PROP_C, P_PROP_D = range(10, 17)
P_CF, P_CF_N, P_CF_CY, P_CF_CZ, P_RECOMPUTE_MINV, P_U_MIN, P_SPEED_FACTOR = range(17, 24)
N_PAR = 24

# crossflow.stations: the strip sum needs both ends (dx = L / (stations - 1)); its cost is linear
# in the count, and MSS's 11 stations already converge it to ~1e-3 relative: 1000 is far past
# any use and keeps one model evaluation below a millisecond
MAX_STATIONS = 1000
# W / mass is the gravity the file assumes (m/s^2): 9.78-9.83 on Earth's surface; the shipped
# files use 9.79-9.81, g = 10 is a common round value. Outside this the mass (or the weight) is
# in other units or mistyped, and the dynamics would be off by that factor.
G_RANGE = (9.5, 10.5)
# mss_inverse is MSS's hard-coded M^-1: it must invert M_RB + M_A to this (max |Minv M - I|;
# NPS AUV II's literal: 2.7e-4). A singular or unrelated matrix is a typo, not a model choice.
MSS_INVERSE_TOL = 0.05

U_MIN = 1e-6          # m/s: |u| below this is outside the Healey-Lienard propeller's domain
COS_THETA_MIN = 1e-6  # |cos(theta)| below this: Euler-angle kinematics singular (theta ~ +-90 deg)


@dataclass
class Coefficient:
    """One hydrodynamic/control coefficient of the vehicle file."""

    name: str
    value: float        # in the file's scaling (prime value if nondimensional)
    equation: int       # 0..5 = X Y Z K M N
    k: int              # length exponent of (rho/2) L^k
    factors: tuple      # factor indices into FACTORS, or ('dot', column) for added mass
    scale: float        # (rho/2) L^k, or 1 for dimensional files
    added_mass_col: int = -1   # 0..5 when this is an added-mass coefficient
    # the equations (0..5) whose thruster force this coefficient scales (multiplier
    # `thrusters`, `thrusters_forward` or `thrusters_reverse`: a thrust gain,
    # core/model/thrusters.py); empty for every other coefficient
    gain_rows: tuple = ()
    gain_sides: tuple = ()      # the curve sides it scales: 0 forward, 1 reverse
    # the thrusters' shared first-order time constant (s, multiplier `thruster_lag`,
    # core/model/thruster_lag.py) rather than a term of an equation
    is_thrust_lag: bool = False

    @property
    def is_added_mass(self) -> bool:
        return self.added_mass_col >= 0

    @property
    def is_thrust_gain(self) -> bool:
        return bool(self.gain_rows)

    @property
    def has_monomial(self) -> bool:
        """Whether the coefficient is a term of the monomial table (not added mass, not a
        thrust gain, not the thrusters' time constant)."""
        return not (self.is_added_mass or self.is_thrust_gain or self.is_thrust_lag)


@dataclass
class Vehicle:
    """A vehicle file, validated, with the flat arrays the compiled model uses."""

    name: str
    title: str
    path: str
    raw: dict
    coefficients: list
    par: np.ndarray              # float parameters, layout P_*
    terms_i: np.ndarray          # int (nt, 2 + MAX_FACTORS): equation, coef (-1 fixed), factors
    terms_s: np.ndarray          # float (nt,): scale (times the value for fixed terms)
    am_i: np.ndarray             # int (na, 3): equation, column, coef index
    am_s: np.ndarray             # float (na,): scale of each added-mass coefficient
    M_RB: np.ndarray             # (6, 6) rigid-body mass matrix
    Minv_literal: np.ndarray | None   # (6, 6) or None: MSS hard-coded inverse
    mass_inverse: str
    identify_default: list
    paper: dict = field(default_factory=dict)
    cruise_rpm: float = 500.0
    cruise_thrust: float = 0.0   # N, the thrust input of a straight run (measured_thrust)
    # (12,) bool, the states the vehicle's degrees of freedom move (`dofs:`); the others are
    # held (core/model/planar.py). All True for a 6-DOF vehicle.
    free_states: np.ndarray = field(default_factory=lambda: np.ones(N_STATE, dtype=bool))
    # the file's `thrusters:` (core/model/thrusters.py), empty for a fin or rudder vehicle
    thrusters: tuple[Thruster, ...] = ()
    # (n, THR_COLS) the thrusters as the compiled model reads them (thrusters.thruster_table)
    thr: np.ndarray = field(default_factory=lambda: np.zeros((0, THR_COLS)))
    # (2, 6) int, per curve side (forward, reverse) and equation X..N the index of the
    # coefficient scaling that side's thruster force in that equation (a thrust gain), or -1
    gain_idx: np.ndarray = field(default_factory=lambda: -np.ones((2, N_NU), dtype=np.int64))
    # the added-mass Coriolis terms -C_A(nu) nu the model computes from the added-mass
    # coefficients (`added_mass_coriolis: fossen`, added_mass_coriolis_terms): per term
    # [equation, added-mass coefficient index, nu factor, nu factor] and its scale; empty when
    # the file writes its own (`none`, the default)
    ca_i: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), dtype=np.int64))
    ca_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # index of the coefficient that is every thruster's time constant (multiplier
    # `thruster_lag`), or -1: then each thruster's own `time_constant` (0: no lag)
    lag_idx: int = -1

    @property
    def lagged(self) -> bool:
        """Whether the thrusters' thrust lags their commands (a `thruster_lag` coefficient, of
        any value, or a thruster's time_constant > 0): the filters then carry the lagged
        thrust (core/model/thruster_lag.py)."""
        return self.lag_idx >= 0 or any(t.time_constant > 0.0 for t in self.thrusters)

    @property
    def input_names(self) -> tuple[str, ...]:
        """Names of the input vector's entries: state.INPUT_NAMES, then the thrusters'."""
        return INPUT_NAMES + tuple(t.name for t in self.thrusters)

    @property
    def hovers(self) -> bool:
        """A thruster vehicle with no main propeller (ROV, hovering AUV): it has no cruise, its
        runs start at rest and its trim is hovering (thrusters at neutral)."""
        return bool(self.thrusters) and self.par[P_PROP] == PROPULSION_MODELS['none']

    @property
    def n_inputs(self) -> int:
        """Length of this vehicle's input vector: the N_INPUT channels of state.Input, then one
        command per thruster in the file's order (docs/vehicles.md, Thrusters)."""
        return N_INPUT + len(self.thrusters)

    @property
    def held(self) -> np.ndarray:
        """Indices (int64) of the held states (empty for a 6-DOF vehicle)."""
        return np.flatnonzero(~self.free_states).astype(np.int64)

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.coefficients]

    @property
    def values(self) -> np.ndarray:
        return np.array([c.value for c in self.coefficients], dtype=float)

    def index(self, name: str) -> int:
        """Index of a coefficient by name (exact, or ignoring '_' and case as a fallback)."""
        for i, c in enumerate(self.coefficients):
            if c.name == name:
                return i
        key = name.replace('_', '').lower()
        hits = [i for i, c in enumerate(self.coefficients)
                if c.name.replace('_', '').lower() == key]
        if len(hits) == 1:
            return hits[0]
        raise ConfigError(f'unknown coefficient {name!r} for vehicle {self.name!r}; '
                          f'known: {", ".join(self.names)}')

    def with_mass_inverse(self, mass_inverse: str) -> 'Vehicle':
        """This vehicle with M^-1 formed as `mass_inverse`: 'default' (as its file says: this
        vehicle), 'exact' (inv(M_RB + M_A), which the added-mass coefficients change) or
        'mss_literal' (MSS's hard-coded inverse); a copy, so that every Model made of it (one
        not given its own mass_inverse) uses that M^-1."""
        if mass_inverse in ('default', self.mass_inverse):
            return self
        if mass_inverse not in ('exact', 'mss_literal'):
            raise ConfigError(f'mass_inverse = {mass_inverse!r}; use default, exact or '
                              'mss_literal')
        if mass_inverse == 'mss_literal' and self.Minv_literal is None:
            raise ConfigError(f'vehicle {self.name!r} has no MSS literal inverse')
        return replace(self, mass_inverse=mass_inverse)

    def mass_matrix(self, c: np.ndarray | None = None) -> np.ndarray:
        """M = M_RB + M_A for coefficient values c (file values by default), (6, 6)."""
        c = self.values if c is None else c
        M = self.M_RB.copy()
        for (eq, col, ci), s in zip(self.am_i, self.am_s):
            M[eq, col] -= s * c[ci]
        return M

    def nondimensional_scale(self, name: str) -> float:
        """(rho/2) L^k of a coefficient (L^k for a thrust term, _term_scale): its dimensional
        value is scale * prime value."""
        c = self.coefficients[self.index(name)]
        if c.is_thrust_gain or c.is_thrust_lag:
            return 1.0          # a ratio to the file's thrust curves, a time in s: either scaling
        return _term_scale(self.par[P_RHO], self.par[P_L], c.k, c.factors, 'nondimensional')


def _term_scale(rho: float, L: float, k: int, factors: tuple, scaling: str) -> float:
    """Scale of a coefficient's term: (rho/2) L^k in the prime system (SNAME 1950), 1 for a
    dimensional file. The thrust factor is a measured force; a force is (rho/2) times lengths
    and speeds in the prime system, so the thrust counts as T / (rho/2) there and its term's
    scale is L^k: `X_T: [1 - t_P, X, 0, thrust]` adds (1 - t_P) T to X (t_P the thrust
    deduction), in either scaling."""
    if scaling != 'nondimensional':
        return 1.0
    with np.errstate(over='ignore'):    # an overflow is inf, refused by _check_finite_terms
        scale = float(0.5 * rho * np.float64(L) ** k)
    if FACTOR_INDEX['thrust'] in factors:
        scale /= 0.5 * rho
    return scale


def _dofs(raw: dict, where: str) -> np.ndarray:
    """(12,) bool of the states a vehicle's `dofs:` list moves (all six when absent)."""
    dofs = raw.get('dofs', list(DOF_STATES))
    if (not isinstance(dofs, list) or not dofs
            or any(not isinstance(d, str) or d not in DOF_STATES for d in dofs)
            or len(set(dofs)) != len(dofs)):
        raise ConfigError(f'{where}: dofs = {dofs!r}; use a list of distinct names from '
                          + ', '.join(DOF_STATES))
    free = np.zeros(N_STATE, dtype=bool)
    for d in dofs:
        free[list(DOF_STATES[d])] = True
    return free


# what a required key is, for the message that says it is missing (docs/vehicles.md)
KEY_MEANING = {
    'rho': 'water density, kg/m^3', 'L': 'length, m (the scaling length of prime values)',
    'mass': 'kg', 'W': 'weight m g, N', 'B': 'buoyancy rho g V, N',
    'Ix': 'roll inertia about the origin, kg m^2', 'Iy': 'pitch inertia, kg m^2',
    'Iz': 'yaw inertia, kg m^2', 'fin_rad': 'largest fin deflection, rad',
    'n_rpm': 'largest propeller shaft speed, rpm',
}


def _num(d: dict, key: str, where: str, positive: bool = False) -> float:
    return finite_number(d, key, where, positive, KEY_MEANING.get(key))


def _vec3(d: dict, key: str, where: str) -> np.ndarray:
    v = d.get(key, [0.0, 0.0, 0.0])
    try:
        a = np.array(v, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f'{where}: {key} = {v!r} is not a list of 3 numbers') from None
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ConfigError(f'{where}: {key} = {v!r} must be a list of 3 finite numbers')
    return a


def _parse_multiplier(text: object, where: str) -> tuple:
    text = str(text).strip()
    if text.endswith('dot') and text[:-3] in NU_NAMES:
        return ('dot', NU_NAMES.index(text[:-3]))
    facs = []
    for f in text.split('*'):
        f = f.strip()
        if f not in FACTOR_INDEX:
            raise ConfigError(f'{where}: unknown factor {f!r} in multiplier {text!r} '
                              f'(allowed: {" ".join(FACTORS)}, or udot..rdot)')
        facs.append(FACTOR_INDEX[f])
    if len(facs) > MAX_FACTORS:
        raise ConfigError(f'{where}: multiplier {text!r} has more than {MAX_FACTORS} factors')
    return tuple(facs)


def rigid_body_terms(mass: float, r_G: np.ndarray,
                     I: Sequence[float]) -> list[tuple[int, float, tuple[int, int]]]:
    """Rigid-body Coriolis/centripetal forces as monomials in nu (Fossen; vehicles.md 1.4).

    Returns a list of (equation, constant, factor tuple); every entry contributes
    constant * product(nu factors) to that equation. I = (Ix, Iy, Iz, Ixy, Iyz, Ixz).
    """
    xg, yg, zg = r_G
    Ix, Iy, Iz, Ixy, Iyz, Ixz = I
    u, v, w, p, q, r = (int(s) for s in (State.U, State.V, State.W, State.P, State.Q, State.R))
    m = mass
    t = [
        # X: m (v r - w q) + m (xG (q^2 + r^2) - yG p q - zG p r)
        (0, m, (v, r)), (0, -m, (w, q)), (0, m * xg, (q, q)), (0, m * xg, (r, r)),
        (0, -m * yg, (p, q)), (0, -m * zg, (p, r)),
        # Y: -m (u r - w p + xG p q - yG (p^2 + r^2) + zG q r)
        (1, -m, (u, r)), (1, m, (w, p)), (1, -m * xg, (p, q)), (1, m * yg, (p, p)),
        (1, m * yg, (r, r)), (1, -m * zg, (q, r)),
        # Z: -m (v p - u q + xG p r + yG q r - zG (p^2 + q^2))
        (2, -m, (v, p)), (2, m, (u, q)), (2, -m * xg, (p, r)), (2, -m * yg, (q, r)),
        (2, m * zg, (p, p)), (2, m * zg, (q, q)),
        # K: (Iy - Iz) q r - Ixy p r - Iyz (r^2 - q^2) + Ixz p q
        #    - m (yG (v p - u q) - zG (u r - w p))
        (3, Iy - Iz, (q, r)), (3, -Ixy, (p, r)), (3, -Iyz, (r, r)), (3, Iyz, (q, q)),
        (3, Ixz, (p, q)), (3, -m * yg, (v, p)), (3, m * yg, (u, q)), (3, m * zg, (u, r)),
        (3, -m * zg, (w, p)),
        # M: (Iz - Ix) p r + Ixy q r - Iyz p q - Ixz (p^2 - r^2)
        #    + m (xG (v p - u q) - zG (w q - v r))
        (4, Iz - Ix, (p, r)), (4, Ixy, (q, r)), (4, -Iyz, (p, q)), (4, -Ixz, (p, p)),
        (4, Ixz, (r, r)), (4, m * xg, (v, p)), (4, -m * xg, (u, q)), (4, -m * zg, (w, q)),
        (4, m * zg, (v, r)),
        # N: (Ix - Iy) p q + Ixy (p^2 - q^2) + Iyz p r - Ixz q r
        #    - m (xG (u r - w p) - yG (w q - v r))
        (5, Ix - Iy, (p, q)), (5, Ixy, (p, p)), (5, -Ixy, (q, q)), (5, Iyz, (p, r)),
        (5, -Ixz, (q, r)), (5, -m * xg, (u, r)), (5, m * xg, (w, p)), (5, m * yg, (w, q)),
        (5, -m * yg, (v, r)),
    ]
    return [e for e in t if e[1] != 0.0]


# `added_mass_coriolis:` the added-mass Coriolis and centripetal forces -C_A(nu) nu are either
# written by the file as coefficients of their own (`none`, the default: the torpedo files' Munk
# moments X_vr, M_uw, ... lump them with viscous parts) or computed by the model from the file's
# added-mass coefficients (`fossen`), so that they follow an identified added mass
ADDED_MASS_CORIOLIS = ('none', 'fossen')


def _levi_civita(m: int, k: int, n: int) -> int:
    """eps_mkn: +1 for a cyclic (m, k, n) of (0, 1, 2), -1 for an anticyclic one, else 0."""
    return (m - k) * (k - n) * (n - m) // 2


def added_mass_coriolis_terms(am_i: np.ndarray,
                              am_s: np.ndarray) -> list[tuple[int, int, float, int, int]]:
    """-C_A(nu) nu (Fossen 2021, eq. 6.43 for a symmetric M_A; eq. 6.51 when it is diagonal) as
    bilinear terms of the added-mass coefficients: (equation, coefficient index, scale, nu
    factor, nu factor) per term, each adding scale * c[coefficient] * nu_a * nu_b to its equation.

    With a = M_A nu = [a1; a2] and nu = [v; omega], -C_A(nu) nu = [a1 x omega; a1 x v + a2 x
    omega]. An added-mass coefficient c at (equation i, column j) of scale s puts -s c into
    M_A[i, j] (M[i, j] -= s c), so a_i gains -s c nu_j, and (e_k x w)_m = eps_mkn w_n gives its
    terms. The diagonal X_udot (a1 = -X_udot): Y += X_udot u r, Z -= X_udot u q,
    M += X_udot u w, N -= X_udot u v, i.e. -a1 u r, a1 u q, -a1 u w, a1 u v."""
    terms = []
    for (eq, col, ci), s in zip(am_i, am_s):
        eq, col, ci = int(eq), int(col), int(ci)
        k = eq % 3
        for m in range(3):
            for n in range(3):
                e = _levi_civita(m, k, n)
                if e == 0:
                    continue
                if eq < 3:      # a1: a1 x omega in the force, a1 x v in the moment
                    terms.append((m, ci, -float(s) * e, col, 3 + n))
                    terms.append((3 + m, ci, -float(s) * e, col, n))
                else:           # a2: a2 x omega in the moment
                    terms.append((3 + m, ci, -float(s) * e, col, 3 + n))
    return terms


def _added_mass_coriolis(raw: dict, where: str, coefs: list[Coefficient], am_i: list,
                         am_s: list) -> tuple[np.ndarray, np.ndarray]:
    """(ca_i, ca_s) of the file's `added_mass_coriolis:` (ADDED_MASS_CORIOLIS): the terms of
    added_mass_coriolis_terms for `fossen`, none for `none`. A coefficient of the file whose
    term is one of them (same equation, same two velocities) would count it twice: refused by
    name."""
    mode = raw.get('added_mass_coriolis', 'none')
    if mode not in ADDED_MASS_CORIOLIS:
        raise ConfigError(f'{where}: added_mass_coriolis = {mode!r}; use none (the file writes '
                          'its own added-mass Coriolis terms, if any) or fossen (the model '
                          'computes -C_A(nu) nu from the added-mass coefficients)')
    if mode == 'none':
        return np.zeros((0, 4), dtype=np.int64), np.zeros(0)
    if not am_i:
        raise ConfigError(f'{where}: added_mass_coriolis: fossen needs added-mass '
                          'coefficients (multiplier udot .. rdot); the file has none')
    terms = added_mass_coriolis_terms(np.array(am_i).reshape(-1, 3), np.array(am_s))
    generated = {(eq, tuple(sorted((a, b)))) for eq, _, _, a, b in terms}
    for c in coefs:
        if (c.has_monomial and len(c.factors) == 2
                and (c.equation, tuple(sorted(c.factors))) in generated):
            raise ConfigError(
                f'{where}: coefficient {c.name} ({EQUATIONS[c.equation]}, '
                f'{"*".join(FACTORS[f] for f in c.factors)}) is a term of the added-mass '
                'Coriolis forces, which added_mass_coriolis: fossen computes from the added '
                'mass: it would count twice; remove it, or the key')
    return (np.array([[eq, ci, a, b] for eq, ci, _, a, b in terms], dtype=np.int64),
            np.array([s for _, _, s, _, _ in terms], dtype=float))


def rigid_body_mass_matrix(mass: float, r_G: np.ndarray, I: Sequence[float]) -> np.ndarray:
    """M_RB = [[m I3, -m S(r_G)], [m S(r_G), I_g]] (Fossen 2021, eq. 3.44), (6, 6)."""
    Ix, Iy, Iz, Ixy, Iyz, Ixz = I
    xg, yg, zg = r_G
    S = np.array([[0.0, -zg, yg], [zg, 0.0, -xg], [-yg, xg, 0.0]])
    I_g = np.array([[Ix, -Ixy, -Ixz], [-Ixy, Iy, -Iyz], [-Ixz, -Iyz, Iz]])
    M = np.zeros((N_NU, N_NU))
    M[LINEAR, LINEAR] = mass * np.eye(3)
    M[LINEAR, ANGULAR] = -mass * S
    M[ANGULAR, LINEAR] = mass * S
    M[ANGULAR, ANGULAR] = I_g
    return M


def vehicle_from_file(path: str) -> Vehicle:
    """Load and validate a vehicle YAML file given by its path (cached per path and mtime:
    parsed once, never in a hot path). Looking a vehicle up by name is
    :func:`auv_ident.vehicles.load_vehicle`."""
    path = os.path.abspath(path)
    try:
        key = (path, os.path.getmtime(path))
    except OSError as err:
        raise ConfigError(f'no vehicle file {path}') from err
    if key not in _CACHE:
        _CACHE[key] = _build(read_yaml_file(path), path)
    return _CACHE[key]


_CACHE: dict[tuple[str, float], Vehicle] = {}


def _six_dof_mapping(raw: object, where: str) -> dict[str, Any]:
    """The parsed file as the mapping of a 6-DOF vehicle, or ConfigError: an empty file is an
    empty mapping (every required key then reported missing), a glider file is refused."""
    raw = {} if raw is None else raw
    if not isinstance(raw, dict):
        raise ConfigError(f'{where}: not a vehicle file (a YAML mapping of keys, '
                          f'docs/vehicles.md; got {type(raw).__name__})')
    if file_kind(raw) == 'glider':
        # a glider flies by buoyancy, lift and drag in its glide plane, not by manoeuvring
        # derivatives: the 6-DOF model has nothing to fly it with
        raise ConfigError(f'{where}: a glider file (kind: glider): its flight model is '
                          'core/glider (docs/glider.md), not the 6-DOF model this command uses')
    return raw


def _build(raw: object, path: str) -> Vehicle:
    """The Vehicle of a parsed vehicle file `raw` (read from `path`), or ConfigError naming the
    file and the first bad entry."""
    where = os.path.basename(path)
    raw = _six_dof_mapping(raw, where)
    problems: list[str] = []

    def checked(check: Callable[..., Any], *args: Any, default: Any, **kwargs: Any) -> Any:
        # the independent entries are all checked before any is used, each problem kept
        try:
            return check(*args, **kwargs)
        except ConfigError as err:
            problems.append(str(err).removeprefix(f'{where}: ').removeprefix(f'{where} '))
            return default

    if not isinstance(raw.get('coefficients'), dict) or not raw['coefficients']:
        problems.append('missing key `coefficients:` (NAME: [value, equation, k, multiplier] '
                        'per hydrodynamic term, docs/vehicles.md)')
    scaling = raw.get('scaling', 'nondimensional')
    if scaling not in ('nondimensional', 'dimensional'):
        problems.append(f'scaling = {scaling!r}; use nondimensional or dimensional')
    rho, L, mass, W, B = (checked(_num, raw, key, where, positive=True, default=float('nan'))
                          for key in ('rho', 'L', 'mass', 'W', 'B'))
    if np.isfinite(mass) and np.isfinite(W) and not G_RANGE[0] <= W / mass <= G_RANGE[1]:
        problems.append(f'mass = {mass!r} kg and W = {W!r} N give W / mass = '
                        f'{W / mass:.4g} m/s^2; W is m g (g {G_RANGE[0]:g}-{G_RANGE[1]:g} '
                        'm/s^2): check the units of mass and W')
    r_G, r_B = (checked(_vec3, raw, key, where, default=np.zeros(3)) for key in ('r_G', 'r_B'))
    inertia = raw.get('inertia') or {}
    I = tuple(checked(_num, inertia, k, where + ' inertia', positive=k in ('Ix', 'Iy', 'Iz'),
                      default=float('nan'))
              if k in ('Ix', 'Iy', 'Iz') or k in inertia else 0.0
              for k in ('Ix', 'Iy', 'Iz', 'Ixy', 'Iyz', 'Ixz'))
    limits = raw.get('limits') or {}
    thrusters, thruster_problems = thrusters_from_file(raw.get('thrusters'), where)
    problems.extend(thruster_problems)
    # a thruster vehicle has no fins and no main propeller: its limits are 0 unless given
    # (the fin and shaft-speed channels then saturate to 0 and push nothing)
    fin, nmax = ((checked(_num, limits, key, where + ' limits', positive=True,
                          default=float('nan'))
                  if key in limits or not raw.get('thrusters') else 0.0)
                 for key in ('fin_rad', 'n_rpm'))
    free = checked(_dofs, raw, where, default=np.ones(N_STATE, dtype=bool))
    if problems:
        raise VehicleFileProblems(where, problems)

    par = np.zeros(N_PAR)
    par[P_RHO], par[P_L], par[P_W], par[P_B] = rho, L, W, B
    par[P_XG:P_ZG + 1] = r_G
    par[P_XB:P_ZB + 1] = r_B
    par[P_FIN], par[P_NMAX], par[P_U_MIN] = fin, nmax, U_MIN
    _propulsion(raw.get('propulsion') or {'model': 'none'}, where, par)
    _crossflow(raw.get('crossflow') or {'model': 'none'}, where, par)
    coefs = _coefficients(raw, where, rho, L, scaling, free)
    if any(FACTOR_INDEX['U'] in c.factors for c in coefs):
        par[P_SPEED_FACTOR] = 1.0
    terms_i, terms_s, am_i, am_s = _term_tables(coefs, rigid_body_terms(mass, r_G, I))
    ca_i, ca_s = _added_mass_coriolis(raw, where, coefs, am_i, am_s)
    mass_inverse, Minv_literal = _mass_inverse(raw, where, free)

    v = Vehicle(
        name=str(raw.get('name', os.path.splitext(where)[0])), title=str(raw.get('title', '')),
        path=path, raw=raw, coefficients=coefs, par=par,
        terms_i=np.array(terms_i, dtype=np.int64).reshape(-1, 2 + MAX_FACTORS),
        terms_s=np.array(terms_s, dtype=float),
        am_i=np.array(am_i, dtype=np.int64).reshape(-1, 3), am_s=np.array(am_s, dtype=float),
        M_RB=_held_rigid_body_mass(mass, r_G, I, free), Minv_literal=Minv_literal,
        mass_inverse=mass_inverse,
        identify_default=list(raw.get('identify_default', [])), paper=raw.get('paper') or {},
        cruise_rpm=(_num(raw, 'cruise_rpm', where, positive=True) if 'cruise_rpm' in raw
                    else 500.0),
        cruise_thrust=(_num(raw, 'cruise_thrust', where) if 'cruise_thrust' in raw else 0.0),
        free_states=free, thrusters=tuple(thrusters), thr=thruster_table(thrusters),
        gain_idx=_gain_index(coefs, where), lag_idx=_lag_index(coefs, thrusters, where),
        ca_i=ca_i, ca_s=ca_s)
    if v.gain_idx.max() >= 0 and not thrusters:
        raise ConfigError(f'{where}: a thrust gain (multiplier `thrusters`) without a '
                          '`thrusters:` list scales nothing')
    _check_finite_terms(v, where)
    M = v.mass_matrix()
    if not np.allclose(M, M.T, rtol=0, atol=1e-9 * np.abs(M).max()):
        raise ConfigError(f'{where}: M_RB + M_A is not symmetric (check added-mass pairs)')
    try:
        np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        raise ConfigError(f'{where}: M_RB + M_A is not positive definite') from None
    if Minv_literal is not None:
        err = float(np.abs(Minv_literal @ M - np.eye(N_NU)).max())
        if not err <= MSS_INVERSE_TOL:
            raise ConfigError(f'{where}: mss_inverse is not the inverse of M_RB + M_A (max '
                              f'|mss_inverse M - I| = {err:.3g}, at most {MSS_INVERSE_TOL:g}): '
                              'a singular or mistyped matrix; use mass_inverse: exact')
    for n in v.identify_default:
        v.index(n)
    return v


def _check_finite_terms(v: Vehicle, where: str) -> None:
    """Every term of the model finite: a coefficient's scale (rho/2) L^k and its dimensional
    value, the rigid-body constants. An overflow (rho: 1e308) would otherwise reach the
    generated kernels as 'inf' and the numerics as NaN."""
    for c in v.coefficients:
        if not (np.isfinite(c.scale) and np.isfinite(c.scale * c.value)):
            raise ConfigError(f'{where}: coefficient {c.name}: its scale (rho/2) L^{c.k} = '
                              f'{c.scale:.3g} times the value {c.value:.3g} is not a finite '
                              'number: check rho, L and the value')
    if not (np.all(np.isfinite(v.terms_s)) and np.all(np.isfinite(v.M_RB))):
        raise ConfigError(f'{where}: the rigid-body terms (mass times r_G, the inertia) are not '
                          'finite numbers: check mass, r_G and inertia')


def _propulsion(prop: dict, where: str, par: np.ndarray) -> None:
    """The file's `propulsion:` block into par (P_PROP and its three constants)."""
    pm = prop.get('model', 'none')
    if pm not in PROPULSION_MODELS:
        raise ConfigError(f'{where}: propulsion.model = {pm!r}; known: '
                          + ', '.join(PROPULSION_MODELS))
    par[P_PROP] = PROPULSION_MODELS[pm]
    if pm == 'healey_lienard':
        par[P_PROP_A] = _num(prop, 'Cd0', where + ' propulsion')
        par[P_PROP_B] = _num(prop, 'eta_gain', where + ' propulsion')
        par[P_PROP_C] = _num(prop, 'Ct_gain', where + ' propulsion')
    elif pm == 'quadratic_thrust':
        par[P_PROP_A] = _num(prop, 'X_prop', where + ' propulsion')
        par[P_PROP_B] = _num(prop, 'K_prop', where + ' propulsion')
        par[P_PROP_C] = _num(prop, 'n_nominal_rpm', where + ' propulsion', positive=True)


def _crossflow(cf: dict, where: str, par: np.ndarray) -> None:
    """The file's `crossflow:` block into par (P_CF and the strip model's constants)."""
    cm = cf.get('model', 'none')
    if cm not in CROSSFLOW_MODELS:
        raise ConfigError(f'{where}: crossflow.model = {cm!r}; known: '
                          + ', '.join(CROSSFLOW_MODELS))
    par[P_CF] = CROSSFLOW_MODELS[cm]
    if cm == 'mss_classic_strip':
        ns = _num(cf, 'stations', where + ' crossflow', positive=True)
        if ns != int(ns) or not 2 <= ns <= MAX_STATIONS:
            raise ConfigError(f'{where} crossflow: stations = {cf["stations"]!r} must be a '
                              f'whole number from 2 to {MAX_STATIONS}')
        par[P_CF_N] = ns
        par[P_CF_CY] = _num(cf, 'Cy', where + ' crossflow')
        par[P_CF_CZ] = _num(cf, 'Cz', where + ' crossflow')


def _coefficients(raw: dict, where: str, rho: float, L: float, scaling: str,
                  free: np.ndarray) -> list[Coefficient]:
    """The file's `coefficients:` mapping as Coefficients, in the file's order."""
    craw = raw['coefficients']
    if not isinstance(craw, dict) or not craw:
        raise ConfigError(f'{where}: `coefficients:` must be a non-empty mapping')
    return [_coefficient(str(name), entry, f'{where} coefficient {name}', rho, L, scaling,
                         free, raw.get('dofs'))
            for name, entry in craw.items()]


def _gain_index(coefs: list[Coefficient], where: str) -> np.ndarray:
    """(2, 6) int: per curve side and equation the thrust gain coefficient scaling that
    thruster force, or -1."""
    gain = -np.ones((2, N_NU), dtype=np.int64)
    for ci, c in enumerate(coefs):
        for side in c.gain_sides:
            for e in c.gain_rows:
                if gain[side, e] >= 0:
                    raise ConfigError(f'{where}: thrust gains {coefs[gain[side, e]].name} and '
                                      f'{c.name} both scale the {GAIN_SIDES[side]} thrust in '
                                      f'{EQUATIONS[e]}')
                gain[side, e] = ci
    return gain


def _lag_index(coefs: list[Coefficient], thrusters: list[Thruster], where: str) -> int:
    """Index of the `thruster_lag` coefficient (every thruster's time constant), or -1; one
    ConfigError for a second one, one without thrusters or beside a thruster's own
    `time_constant`."""
    lag = [i for i, c in enumerate(coefs) if c.is_thrust_lag]
    if not lag:
        return -1
    names = ', '.join(coefs[i].name for i in lag)
    if len(lag) > 1:
        raise ConfigError(f"{where}: coefficients {names} are each the thrusters' time "
                          'constant (multiplier thruster_lag): keep one')
    if not thrusters:
        raise ConfigError(f'{where}: coefficient {names} (multiplier thruster_lag) without a '
                          '`thrusters:` list delays nothing')
    own = [t.name for t in thrusters if t.time_constant > 0.0]
    if own:
        raise ConfigError(f"{where}: coefficient {names} is every thruster's time constant, "
                          f'and thrusters {", ".join(own)} give their own time_constant: state '
                          'the lag one way')
    return lag[0]


def _thrust_lag(name: str, value: float, eq: object, k: object, cw: str) -> Coefficient:
    """The thrusters' shared time constant `NAME: [tau, XYZKMN, 0, thruster_lag]` (s, >= 0):
    the delivered thrust of every thruster follows its curve's value through tau f_dot =
    f_ss - f (core/model/thruster_lag.py); 0 is no lag."""
    if str(eq) != 'XYZKMN' or k != 0:
        raise ConfigError(f"{cw}: the thrusters' time constant delays their whole wrench: "
                          f'give [tau_s, XYZKMN, 0, thruster_lag], got equation {eq!r}, k {k!r}')
    if value < 0.0:
        raise ConfigError(f'{cw}: time constant {value!r} s must be >= 0 (0: no lag)')
    return Coefficient(name, value, 0, 0, (), 1.0, is_thrust_lag=True)


GAIN_SIDES = ('forward', 'reverse')
# the multiplier of the thrusters' shared time constant (s)
LAG_MULTIPLIER = 'thruster_lag'
# a thrust gain's multiplier -> the curve sides it scales
GAIN_MULTIPLIERS = {'thrusters': (0, 1), 'thrusters_forward': (0,), 'thrusters_reverse': (1,)}


def _thrust_gain(name: str, value: float, eq: object, sides: tuple, cw: str) -> Coefficient:
    """A thrust gain `NAME: [value, EQUATIONS, 0, thrusters]`: value (dimensionless, 1 = the
    file's thrust curves) times the thrusters' force in each equation named (e.g. XYZKMN for
    one gain of all, XY for the horizontal thrusters' plane); `thrusters_forward` and
    `thrusters_reverse` scale one side of the curves (f > 0, f < 0) only."""
    rows = tuple(EQUATIONS.index(a) for a in str(eq) if a in EQUATIONS)
    if not rows or len(set(rows)) != len(str(eq)):
        raise ConfigError(f'{cw}: a thrust gain names the equations it scales, letters of '
                          f'{"".join(EQUATIONS)} each once (XYZKMN: all), got {eq!r}')
    return Coefficient(name, value, rows[0], 0, (), 1.0, gain_rows=rows, gain_sides=sides)


def _coefficient(name: str, entry: object, cw: str, rho: float, L: float, scaling: str,
                 free: np.ndarray, dofs: object) -> Coefficient:
    """One `name: [value, equation, k, multiplier]` entry (cw: where, for the messages)."""
    if not isinstance(entry, list) or len(entry) != 4:
        raise ConfigError(f'{cw}: expected [value, equation, k, multiplier], got {entry!r}')
    value, eq, k, mult = entry
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f'{cw}: value {value!r} is not a number') from None
    if not np.isfinite(value):
        raise ConfigError(f'{cw}: value {value!r} is not finite')
    if str(mult).strip() in GAIN_MULTIPLIERS:
        return _thrust_gain(name, value, eq, GAIN_MULTIPLIERS[str(mult).strip()], cw)
    if str(mult).strip() == LAG_MULTIPLIER:
        return _thrust_lag(name, value, eq, k, cw)
    if eq not in EQUATIONS:
        raise ConfigError(f'{cw}: equation {eq!r} not one of {" ".join(EQUATIONS)}')
    if not isinstance(k, int) or not 0 <= k <= 6:
        raise ConfigError(f'{cw}: k = {k!r} must be an integer 0..6')
    facs = _parse_multiplier(mult, cw)
    am_col = facs[1] if facs[0] == 'dot' else -1
    scale = _term_scale(rho, L, k, facs if am_col < 0 else (), scaling)
    if am_col >= 0 and not (free[EQUATIONS.index(eq)] and free[am_col]):
        raise ConfigError(f'{cw}: added mass of a held degree of freedom (dofs: '
                          f'{dofs}); leave it out')
    return Coefficient(name, value, EQUATIONS.index(eq), k, facs if am_col < 0 else (), scale,
                       am_col)


def _term_tables(
        coefs: list[Coefficient],
        rigid_terms: list[tuple[int, float, tuple[int, int]]]) -> tuple[list, list, list, list]:
    """(terms_i, terms_s, am_i, am_s) as lists: the monomial term table (the coefficients' terms
    in the file's order, then the rigid-body terms `rigid_terms`) and the added-mass table."""
    terms_i, terms_s, am_i, am_s = [], [], [], []
    for ci, c in enumerate(coefs):
        if c.is_added_mass:
            am_i.append((c.equation, c.added_mass_col, ci))
            am_s.append(c.scale)
        elif c.is_thrust_gain or c.is_thrust_lag:
            continue            # applied by the thruster kernel (hydrodynamics._thrusters)
        else:
            f = list(c.factors) + [-1] * (MAX_FACTORS - len(c.factors))
            terms_i.append([c.equation, ci] + f)
            terms_s.append(c.scale)
    for eq, const, facs in rigid_terms:
        f = list(facs) + [-1] * (MAX_FACTORS - len(facs))
        terms_i.append([eq, -1] + f)
        terms_s.append(const)
    return terms_i, terms_s, am_i, am_s


def _held_rigid_body_mass(mass: float, r_G: np.ndarray, I: Sequence[float],
                          free: np.ndarray) -> np.ndarray:
    """M_RB (6, 6) with identity rows and columns for the held degrees of freedom."""
    M_RB = rigid_body_mass_matrix(mass, r_G, I)
    # A held degree of freedom: its acceleration is zero and the constraint takes whatever
    # force its equation needs, so the free accelerations solve M_ff nu_f_dot = F_f alone.
    # Identity rows and columns for the held ones make M^-1 = blockdiag(M_ff^-1, I) in every
    # code path that inverts M (the held rows of f are zeroed afterwards, core/model/planar.py).
    held_nu = ~free[:N_NU]
    M_RB[held_nu, :] = 0.0
    M_RB[:, held_nu] = 0.0
    M_RB[held_nu, held_nu] = 1.0
    return M_RB


def _mass_inverse(raw: dict, where: str, free: np.ndarray) -> tuple[str, np.ndarray | None]:
    """(mass_inverse, Minv_literal): the file's choice of M^-1 ('exact', or 'mss_literal' with
    its 6x6 `mss_inverse`; None for exact)."""
    mass_inverse = raw.get('mass_inverse', 'exact')
    if mass_inverse == 'exact':
        return mass_inverse, None
    if mass_inverse != 'mss_literal':
        raise ConfigError(f'{where}: mass_inverse = {mass_inverse!r}; use exact or mss_literal')
    if not free.all():
        raise ConfigError(f'{where}: mass_inverse: mss_literal is a 6-DOF inverse; a vehicle '
                          'with dofs needs exact')
    try:
        Minv_literal = np.array(raw['mss_inverse'], dtype=float)
    except (KeyError, TypeError, ValueError) as err:
        raise ConfigError(f'{where}: mass_inverse: mss_literal needs a 6x6 `mss_inverse`') \
            from err
    if Minv_literal.shape != (6, 6) or not np.all(np.isfinite(Minv_literal)):
        raise ConfigError(f'{where}: mss_inverse must be a finite 6x6 matrix')
    return mass_inverse, Minv_literal
