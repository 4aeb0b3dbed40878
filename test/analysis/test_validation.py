"""Validation against the measurements of a held-out run (analysis/validation.py), report
--validate through the command line, and the self-contained report.html."""
import base64
from html.parser import HTMLParser
import json
import os

import numpy as np
import pytest

from auv_ident import cli
from auv_ident.analysis.bag_identify import bag_source
from auv_ident.analysis.experiments import load_source
from auv_ident.analysis.report import make_report
from auv_ident.analysis.report_html import markdown_to_html
from auv_ident.analysis.results import coefficient_list
from auv_ident.analysis.validation import (
    refuse_identification_run,
    refuse_same_bag,
    split_held_out,
    validate_on_bag,
    validate_on_run,
)
from auv_ident.core.errors import ConfigError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.model.state import N_STATE, NU_NAMES, STATE_NAMES
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.independent_data import DataConfig, generate
from auv_ident.offline.sim_bag import write_run_bag
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


@pytest.fixture(scope='module')
def perturbed_run():
    """A noise-free 60 s 'steps' run of a truth vehicle whose five paper coefficients are the
    file's x 1.2: (vehicle, names, truth values of the names, run)."""
    v = load_vehicle('nps_auv2')
    names = coefficient_list(v, '')
    est = 1.2 * Model(v, names).theta_true
    truth = Model(v, coefficient_values=Model(v, names).coefficients_with(est))
    run = simulate(truth, 'steps', duration=60.0, seed=4, noise_std=np.zeros(N_STATE))
    return v, names, est, run


def test_true_model_fits_noise_free_measurements_and_the_file_model_does_worse(perturbed_run):
    v, names, est, run = perturbed_run
    val = validate_on_run(v, names, est, None, run.t, run.y, run.u, source='steps')
    doc = val.document()
    assert doc['models'] == ['identified', 'prior'] and set(doc['channels']) == set(STATE_NAMES)
    for ch, d in doc['channels'].items():
        if ch == 'u':      # constant shaft speed: surge barely moves, but the fit still holds
            assert d['fit_percent'] > 99.0, (ch, d)
        else:
            assert d['fit_percent'] > 99.9 and d['theil'] < 1e-3, (ch, d)
        assert d['rmse'] <= d['rmse_prior'], (ch, d)
    assert doc['mean_fit_percent_nu']['identified'] > 99.9
    assert doc['mean_fit_percent_nu']['prior'] < doc['mean_fit_percent_nu']['identified'] - 5
    for ch in ('w', 'q', 'theta', 'z'):          # the perturbed coefficients act in pitch
        assert doc['channels'][ch]['fit_percent_prior'] < 95.0, (ch, doc['channels'][ch])
    # K-step prediction: the true model stays on the data, the file model's error grows with K
    k = {K: doc['prediction'][f'K{K}']['channels']['z'] for K in (1, 10, 100)}
    assert all(k[K]['rmse'] < 1e-6 for K in k)
    assert k[1]['rmse_prior'] < k[10]['rmse_prior'] < k[100]['rmse_prior']
    assert doc['prediction']['K10']['horizon_s'] == pytest.approx(0.5)
    assert json.loads(json.dumps(doc)) == doc     # JSON-able as it stands


def test_missing_position_channels_are_filled_from_trim_and_not_scored(perturbed_run):
    v, names, est, run = perturbed_run
    Y = run.y.copy()
    Y[:, 6:8] = np.nan                  # no position fixes (x, y)
    Y[::7, :] = np.nan                  # and rows without any measurement
    val = validate_on_run(v, names, est, None, run.t, Y, run.u, x0_window=0.0)
    doc = val.document()
    assert set(doc['channels']) == set(STATE_NAMES) - {'x', 'y'}
    assert set(doc['initial_state']['filled']) == {'x', 'y'}
    assert doc['initial_state']['x0'][6:8] == [0.0, 0.0]
    assert all(doc['channels'][ch]['fit_percent'] > 99.0 for ch in NU_NAMES)
    assert doc['samples'] == len(run.t) - len(run.t[::7])


