"""Raw sensors against a fused odometry of the same independent run (analysis/raw_comparison.py):
the small version of tools/raw_sensor_campaign.py (one 120 s run)."""
import numpy as np
import pytest

from auv_ident.analysis.raw_comparison import compare_case, summary


@pytest.mark.slow
def test_raw_sensors_at_least_as_accurate_as_fused_odometry():
    case = compare_case(seed=0, duration=120.0)
    raw, fused = case.rel_error('raw'), case.rel_error('fused')
    assert np.mean(raw) <= np.mean(fused), (raw, fused)
    assert np.count_nonzero(np.abs(case.z('raw')) <= 3.0) >= 4
    mis, sd = case.raw_errors['dvl_misalignment']
    assert abs(mis - case.true_errors['dvl_misalignment']) <= 3.0 * sd
    for k, b in zip(('gyro_bias_p', 'gyro_bias_q', 'gyro_bias_r'),
                    case.true_errors['gyro_bias']):
        assert abs(case.raw_errors[k][0] - b) <= 3.0 * case.raw_errors[k][1]
    # no good message rejected (every generated record is one): all fused or taken, but the
    # sensor records stamped before the filter can start
    assert case.raw_skipped == ({'waiting': case.before_start} if case.before_start else {})
    assert sum(case.raw_fused.values()) + case.before_start == sum(case.records.values())
    assert case.records['dvl'] > 0 and case.records['pressure'] > 0
    s = summary([case])
    assert set(s['coefficients']) == set(case.names)
