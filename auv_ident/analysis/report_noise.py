"""The report's honesty sections: the diagnosis, the noise model read off the data, the
identifiability of each coefficient, and the innovations' autocorrelation figure.

Everything comes from the result document (core/identification/pipeline.py fills `diagnosis`,
`noise_model` and `identifiability`), so `report` shows what `identify --json` says.
"""
import math

import numpy as np

from auv_ident.analysis.report_format import cell, markdown_table, pyplot, save_figure
from auv_ident.core.model.state import STATE_NAMES, STATE_UNITS

# A white sequence's sample autocorrelation at a lag > 0 lies within +-1.96 / sqrt(n) with
# probability 95 % (Bartlett), the band drawn in the figure
WHITE_BAND_Z = 1.96


def diagnosis_lines(doc):
    """The diagnosis as the report's first lines: the verdict in bold, then every message."""
    d = doc.get('diagnosis')
    if not d:
        return []
    head, rest = d['messages'][0], d['messages'][1:]
    return [f'**{head}**', ''] + [f'- {m}' for m in rest] + ([''] if rest else [])


def noise_model_markdown(doc):
    """Section lines: per channel the innovations' level against the configured noise, the
    AR(1) correlation and time constant, the whiteness test and the 1-sigma used."""
    nm = doc.get('noise_model')
    if not nm:
        return []
    L = ['', '## Noise model from the data', '',
         'Per measured channel, from the innovations of the EKF pass with the configured noise '
         '(core/identification/noise_fit.py): level = RMS of the whitened innovations (1: the '
         'configured '
         'noise holds), lag-1 autocorrelation (AR(1)) and its time constant, the Ljung-Box '
         f'whiteness test over {len(next(iter(nm["channels"].values()), {}).get("acf", [0])) - 1}'
         ' lags, and the 1-sigma the identification used (the configured one, or the effective '
         'one level x sqrt((1 + rho) / (1 - rho)) x configured when the data contradict it). '
         + ('The noise model from the data was used.' if nm['used'] else
            'The configured noise held; it was used as is.')
         + f' Coefficient covariance: {nm["covariance"]}'
         + (f' (Newey-West, {nm["lags"]} lags)' if nm['covariance'] == 'sandwich' else '')
         + '.', '']
    rows = []
    for j, name in enumerate(STATE_NAMES):
        c = nm['channels'].get(name)
        if c is None:
            continue
        tau = c['tau_s']
        rows.append([name, cell(c['level']), cell(c['ar1']),
                     'inf' if tau is None or (isinstance(tau, float) and math.isinf(tau))
                     else cell(tau), cell(c['p_white']), 'yes' if c['white'] else 'no',
                     cell(nm['configured_std'][j]), cell(nm['effective_std'][j]),
                     STATE_UNITS[j]])
    L.append(markdown_table(['measured channel', 'level', 'AR(1)', 'tau (s)', 'p white', 'white',
                             'configured 1-sigma', 'used 1-sigma', 'unit'], rows))
    for note in nm.get('notes') or []:
        L += ['', note]
    return L


def identifiability_markdown(doc):
    """Section lines: per coefficient the 1-sigma the run supports, its largest correlation
    and the verdict, with the advice for the ones that are not identifiable."""
    ident = doc.get('identifiability')
    if not ident:
        return []
    L = ['', '## Identifiability', '',
         'From the sensitivities of the refined residuals (Fisher information; core/'
         'uncertainty.py): identifiable = 1-sigma under 5 % of the value and no correlation '
         'above 0.95 (a water-current component: 1-sigma under 0.05 m/s); weak; not excited '
         '(no information, or 1-sigma above 50 %).', '']
    rows = [[n, cell(d['crb_std']), cell(100.0 * d['rel_std']) if math.isfinite(d['rel_std'])
             else 'inf', cell(d['max_correlation']), d['correlated_with'] or '-', d['verdict'],
             d.get('advice', '')] for n, d in ident.items()]
    L.append(markdown_table(['parameter', '1-sigma', '1-sigma % of value', 'largest correlation',
                             'with', 'verdict', 'what would excite it'], rows))
    return L


def fig_innovation_autocorrelation(path, doc, T):
    """Autocorrelation of each channel's whitened innovations (configured noise) with the
    95 % band of white noise: bars outside it are correlated noise (or model error).
    Returns path, or None when the document has no noise model."""
    nm = doc.get('noise_model')
    if not nm or not nm['channels']:
        return None
    plt = pyplot()
    names = [n for n in STATE_NAMES if n in nm['channels']]
    cols = 4
    rows = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(12, 2.3 * rows), squeeze=False,
                             sharex=True, sharey=True)
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    for ax, name in zip(axes.ravel(), names):
        c = nm['channels'][name]
        acf = np.asarray(c['acf'], dtype=float)
        lags = np.arange(len(acf)) * T
        band = WHITE_BAND_Z / math.sqrt(max(c['samples'], 1))
        ax.vlines(lags[1:], 0.0, acf[1:], color='C0' if c['white'] else 'C3')
        ax.axhspan(-band, band, color='0.85', zorder=0)
        ax.axhline(0.0, color='k', lw=0.6)
        ax.set_title(f'{name}: level {c["level"]:.2g}, AR(1) {c["ar1"]:.2f}', fontsize=9)
        ax.set_ylim(-1.0, 1.0)
    for ax in axes[-1]:
        ax.set_xlabel('lag (s)')
    fig.suptitle('Autocorrelation of the whitened innovations (grey: 95 % band of white '
                 'noise; red: not white by the Ljung-Box test)', fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)
