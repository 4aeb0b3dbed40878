"""`export --format vehicle`: the identified values in the vehicle file, read back exactly,
the prior: block holding their 1-sigmas, loadable by every command, and a round trip (the
exported file as the prior of the same bag's identification gives the same coefficients)."""
import json
from pathlib import Path

import helpers
import pytest
import yaml

from auv_ident.analysis.export import export_model, ExportError
from auv_ident.cli import main
from auv_ident.core.model.vehicle import vehicle_from_file
from auv_ident.session.estimate_file import estimate_document, write_estimate_json
from auv_ident.vehicles import load_vehicle

BAG = str(Path(helpers.REPO) / 'bags' / 'nps_auv2_ident')


def _model_json(path, vehicle, values, std, **extra):
    doc = {'vehicle': vehicle, 'source': 'bag runs/tank_1',
           'coefficients': {n: {'estimate': v, 'std': s}
                            for n, v, s in zip(values, values.values(), std)}}
    doc.update(extra)
    path.write_text(json.dumps(doc), encoding='utf-8')
    return path


@pytest.mark.parametrize('vehicle', ['nps_auv2', 'remus100', 'isimi', 'kvlcc2_hsva'])
def test_every_shipped_file_exports_its_identified_values_exactly(tmp_path, vehicle):
    v = load_vehicle(vehicle)
    names = v.identify_default[:3]
    values = {n: v.values[v.index(n)] * 1.1 + 1e-17 for n in names}  # not short decimals
    std = [abs(x) * 0.01 for x in values.values()]
    model = _model_json(tmp_path / 'model.json', vehicle, values, std)
    out = export_model(model, tmp_path / 'out.yaml')
    back = vehicle_from_file(str(out))
    assert back.name == v.name and back.names == v.names
    for n in v.names:
        want = values.get(n, v.values[v.index(n)])
        assert back.values[back.index(n)] == want, n   # to the last bit
    raw = yaml.safe_load(out.read_text(encoding='utf-8'))
    per = raw['prior']['coefficients']
    for n, s in zip(names, std):
        assert per[n] == {'sd': s}
    # the file's own prior entries stay (kvlcc2_hsva's second-order terms)
    for n, entry in ((v.raw.get('prior') or {}).get('coefficients') or {}).items():
        if n not in names:
            assert per[n] == entry
    text = out.read_text(encoding='utf-8')
    assert text.startswith('# Exported by `python -m auv_ident export`')
    line = next(ln for ln in text.splitlines() if ln.lstrip().startswith(names[0] + ': ['))
    assert '1-sigma' in line and 'file value' in line


def test_the_identifier_nodes_estimate_file_exports_too(tmp_path):
    v = load_vehicle('nps_auv2')
    est = [v.values[v.index(n)] * 0.9 for n in ('Z_w', 'M_uq')]
    path = tmp_path / 'estimate.json'
    write_estimate_json(path, estimate_document('nps_auv2', ['Z_w', 'M_uq'], est,
                                                [[1e-6, 0.0], [0.0, 4e-6]], 5 * 10**9, 100))
    out = export_model(path, tmp_path / 'live.yaml')
    back = vehicle_from_file(str(out))
    assert back.values[back.index('M_uq')] == est[1]
    assert yaml.safe_load(out.read_text())['prior']['coefficients']['M_uq'] == {'sd': 0.002}


def test_a_model_identified_with_another_mass_inverse_says_so_in_the_file(tmp_path):
    values = {'Z_wdot': load_vehicle('nps_auv2').values[load_vehicle('nps_auv2').index(
        'Z_wdot')] * 1.2}
    model = _model_json(tmp_path / 'm.json', 'nps_auv2', values, [1e-4], mass_inverse='exact')
    back = vehicle_from_file(str(export_model(model, tmp_path / 'v.yaml')))
    assert back.mass_inverse == 'exact'


