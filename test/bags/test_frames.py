"""An ENU/FLU (REP-103) bag without frame metadata: frame 'auto' reads its frame ids ('odom',
'base_link': no _ned/_frd token) as ENU/FLU and identifies it right; forced to NED, the same
bag is never called consistent with flipped signs: NOT plausible on the first line, exit 3."""
import re

import pytest

from auv_ident.cli import EXIT_UNTRUSTED, main
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.sim_bag import write_run_bag
from auv_ident.vehicles import load_vehicle

TRUTH = {'Z_ds': -0.073, 'Z_q': -0.14, 'Z_w': -0.3, 'M_ds': -0.041}


@pytest.fixture(scope='module')
def enu_bag(tmp_path_factory):
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=200, seed=5)
    path = write_run_bag(run, tmp_path_factory.mktemp('enu') / 'bag', frame='enu')
    meta = path / 'metadata.yaml'
    text = meta.read_text()
    meta.write_text(re.sub(r'\n +auv_ident\.frame: enu', '', text))  # as a foreign recorder
    assert 'auv_ident.frame' not in meta.read_text()
    return str(path)


def _table(out):
    rows = {}
    for line in out.splitlines():
        parts = line.split()
        if parts and parts[0] in TRUTH and len(parts) > 2:
            rows[parts[0]] = float(parts[2])
    return rows


def test_an_enu_bag_without_metadata_is_read_as_rep103(enu_bag, capsys):
    rc = main(['identify', '--bag', enu_bag, '--current', 'none', '--no-refine'])
    out = capsys.readouterr().out
    assert rc == 0 and out.startswith('consistent'), out[:300]
    est = _table(out)
    for name, truth in TRUTH.items():
        assert est[name] * truth > 0 and abs(est[name] / truth - 1) < 0.05, (name, est[name])


def test_the_enu_bag_forced_to_ned_is_flagged_not_consistent_with_flipped_signs(enu_bag,
                                                                                 capsys):
    rc = main(['identify', '--bag', enu_bag, '--frame', 'ned', '--current', 'none',
               '--no-refine'])
    out = capsys.readouterr().out
    first = out.splitlines()[0]
    assert rc == EXIT_UNTRUSTED and first.startswith('NOT plausible: ')
    assert 'Z_ds' in first and 'M_ds' in first and 'opposite sign' in first
