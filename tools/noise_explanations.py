"""Which explanation of innovations far above their predicted level gives honest error bars:
the measurement noise alone, or the process noise matched to them (core/identification/
noise_fit.py, the process-noise decision)?

NPS AUV II, 'ident' manoeuvre, 60 s at 20 Hz, the vehicle file's values as the truth, made
either with AR(1) measurement noise at 10x the documented 1-sigma (tau 1 s; 'ar') or with white
acceleration noise of 0.01 on every nu_dot and the documented white measurement noise ('pn').
Per seed and kind: the configured pass's largest innovation level, that of the pass with the
measurement noise alone (noise_fit.noise_only_levels), and |error|/sigma of the EKF pass with
each explanation: the measurement noise model read off the configured pass (what is used when
the process noise is not matched), and the matched process noise with the measurement noise
model read off its pass (what is used when it is).

    PYTHONPATH=. .venv/bin/python tools/noise_explanations.py [--seeds 2,3] [--kinds ar,pn]
"""
import argparse
from dataclasses import replace
from pathlib import Path
import sys

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from auv_ident.analysis.results import make_config  # noqa: E402
from auv_ident.core.identification import noise_fit as nf  # noqa: E402
from auv_ident.core.identification.results import Record  # noqa: E402
from auv_ident.core.identification.uncertainty import noise_model  # noqa: E402
from auv_ident.core.model.hydrodynamics import Model  # noqa: E402
from auv_ident.core.model.sensors import ar1_noise, DEFAULT_NOISE_STD  # noqa: E402
from auv_ident.core.model.state import STATE_NAMES  # noqa: E402
from auv_ident.core.simulation.simulate import simulate  # noqa: E402
from auv_ident.vehicles import load_vehicle  # noqa: E402


def _record(v, kind, seed):
    if kind == 'ar':
        run = simulate(Model(v), 'ident', duration=60.0, seed=seed, noise_std=np.zeros(12))
        y = run.y + ar1_noise(np.random.default_rng([seed, 1]), len(run.t),
                              10 * DEFAULT_NOISE_STD, 1.0, run.T)
    else:
        run = simulate(Model(v), 'ident', duration=60.0, seed=seed,
                       process_std=np.full(6, 0.01))
        y = run.y
    return Record(run.t, y, run.u), run.T


def _with_model(m, cfg, rec, T, fp, q):
    """The EKF pass with the measurement noise model read off fp and process noise q."""
    meas = np.asarray(cfg.measured, dtype=bool)
    nm = nf._informative(noise_model(nf._pooled(fp), T, STATE_NAMES))
    eff = nf.effective_std(cfg.noise_std, nm, meas)
    return nf._pass(m, replace(cfg, noise_std=eff, q_state=q), [rec], T, None, 0.25, 0)


def case(kind, seed):
    v = load_vehicle('nps_auv2')
    names = list(v.identify_default)
    m = Model(v, names)
    rec, T = _record(v, kind, seed)
    cfg = make_config(names)
    meas = np.asarray(cfg.measured, dtype=bool)
    first = nf._pass(m, cfg, [rec], T, None, 0.25, 0)
    levels = nf._levels(nf._pooled(first), meas)
    alone = nf.noise_only_levels(m, cfg, [rec], T, levels)
    matched = nf.match_process_noise(m, cfg, [rec], T, first)
    truth = m.theta_file[:m.p_coef]
    z = {}
    for tag, fp in (('noise model', _with_model(m, cfg, rec, T, first, cfg.q_state)),
                    ('matched', _with_model(m, cfg, rec, T, matched.last, matched.q_state))):
        sd = np.sqrt(np.diag(fp.theta_cov))[:m.p_coef]
        z[tag] = float(np.max(np.abs(fp.theta[:m.p_coef] - truth) / sd))
    return (float(np.nanmax(levels)), None if alone is None else float(np.nanmax(alone)),
            z['noise model'], z['matched'])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', default='2,3')
    ap.add_argument('--kinds', default='ar,pn')
    a = ap.parse_args(argv)
    print('kind seed  max level  alone  max |err|/sigma: noise model  matched')
    for kind in a.kinds.split(','):
        for seed in (int(s) for s in a.seeds.split(',')):
            lv, alone, zn, zm = case(kind, seed)
            shown = '-' if alone is None else f'{alone:.2f}'
            print(f'{kind:4s} {seed:4d} {lv:10.3g} {shown:>6} {zn:28.2f} {zm:8.2f}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
