"""Load: a real identifier process takes 200 Hz odometry and actuator commands for two minutes
of simulated time (24001 samples of each) at 6x real time, published from this process
(auv_ident.ros.loadtest, the `python -m auv_ident loadtest` benchmark in a shorter run).

Every message must be processed (the identifier's /diagnostics counts: accepted + rejected =
published, for both topics; nothing rejected, no filter reset), every estimate finite, the
identifier's resident memory flat (growth from 10 % of the samples to the end below 20 MB),
the per-message latency reported, and the estimate file written at the end must hold every
update and warm-start a later session.
"""
import math

import numpy as np
import pytest

from auv_ident.ros.loadtest import format_loadtest, run_loadtest
from auv_ident.session.session import IdentSession
from auv_ident.session.settings import IdentifierSettings

pytestmark = pytest.mark.slow     # a real identifier process for ~40 s

RATE_HZ = 200.0
SIM_SECONDS = 120.0
RTF = 6.0
MAX_RSS_GROWTH_MB = 20.0


def test_identifier_keeps_up_with_200hz_and_memory_stays_flat(ros_env, tmp_path):
    d = run_loadtest(rate_hz=RATE_HZ, sim_seconds=SIM_SECONDS, real_time_factor=RTF,
                     compute_samples=2000, env=ros_env, log_dir=tmp_path)
    report = format_loadtest(d)
    print(report)
    n = int(SIM_SECONDS * RATE_HZ) + 1
    assert d['samples'] == n
    assert d['identifier_exit_code'] == 0, report
    assert d['all_processed'], report
    assert d['accepted'] == n and d['rejected'] == 0, report
    assert d['commands'] == n and d['commands_rejected'] == 0, report
    assert d['filter_resets'] == 0 and d['internal_errors'] == 0, report
    assert d['non_finite_estimates'] == 0
    assert d['estimates_received'] >= 0.9 * n, report       # ~/estimate is depth 1
    assert d['saved_steps'] == n, report
    lat = d['latency_ms']
    assert lat['n'] >= 0.9 * n and math.isfinite(lat['p50']) and math.isfinite(lat['p99'])
    assert lat['p50'] <= lat['p99'] <= lat['max']
    rss = d['rss_mb']
    assert rss['samples'] >= 20, report
    assert abs(rss['growth']) < MAX_RSS_GROWTH_MB and rss['max_growth'] < MAX_RSS_GROWTH_MB, \
        report
    # the estimate file written on shutdown starts a later run
    warm = IdentSession(IdentifierSettings.from_values(warm_start=str(tmp_path / 'estimate.json'),
                                                       sample_time=1 / RATE_HZ))
    est, cov = warm.current()
    assert np.all(np.isfinite(est)) and np.all(np.linalg.eigvalsh(cov) > 0)
