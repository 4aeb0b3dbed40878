"""One list of identifier settings: the node's declared parameters, the command-line options,
config/identifier.yaml and the docs/ros.md table all agree with the fields of
IdentifierSettings (names, defaults, help, choices), and the last two are what
tools/settings_docs.py writes from them."""
from pathlib import Path

import pytest
from rclpy.parameter import Parameter
import yaml

from auv_ident.cli import build_parser
from auv_ident.ros.identifier_node import _PARAMETERS
from auv_ident.session.settings import help_text, IdentifierSettings, settings_fields
from auv_ident.session.settings_text import (
    docs_cell,
    docs_default,
    replace_docs_table,
    SAVE_PATH,
    yaml_text,
)

REPO = Path(__file__).resolve().parents[2]
FIELDS = settings_fields()
NAMES = [f.name for f in FIELDS]


def _subparser(name):
    sub = next(a for a in build_parser()._actions if a.dest == 'cmd')
    return sub.choices[name]


def test_the_node_declares_every_setting_from_its_field():
    assert [p.name for p in _PARAMETERS] == NAMES + [SAVE_PATH[0]]
    for f, p in zip(FIELDS, _PARAMETERS):
        assert p.description == help_text(f), f.name
        if isinstance(p.default, Parameter.Type):        # an empty list: typed, unset
            assert f.default == (), f.name
        else:
            assert type(p.default) is (list if isinstance(f.default, tuple)
                                       else type(f.default)), f.name
            assert p.default == (list(f.default) if isinstance(f.default, tuple)
                                 else f.default), f.name


def test_the_node_parameters_read_back_as_the_default_settings():
    values = {p.name: None if isinstance(p.default, Parameter.Type) else p.default
              for p in _PARAMETERS if p.name != SAVE_PATH[0]}
    assert IdentifierSettings.from_values(**values) == IdentifierSettings()


@pytest.mark.parametrize('command, names', [('identify', NAMES),
                                            ('report', None), ('montecarlo', None)])
def test_the_command_line_options_are_made_from_the_fields(command, names):
    options = {a.dest: a for a in _subparser(command)._actions if a.option_strings}
    fields = {f.name: f for f in FIELDS}
    mirrored = [n for n in options if n in fields]
    if names is not None:
        assert set(names) <= set(mirrored)
    for name in mirrored:
        f, a = fields[name], options[name]
        assert '--' + name.replace('_', '-') in a.option_strings
        assert a.default is None        # not given: the default, or what a bag says
        assert a.help.replace('%%', '%').startswith(help_text(f)), name
        assert tuple(a.choices or ()) == f.metadata['choices'], name


def test_the_command_line_builds_the_settings_it_was_given():
    from auv_ident.cli.common import settings_of as _settings
    args = _subparser('identify').parse_args(
        ['--bag', 'x', '--coefficients', 'auto,Z_ds', '--mass-inverse', 'exact',
         '--noise-std', ','.join(['0.1'] * 12), '--current-down', '--max-command-age', '0.5'])
    s = _settings(args)
    assert s == IdentifierSettings(coefficients=('auto', 'Z_ds'), mass_inverse='exact',
                                   noise_std=(0.1,) * 12, current_down=True,
                                   max_command_age=0.5)
    assert s.given == {'coefficients', 'mass_inverse', 'noise_std', 'current_down',
                       'max_command_age'}


def test_config_identifier_yaml_lists_every_setting_at_its_default():
    text = (REPO / 'config' / 'identifier.yaml').read_text(encoding='utf-8')
    params = yaml.safe_load(text)['identifier']['ros__parameters']
    assert list(params) == NAMES + [SAVE_PATH[0]]
    for f in FIELDS:
        value = params[f.name]
        assert (tuple(value) if isinstance(value, list) else value) == f.default, f.name
        assert type(value) is (list if isinstance(f.default, tuple) else type(f.default))
    assert params[SAVE_PATH[0]] == SAVE_PATH[1]
    assert text == yaml_text(), 'config/identifier.yaml: python tools/settings_docs.py'


def test_the_docs_table_lists_every_setting_with_its_default_and_help():
    text = (REPO / 'docs' / 'ros.md').read_text(encoding='utf-8')
    section = text.split('\n## identifier\n', 1)[1]
    rows = [line for line in section.split('\n## ', 1)[0].splitlines()
            if line.startswith('| `')]
    cells = [[c.strip() for c in row.strip('|').split(' | ')] for row in rows]
    assert [c[0] for c in cells] == [f'`{n}`' for n in NAMES + [SAVE_PATH[0]]]
    for f, (_, default, meaning) in zip(FIELDS, cells):
        assert default == docs_default(f), f.name
        assert meaning == docs_cell(help_text(f)), f.name
    assert text == replace_docs_table(text), 'docs/ros.md: python tools/settings_docs.py'
