"""A glider's vehicle file (``kind: glider``, config/slocum_comet.yaml): its flight model's
parameters with the prior they come from, validated as the 6-DOF vehicle files are
(:mod:`auv_ident.core.vehicle_files`: every problem at once, each naming its key, in one
:class:`~auv_ident.core.vehicle_files.VehicleFileProblems`).

Keys (SI): ``kind: glider``, ``name``, ``prior`` (the published source of the values, a text),
``pitch_source`` (``measured``: the flight model reads the pitch, :mod:`.flight` says why),
and the numbers of :data:`NUMBERS`; the lift slope of the model is the hull's plus the wings'
(``lift_slope_hull + lift_slope_wings``). An unknown key is a problem too (a misspelt key
would otherwise leave its value unread).
"""
from dataclasses import dataclass
import os
from typing import Any

from auv_ident.core.errors import ConfigError
from auv_ident.core.glider.flight import GliderParameters
from auv_ident.core.vehicle_files import (
    file_kind,
    finite_number,
    read_yaml_file,
    VehicleFileProblems,
)

# key: (must be positive (True) or only >= 0 (False), meaning for the message)
NUMBERS = {
    'mass': (True, 'kg, in air'),
    'hull_volume': (True, 'V_g m^3 at zero gauge pressure and reference_temperature'),
    'compressibility': (False, 'epsilon 1/Pa, the hull'),
    'thermal_expansion': (False, 'alpha_T 1/K, the hull, volumetric'),
    'reference_temperature': (False, 'T_0 degC of hull_volume'),
    'wing_area': (True, "S m^2, the coefficients' reference area"),
    'drag_zero_lift': (True, 'C_D0'),
    'induced_drag': (False, 'C_D1 1/rad^2'),
    'lift_slope_hull': (False, 'a_h 1/rad'),
    'lift_slope_wings': (False, 'a_w 1/rad'),
    'added_mass_axial': (False, 'k1, fraction of the mass'),
    'added_mass_normal': (False, 'k2, fraction of the mass'),
}
SIGNED = ('reference_temperature',)     # any finite value
PITCH_SOURCES = ('measured',)
TEXTS = ('kind', 'name', 'prior', 'pitch_source')


@dataclass(frozen=True)
class GliderVehicle:
    """A glider's vehicle file, read: its name, the flight model's prior ``params``, the
    published source of the values ``prior`` and where the pitch comes from."""

    name: str
    params: GliderParameters
    prior: str
    pitch_source: str
    path: str


def _numbers(raw: dict[str, Any], where: str, problems: list[str]) -> dict[str, float]:
    values: dict[str, float] = {}
    for key, (positive, meaning) in NUMBERS.items():
        if key not in raw:
            problems.append(f'missing key {key!r} ({meaning})')
            continue
        try:
            v = finite_number(raw, key, where, positive=positive)
        except ConfigError as err:
            problems.append(str(err).removeprefix(f'{where}: '))
            continue
        if v < 0 and key not in SIGNED:
            problems.append(f'{key} = {v!r} must not be negative ({meaning})')
            continue
        values[key] = v
    return values


def _texts(raw: dict[str, Any], problems: list[str]) -> None:
    for key in ('name', 'prior'):
        if not isinstance(raw.get(key), str) or not raw[key].strip():
            problems.append(f'missing key {key!r} (a text: '
                            + ("the vehicle's name)" if key == 'name' else
                               'the published source of the values)'))
    source = raw.get('pitch_source')
    if source not in PITCH_SOURCES:
        problems.append(f'pitch_source = {source!r}; only measured: the flight model reads the '
                        'pitch, it does not model it from the battery position (docs/glider.md)')
    unknown = sorted(str(k) for k in raw if k not in NUMBERS and k not in TEXTS)
    if unknown:
        problems.append(f'unknown key(s) {", ".join(map(repr, unknown))}; known: '
                        f'{", ".join((*TEXTS, *NUMBERS))}')


def glider_from_dict(raw: object, path: str) -> GliderVehicle:
    """The GliderVehicle of a parsed glider file (module docstring), or VehicleFileProblems
    naming every bad key."""
    where = os.path.basename(path)
    if file_kind(raw) != 'glider':
        raise ConfigError(f'{where}: not a glider file (`kind: glider` missing)')
    assert isinstance(raw, dict)
    problems: list[str] = []
    values = _numbers(raw, where, problems)
    _texts(raw, problems)
    if problems:
        raise VehicleFileProblems(where, problems)
    lift_slope = values.pop('lift_slope_hull') + values.pop('lift_slope_wings')
    params = GliderParameters(lift_slope=lift_slope, **values)
    return GliderVehicle(name=raw['name'], params=params, prior=' '.join(raw['prior'].split()),
                         pitch_source=raw['pitch_source'], path=path)


def glider_from_file(path: str) -> GliderVehicle:
    """Load and validate a glider's vehicle file given by its path (module docstring)."""
    if not os.path.isfile(path):
        raise ConfigError(f'no glider file {path}')
    return glider_from_dict(read_yaml_file(path), path)
