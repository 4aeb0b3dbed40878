"""The campaigns count the runs the trust verdicts flag (#26): with the correct vehicle file a
NOT plausible run is a false alarm, so montecarlo's table and the noise campaign's summary
say how many there were."""
import importlib.util
from pathlib import Path

from auv_ident.analysis.experiments import montecarlo_table

TOOLS = Path(__file__).resolve().parents[2] / 'tools'


def _stats(runs):
    per = {'Z_w': {'median_abs_error_pct': 1.0, 'max_abs_error_pct': 2.0, 'within_3sigma': 1.0,
                   'ekf_median_abs_error_pct': 1.0, 'ekf_within_3sigma': 1.0}}
    return {'per_coefficient': per, 'diverged': 0, 'cases': len(runs), 'runs': runs,
            'mean_nees': 1.0, 'nees_expected': 1, 'mean_nis_per_dof': 1.0,
            'within_3sigma_all': 1.0, 'median_abs_z': 0.7, 'ekf_median_abs_z': 0.7,
            'ekf_within_3sigma_all': 1.0,
            'consistent': sum(1 for r in runs if r['consistent']),
            'not_plausible': sum(1 for r in runs if not r['plausible'])}


def test_montecarlo_table_counts_not_plausible_and_not_consistent_runs():
    runs = [{'consistent': True, 'plausible': True}, {'consistent': False, 'plausible': False},
            {'consistent': True, 'plausible': False}]
    assert 'NOT plausible in 2 of 3 runs; NOT consistent in 1 of 3' in montecarlo_table(
        _stats(runs))


def test_noise_campaign_summary_counts_the_flagged_runs():
    spec = importlib.util.spec_from_file_location('noise_campaign', TOOLS / 'noise_campaign.py')
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    cases = [{'consistent': True, 'plausible': True}, {'consistent': False, 'plausible': False},
             {'consistent': True, 'plausible': True}]
    assert mod.false_alarm_line(cases) == 'NOT plausible in 1 of 3 runs; NOT consistent in 1 of 3'
