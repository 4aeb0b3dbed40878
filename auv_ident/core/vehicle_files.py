"""Reading vehicle files, of every kind: the YAML (a key written twice refused), the checked
numbers, the error that lists every problem of a file at once, and the file's kind. Shared by
the 6-DOF vehicle files (:mod:`auv_ident.core.model.vehicle`) and the glider's
(:mod:`auv_ident.core.glider.vehicle`), so that both name a bad key the same way."""
from typing import Any

import numpy as np
import yaml

from auv_ident.core.errors import ConfigError


class VehicleFileProblems(ConfigError):
    """Every problem found in a vehicle file's entries at once (``problems``: one text each),
    so that a new file is put right in one round, not one run per missing key."""

    def __init__(self, where: str, problems: list[str]):
        self.where = where
        self.problems = list(problems)
        count = f'{len(problems)} problems' if len(problems) > 1 else 'problem'
        super().__init__(f'{where}: {count}: ' + '; '.join(problems))


def finite_number(d: dict, key: str, where: str, positive: bool = False,
                  meaning: str | None = None) -> float:
    """d[key] as a finite (positive) float, or ConfigError naming the key (and, when it is
    missing, its ``meaning``: units, what it is)."""
    if key not in d:
        raise ConfigError(f'{where}: missing key {key!r}'
                          + (f' ({meaning})' if meaning else ''))
    try:
        v = float(d[key])
    except (TypeError, ValueError):
        raise ConfigError(f'{where}: {key} = {d[key]!r} is not a number') from None
    if not np.isfinite(v) or (positive and v <= 0):
        raise ConfigError(f'{where}: {key} = {v!r} must be a finite'
                          + (' positive' if positive else '') + ' number')
    return v


class _UniqueKeyLoader(yaml.SafeLoader):
    """yaml.SafeLoader that refuses a mapping holding one key twice (PyYAML keeps the last
    silently, so a coefficient written twice would take whichever came last)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: dict = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.setdefault(key, key_node.start_mark.line + 1)
            except TypeError:       # an unhashable key: the base class says so
                break
            if first != key_node.start_mark.line + 1:
                raise yaml.constructor.ConstructorError(
                    None, None, f'duplicate key {key!r} (first on line {first})',
                    key_node.start_mark)
        return super().construct_mapping(node, deep=deep)


def read_yaml_file(path: str) -> Any:
    """The parsed YAML of a vehicle file (any kind); a duplicate key or a syntax error is a
    ConfigError naming the file and the line."""
    with open(path, encoding='utf-8') as fh:
        try:
            return yaml.load(fh, Loader=_UniqueKeyLoader)   # noqa: S506 (a SafeLoader)
        except yaml.YAMLError as err:
            raise ConfigError(f'{path}: not valid YAML: {_yaml_problem(err)}') from None


def file_kind(raw: object) -> str:
    """'glider' for a glider's file (``kind: glider``, :mod:`auv_ident.core.glider.vehicle`),
    else '6dof' (:mod:`auv_ident.core.model.vehicle`)."""
    return 'glider' if isinstance(raw, dict) and raw.get('kind') == 'glider' else '6dof'


def _yaml_problem(err: yaml.YAMLError) -> str:
    """A YAML error on one line: its problem and where (PyYAML's text spans several lines)."""
    problem = getattr(err, 'problem', None)
    mark = getattr(err, 'problem_mark', None)
    if problem is None or mark is None:
        return ' '.join(str(err).split())
    return f'{problem} (line {mark.line + 1}, column {mark.column + 1})'
