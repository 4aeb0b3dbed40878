"""Tier 5: the shipped reference bag identifies to stored coefficients (regression)."""
import json
import os

from helpers import REPO
import numpy as np
import pytest

from auv_ident.analysis.bag_identify import identify_bag
from auv_ident.session.settings import IdentifierSettings

pytestmark = pytest.mark.slow     # a 600 s identification (EKF pass + refinement)

BAG = os.path.join(REPO, 'bags', 'nps_auv2_ident')
# python -m auv_ident identify --bag bags/nps_auv2_ident --current none --json out.json
# (2026-11-22; the still-water filter, kept bit for bit when the current is not identified)
EXPECTED = {'Z_ds': -0.0729665, 'Z_q': -0.139586, 'Z_w': -0.300093, 'M_ds': -0.0410185,
            'K_v': 0.00307345}


def test_shipped_bag_identifies_within_one_percent_and_matches_the_stored_result(tmp_path):
    doc, table = identify_bag(BAG, IdentifierSettings.from_values(current='none'))
    assert doc['vehicle'] == 'nps_auv2' and doc['steps'] == 12001 and doc['rejected'] == 0
    for name, val in EXPECTED.items():
        c = doc['coefficients'][name]
        assert abs(c['error_pct']) < 1.0, (name, c)
        assert abs(c['estimate'] - c['truth']) < 3 * c['std'], (name, c)
        assert np.isclose(c['estimate'], val, rtol=2e-6), (name, c['estimate'], val)
    assert doc['current'] is None and doc['warnings'] == []
    assert 'K_v' in table and 'paper err %' in table and 'current (m/s)' not in table
    json.dumps(doc)


def test_shipped_still_water_bag_with_the_current_estimated_finds_no_current():
    """The default (current estimated) on still water: the same accuracy, and a current of 0
    within its 3-sigma (the bag's metadata say it was simulated in still water)."""
    doc, table = identify_bag(BAG)
    for name in EXPECTED:
        c = doc['coefficients'][name]
        assert abs(c['error_pct']) < 1.0, (name, c)
        assert abs(c['estimate'] - c['truth']) < 3 * c['std'], (name, c)
    cur = doc['current']
    assert cur['estimated'] == ['current_n', 'current_e'] and cur['truth'] == [0.0, 0.0, 0.0]
    assert cur['velocity_reference'] == 'ground' and cur['down'] == 0.0
    for i in range(2):
        assert abs(cur['error'][i]) < max(3 * cur['std'][i], 1e-3), cur
    assert cur['identifiability']['separable'], cur['identifiability']
    assert 'current (m/s)' in table and 'north' in table and 'warning' not in table
    json.dumps(doc)
