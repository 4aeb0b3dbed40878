"""Tier 1/5: the validation report (figures, table vs JSON, held-out validation)."""
import json
import re

import matplotlib.image as mpimg
import numpy as np
import pytest

from auv_ident.core.errors import ConfigError
from auv_ident.core.vehicle import load_vehicle
from auv_ident.report import make_report, validate

PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


@pytest.fixture(scope='module')
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp('report')
    return make_report(str(out), vehicle='nps_auv2', simulate_maneuver='ident', seed=2,
                       duration=60.0, validation_duration=40.0, command='pytest',
                       progress=False)


def test_every_figure_exists_and_is_a_valid_png(report):
    names = set(report['figures'])
    assert {'convergence', 'validation_positions', 'validation_attitudes',
            'validation_speeds', 'nis', 'adapted_noise'} <= names
    for path in report['figures'].values():
        with open(path, 'rb') as fh:
            assert fh.read(8) == PNG_MAGIC, path
        img = mpimg.imread(path)
        assert img.shape[0] > 200 and img.shape[1] > 300, path


def test_report_table_numbers_equal_the_json(report):
    text = open(report['report'], encoding='utf-8').read()
    doc = json.load(open(report['json'], encoding='utf-8'))
    assert doc == json.loads(json.dumps(report['result']))
    for name, c in doc['coefficients'].items():
        row = next(line for line in text.splitlines()
                   if re.match(rf'^\|\s*`?{re.escape(name)}`?\s*\|', line))
        nums = [float(x) for x in re.findall(r'[-+]?\d+\.?\d*(?:[eE][-+]?\d+)?', row)]
        for key in ('truth', 'estimate', 'std'):
            assert any(np.isclose(n, c[key], rtol=1e-5) for n in nums), (name, key, row)
    for fig in ('convergence.png', 'validation_positions.png', 'nis.png'):
        assert f']({fig})' in text
    assert 'pytest' in text          # the exact command


def test_validation_with_true_coefficients_is_exact_and_with_wrong_ones_is_not():
    v = load_vehicle('nps_auv2')
    names = ['Z_w', 'K_v']
    truth = np.array([v.values[v.index(n)] for n in names])
    val = validate(v, names, truth, 'steps', 30.0, 1000, identification_maneuver='ident')
    assert val.maneuver == 'steps'
    assert all(r == 0.0 for r in val.rms.values())
    bad = validate(v, names, truth * 1.2, 'steps', 30.0, 1000, identification_maneuver='ident')
    assert bad.rms['w'] > 0 and bad.rms['z'] > 0


def test_validation_on_the_identification_manoeuvre_is_refused():
    with pytest.raises(ConfigError, match='held-out'):
        validate('nps_auv2', ['Z_w'], np.array([-0.3]), 'ident', 10.0, 1000,
                 identification_maneuver='ident')