def test_held_out_split_and_refusal_of_the_identification_run():
    a = load_source(IdentifierSettings(), 'ident', seed=1, duration=40.0)
    b = load_source(IdentifierSettings(), 'ident', seed=2, duration=40.0)
    ident, held = split_held_out(a, 0.25)
    assert ident.t[-1] < 30.0 <= held.t[0] and len(ident.t) + len(held.t) == len(a.t)
    assert held.description.startswith('final 25 % (held out)')
    with pytest.raises(ConfigError, match='fraction'):
        split_held_out(a, 0.95)
    with pytest.raises(ConfigError, match='is the identification run'):
        refuse_identification_run(a, a)          # a copy
    with pytest.raises(ConfigError, match='is the identification run'):
        refuse_identification_run(a, held)       # a cut of it
    refuse_identification_run(a, b)              # another run: same stamps, other values
    refuse_identification_run(ident, held)       # the held-out part is not the identified part


def test_a_bag_of_the_simulated_identification_run_is_refused(tmp_path):
    """--simulate M --validate BAG where BAG holds the same simulation: the bag's stamps have an
    epoch and its attitudes went through quaternions, yet it is the identification run."""
    a = load_source(IdentifierSettings(), 'ident', seed=0, duration=20.0)
    bag = write_run_bag(simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=20.0,
                                 seed=0), str(tmp_path / 'same'))
    same = bag_source(bag)
    assert same.time_origin_ns > 0 and a.time_origin_ns == 0
    with pytest.raises(ConfigError, match='100 % of its samples'):
        refuse_identification_run(a, same)


def test_validate_on_bag_scores_given_coefficients_on_a_bag(tmp_path):
    """A model given by its values (as from an estimate file) scored on a bag: with the file's
    own values it is the prior, so both models fly the same and follow the bag."""
    data = generate(DataConfig(seed=7, duration=20.0), tmp_path / 'gen')
    v = load_vehicle('nps_auv2')
    names = coefficient_list(v, '')
    val, run = validate_on_bag(v, names, Model(v, names).theta_true, None, str(data.bag))
    doc = val.document()
    assert run.description.startswith(f'bag {data.bag} (')
    assert doc['models'] == ['identified', 'prior']
    assert all(d['fit_percent'] == d['fit_percent_prior'] for d in doc['channels'].values())
    assert doc['channels']['r']['fit_percent'] > 80


def test_same_bag_path_is_refused_before_anything_is_written(tmp_path):
    data = generate(DataConfig(seed=7, duration=5.0), tmp_path / 'gen')
    with pytest.raises(ConfigError, match='identification bag itself'):
        refuse_same_bag(str(data.bag), str(tmp_path / 'gen' / '.' / 'bag'))
    out = tmp_path / 'report'
    with pytest.raises(ConfigError, match='identification bag itself'):
        make_report(str(out), bag=str(data.bag), validate_bag=str(data.bag), progress=False)
    assert not out.exists()


class _Page(HTMLParser):
    """Tags, attributes and the title of an HTML page."""

    def __init__(self):
        super().__init__()
        self.tags, self.attrs, self.title, self._in_title = [], [], '', False

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self.attrs.append((tag, dict(attrs)))
        self._in_title = tag == 'title'

    def handle_endtag(self, tag):
        self._in_title = False

    def handle_data(self, data):
        if self._in_title:
            self.title += data


@pytest.fixture(scope='module')
def cli_report(tmp_path_factory):
    """report --bag A --validate B through the command line, on two 40 s independent bags of
    the same vehicle (another seed: another manoeuvre and noise)."""
    base = tmp_path_factory.mktemp('cli_validate')
    a = generate(DataConfig(seed=11, duration=40.0, odom_rate=20.0), base / 'a')
    b = generate(DataConfig(seed=12, duration=30.0, odom_rate=20.0), base / 'b')
    out = base / 'report'
    code = cli.main(['report', '--bag', str(a.bag), '--validate', str(b.bag), '--out', str(out)])
    return code, a, b, out


