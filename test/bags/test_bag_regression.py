"""Tier 5: the shipped reference bag identifies to stored coefficients (regression)."""
import json
import os

import numpy as np
import pytest

from auv_ident.analysis.bag_identify import identify_bag
from helpers import REPO

pytestmark = pytest.mark.slow     # a 600 s identification (EKF pass + refinement)

BAG = os.path.join(REPO, 'bags', 'nps_auv2_ident')
# python -m auv_ident identify --bag bags/nps_auv2_ident --json out.json  (2026-11-22)
EXPECTED = {'Z_ds': -0.0729665, 'Z_q': -0.139586, 'Z_w': -0.300093, 'M_ds': -0.0410185,
            'K_v': 0.00307345}


def test_shipped_bag_identifies_within_one_percent_and_matches_the_stored_result(tmp_path):
    doc, table = identify_bag(BAG)
    assert doc['vehicle'] == 'nps_auv2' and doc['steps'] == 12001 and doc['rejected'] == 0
    for name, val in EXPECTED.items():
        c = doc['coefficients'][name]
        assert abs(c['error_pct']) < 1.0, (name, c)
        assert abs(c['estimate'] - c['truth']) < 3 * c['std'], (name, c)
        assert np.isclose(c['estimate'], val, rtol=2e-6), (name, c['estimate'], val)
    assert 'K_v' in table and 'paper err %' in table
    json.dumps(doc)
