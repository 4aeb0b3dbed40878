"""What a bag replay keeps per odometry sample is compact float arrays (session/record.py Rows,
UpdateLog), not a tuple and small arrays per message: ``identify --bag`` on an hour of data
must not grow by kilobytes a sample (docs/reliability.md, bounded memory)."""
import tracemalloc

from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.replay import replay_bag
from auv_ident.offline.sim_bag import write_run_bag
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

# bytes per sample (tracemalloc) at the replay's peak and kept in its result; measured 1122 and
# 527 (the tuples and small arrays before: 2081 and 907). Kept: [t, u7], [t, y12], the R
# diagonal while replaying, the ReplayResult's paired arrays (t, Y, U, t_cmd, U_cmd: 28 values)
# and its updates (stamp, estimate and std of 7 parameters: 15 values), 8 bytes each
MAX_PEAK_PER_SAMPLE = 1500
MAX_KEPT_PER_SAMPLE = 700


def test_replay_keeps_compact_arrays_per_sample(tmp_path):
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=150.0, T=0.05, seed=2)
    path = tmp_path / 'run'
    write_run_bag(run, path)
    # the live noise learning keeps a record of its own, bounded (noise_learning.KEEP_LIMIT)
    settings = IdentifierSettings.from_values(learn_noise=False)
    replay_bag(path, settings)          # compiled, imported, cached
    tracemalloc.start()
    try:
        rr = replay_bag(path, settings)
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    n = len(run.t)
    assert rr.accepted == n and len(rr.updates) == n
    stamps = [u[0] for u in rr.updates]
    assert all(isinstance(s, int) for s in stamps) and stamps == sorted(stamps)
    assert rr.updates[-1][1].shape == rr.estimate.shape
    assert peak / n < MAX_PEAK_PER_SAMPLE, peak / n
    assert kept / n < MAX_KEPT_PER_SAMPLE, kept / n