def test_cli_report_validates_on_another_bag(cli_report, capsys):
    code, a, b, out = cli_report
    assert code == 0
    doc = json.loads((out / 'result.json').read_text())
    vd = doc['validation']
    # every sample is used (but the first, when its command arrived after it)
    assert vd['source'] in {f'bag {b.bag} ({n} samples)'
                            for n in (len(b.odom_stamp_ns) - 1, len(b.odom_stamp_ns))}
    assert vd['holdout_fraction'] is None
    assert doc['source'] in {f'bag {a.bag} ({n} samples)'
                             for n in (len(a.odom_stamp_ns) - 1, len(a.odom_stamp_ns))}
    assert vd['duration_s'] == pytest.approx(30.0, abs=0.2)
    for ch in STATE_NAMES:
        assert set(vd['channels'][ch]) == {'fit_percent', 'fit_percent_prior', 'rmse',
                                           'rmse_prior', 'theil', 'theil_prior'}
    assert set(vd['prediction']) == {'K1', 'K10', 'K100'}
    # the truth is the file: both models follow B's yaw rate closely
    r_fit = vd['channels']['r']
    assert r_fit['fit_percent'] > 80 and r_fit['fit_percent_prior'] > 80


def test_cli_report_refuses_the_identification_bag_in_one_line(cli_report, capsys, tmp_path):
    _, a, _, _ = cli_report
    capsys.readouterr()
    code = cli.main(['report', '--bag', str(a.bag), '--validate', str(a.bag),
                     '--out', str(tmp_path / 'r')])
    err = capsys.readouterr().err
    assert code == 2 and err.count('\n') == 1 and 'identification bag itself' in err


def test_report_html_is_self_contained(cli_report):
    _, _, _, out = cli_report
    text = (out / 'report.html').read_text(encoding='utf-8')
    md = (out / 'report.md').read_text(encoding='utf-8')
    page = _Page()
    page.feed(text)
    page.close()
    assert page.tags[0] == 'html' and page.title.startswith('Identification report: ')
    md_tables = sum(1 for i, ln in enumerate(md.splitlines()[1:], 1)
                    if ln.startswith('|---') and md.splitlines()[i - 1].startswith('|'))
    assert page.tags.count('table') == md_tables >= 5
    assert '<th>fit % identified</th>' in text and '<th>K=100 prior (vehicle file)</th>' in text
    imgs = [a for tag, a in page.attrs if tag == 'img']
    assert len(imgs) == md.count('](') == len([f for f in os.listdir(out) if f.endswith('.png')])
    for a in imgs:
        assert a['src'].startswith('data:image/png;base64,')
        assert base64.b64decode(a['src'].split(',', 1)[1]).startswith(PNG_SIGNATURE)
    for tag, a in page.attrs:           # nothing loaded from elsewhere
        for key in ('src', 'href'):
            assert key not in a or a[key].startswith('data:'), (tag, a)
    assert tag != 'link' and 'script' not in page.tags


def test_markdown_to_html_escapes_and_drops_links(tmp_path):
    text = markdown_to_html('# R <1>\n\nsee [docs](http://example.com) and `a<b`\n\n'
                            '- one *two*\n- **three**\n', str(tmp_path))
    assert '<title>R &lt;1&gt;</title>' in text and 'href' not in text
    assert 'see docs and <code>a&lt;b</code>' in text
    assert '<li>one <em>two</em></li>' in text and '<li><strong>three</strong></li>' in text
    with pytest.raises(FileNotFoundError):
        markdown_to_html('![x](missing.png)', str(tmp_path))