def test_refusals_name_the_culprit(tmp_path, capsys):
    values = {'Z_w': -0.31}
    model = _model_json(tmp_path / 'm.json', 'nps_auv2', values, [1e-3])
    (tmp_path / 'taken.yaml').write_text('keep me', encoding='utf-8')
    assert main(['export', str(model), '--out', str(tmp_path / 'taken.yaml')]) == 2
    assert 'exists already' in capsys.readouterr().err
    assert (tmp_path / 'taken.yaml').read_text() == 'keep me'
    assert main(['export', str(model), '--out', str(tmp_path / 'taken.yaml'), '--force']) == 0
    assert main(['export', str(model), '--bag', 'b', '--out', str(tmp_path / 'x.yaml')]) == 2
    assert '--bag and --fit-out are for the fitted formats' in capsys.readouterr().err
    assert main(['export', str(model), '--vehicle', 'remus100', '--out',
                 str(tmp_path / 'x.yaml')]) == 2
    assert "model of 'nps_auv2'" in capsys.readouterr().err
    # a file whose coefficient is not in the one-line flow form is not guessed at
    raw = Path(load_vehicle('nps_auv2').path).read_text(encoding='utf-8')
    odd = tmp_path / 'odd.yaml'
    odd.write_text(raw.replace('  Z_w: [-0.3, Z, 2, u*w]', '  Z_w:\n    [-0.3, Z, 2, u*w]'),
                   encoding='utf-8')
    with pytest.raises(ExportError, match='Z_w'):
        export_model(model, tmp_path / 'y.yaml', vehicle=str(odd))
    assert not (tmp_path / 'y.yaml').exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith('.')] == []


def test_the_exported_file_simulates(tmp_path):
    model = _model_json(tmp_path / 'm.json', 'nps_auv2', {'Z_w': -0.33}, [1e-3])
    out = export_model(model, tmp_path / 'v.yaml')
    assert main(['simulate', '--vehicle', str(out), '--maneuver', 'ident', '--duration', '5',
                 '--out', str(tmp_path / 'sim')]) == 0


@pytest.mark.slow   # two identifications of the shipped 600 s bag
def test_round_trip_identify_export_identify_gives_the_same_coefficients(tmp_path):
    first, second = tmp_path / 'a.json', tmp_path / 'b.json'
    common = ['--current', 'none', '--no-refine']
    assert main(['identify', '--bag', BAG, *common, '--json', str(first)]) == 0
    assert main(['export', str(first), '--out', str(tmp_path / 'v.yaml')]) == 0
    # the same vehicle (its name kept): no --other-vehicle needed
    assert main(['identify', '--bag', BAG, '--vehicle', str(tmp_path / 'v.yaml'), *common,
                 '--json', str(second)]) == 0
    a = json.loads(first.read_text())['coefficients']
    b = json.loads(second.read_text())['coefficients']
    assert list(a) == list(b)
    for n in a:
        assert abs(b[n]['estimate'] - a[n]['estimate']) < 0.01 * a[n]['std'], n
        assert b[n]['std'] == pytest.approx(a[n]['std'], rel=1e-3)


def test_report_export_refuses_an_unknown_format_before_any_work(tmp_path, capsys):
    assert main(['report', '--simulate', 'ident', '--duration', '5', '--out',
                 str(tmp_path / 'rep'), '--export', 'vrml']) == 2
    assert "--export 'vrml': use one of" in capsys.readouterr().err
    assert not (tmp_path / 'rep').exists()


def test_export_into_a_report_folder_names_each_format(tmp_path):
    from auv_ident.analysis.export import export_into, REPORT_FILES
    model = _model_json(tmp_path / 'm.json', 'remus100', {'Z_w': -70.0}, [1.0])
    paths = export_into(tmp_path, model, ['python', 'gz', 'vehicle', 'gz'])
    assert [p.name for p in paths] == [REPORT_FILES[f] for f in ('python', 'gz', 'vehicle')]
    assert (tmp_path / 'gz.sdf.fit.json').exists()
    assert vehicle_from_file(str(tmp_path / 'vehicle.yaml')).values[
        load_vehicle('remus100').index('Z_w')] == -70.0


@pytest.mark.slow   # a report of a simulated run (~30 s)
def test_report_exports_its_model_into_its_folder(tmp_path):
    out = tmp_path / 'rep'
    assert main(['report', '--simulate', 'ident', '--duration', '60', '--vehicle', 'remus100',
                 '--out', str(out), '--export', 'vehicle', '--export', 'python']) in (0, 1)
    doc = json.loads((out / 'result.json').read_text(encoding='utf-8'))
    back = vehicle_from_file(str(out / 'vehicle.yaml'))
    for n, c in doc['coefficients'].items():
        assert back.values[back.index(n)] == c['estimate'], n
    assert 'def simulate(' in (out / 'model.py').read_text(encoding='utf-8')
