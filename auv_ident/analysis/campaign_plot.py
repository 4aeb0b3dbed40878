"""trends.png of a campaign: each coefficient with its 1-sigma against the start time of the
bag it came from, one line per vehicle (how each vehicle's coefficients drift)."""
import datetime
import math

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402 - after the backend is chosen


def _start(text):
    return datetime.datetime.fromisoformat(text.replace('Z', '+00:00'))


def trend_series(rows):
    """{coefficient: {vehicle: [(start datetime, estimate, 1-sigma), ...] by time}} of the
    'ok' rows of campaign.csv (dicts of strings)."""
    series = {}
    for r in rows:
        if r.get('status') != 'ok' or not r.get('start_time'):
            continue
        for name, value in r.items():
            std = r.get(name + '_std', '')
            if name.endswith('_std') or value in ('', None) or std in ('', None):
                continue
            series.setdefault(name, {}).setdefault(r.get('vehicle') or '?', []).append(
                (_start(r['start_time']), float(value), float(std)))
    for per_vehicle in series.values():
        for points in per_vehicle.values():
            points.sort()
    return series


def plot_trends(rows, path):
    """Write the figure to `path` (PNG); with no 'ok' row, a figure that says so."""
    series = trend_series(rows)
    n = max(1, len(series))
    cols = 2 if n > 1 else 1
    nrows = math.ceil(n / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(6 * cols, 2.6 * nrows), squeeze=False,
                             sharex=True)
    flat = axes.ravel()
    if not series:
        flat[0].text(0.5, 0.5, 'no bag identified', ha='center', va='center')
    for ax, (name, per_vehicle) in zip(flat, sorted(series.items())):
        for vehicle, points in sorted(per_vehicle.items()):
            t, est, std = zip(*points)
            ax.errorbar(t, est, yerr=std, marker='o', ms=3, capsize=2, label=vehicle)
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
    for ax in flat[len(series):] if series else ():
        ax.set_visible(False)
    if series:
        flat[0].legend(loc='best', fontsize='small', title='vehicle')
    fig.suptitle('identified coefficients (1-sigma bars) against the bag start time (UTC)')
    fig.autofmt_xdate()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
