"""`campaign`: identify every bag of a folder (a fleet's archive) on the Dask engine, one task
per bag, into one table (campaign.csv) and a plot of each coefficient over time (trends.png).

A bag that cannot be identified is a row with its one-line error, never the end of the
campaign. The table is rewritten (atomically) every TABLE_EVERY_S while bags finish and when
the campaign ends or is interrupted, so an interrupted campaign keeps what it finished, and a
run with the same output folder skips the bags already 'ok' (bags that failed are tried
again: one may have been repaired meanwhile). A row is trusted only for the bag and the settings
it was made from: each row records the bag's content key (its files' names, sizes and
modification times) and the campaign's settings key (vehicle file content, coefficients,
refinement); a bag edited or replaced since, or a run with other settings, is identified again
(rows of a table without the keys are too). Why CSV and no
Parquet: a campaign table is one row per bag, thousands of rows at most; CSV is read by
everything the operators use, and pyarrow (a wheel of tens of MB) would weigh on every
install for nothing measurable at that size.
"""
import csv
import datetime
import glob
import hashlib
import io
import json
import os
import tempfile
import time

from auv_ident.analysis import engine
from auv_ident.analysis.bag_identify import identify_bag
from auv_ident.analysis.campaign_plot import plot_trends
from auv_ident.bags.info import bag_info
from auv_ident.core.errors import ConfigError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.safe_files import write_atomic
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.sim_bag import write_run_bag
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

CSV_NAME = 'campaign.csv'
TRENDS_NAME = 'trends.png'
HEAD_COLUMNS = ('bag', 'status', 'worker', 'wall_s', 'start_time', 'duration_s', 'vehicle')
TAIL_COLUMNS = ('consistent', 'error', 'bag_key', 'settings_key')
WARM_UP_DURATION_S = 20.0    # s of the simulated bag each worker identifies before its tasks
# s between rewrites of campaign.csv during a campaign: a rewrite after every bag would cost
# O(bags^2) rows written on a large archive; a crash loses at most this much of finished work
TABLE_EVERY_S = 2.0


def find_bags(where):
    """Bags under a folder (searched recursively: a folder with metadata.yaml is a bag, and so
    is a .mcap file outside such a folder) or matching a glob pattern; absolute paths, sorted.
    Raises ConfigError naming `where` when there is none."""
    if os.path.isdir(where):
        found = []
        for folder, subdirs, files in os.walk(where):
            if 'metadata.yaml' in files:
                found.append(folder)
                subdirs[:] = []          # a bag's files are not bags of their own
                continue
            subdirs.sort()
            found += [os.path.join(folder, f) for f in files if f.endswith('.mcap')]
    else:
        found = [p for p in glob.glob(where, recursive=True)
                 if (os.path.isdir(p) and os.path.isfile(os.path.join(p, 'metadata.yaml')))
                 or p.endswith('.mcap')]
    if not found:
        raise ConfigError(f'--bags {where}: no bag there (a folder with metadata.yaml, or a '
                          '.mcap file)')
    return sorted(os.path.abspath(p) for p in found)


def _iso_utc(ns):
    return (datetime.datetime.fromtimestamp(ns / 1e9, tz=datetime.timezone.utc)
            .isoformat(timespec='milliseconds').replace('+00:00', 'Z'))


def identify_bag_row(job):
    """One task: identify one bag; a row of campaign.csv (dict). Runs on a worker.

    job : dict with 'bag' (path), 'vehicle' (VehicleText or None: the bag's metadata says),
    'coefficients' (comma-separated, '' = the vehicle's default), 'refine' (bool)."""
    t0 = time.perf_counter()
    row = {'bag': job['bag'], 'worker': engine.worker_address()}
    try:
        info = bag_info(job['bag'])
        if info.start_ns is not None:
            row['start_time'] = _iso_utc(info.start_ns)
            row['duration_s'] = round(info.duration_ns / 1e9, 3)
        vehicle = job['vehicle'].local_path() if job['vehicle'] is not None else None
        doc, _ = identify_bag(job['bag'], IdentifierSettings.from_values(
            vehicle=vehicle, coefficients=job['coefficients']), refine_pass=job['refine'])
    except Exception as err:  # noqa: BLE001 - any failure is this bag's row, not the end
        row.update(status='error', error=engine.one_line(err))
    else:
        row.update(status='ok', vehicle=doc['vehicle'], error='',
                   consistent=bool(doc['diagnosis']['consistent']))
        for name, c in doc['coefficients'].items():
            row[name] = c['estimate']
            row[name + '_std'] = c['std']
    row['wall_s'] = round(time.perf_counter() - t0, 3)
    return row


def warm_up_bag(vehicle, coefficients, refine):
    """What each worker runs before its first task (engine.WarmUp): identify a short bag of
    the vehicle (VehicleText; None: NPS AUV II) simulated on the worker, through the very path
    of the tasks."""
    path = vehicle.local_path() if vehicle is not None else 'nps_auv2'
    with tempfile.TemporaryDirectory(prefix='auv_ident_warm_') as tmp:
        run = simulate(Model(load_vehicle(path)), 'ident', duration=WARM_UP_DURATION_S, seed=0)
        bag = write_run_bag(run, os.path.join(tmp, 'bag'))
        identify_bag(bag, IdentifierSettings.from_values(vehicle=path, coefficients=coefficients),
                     refine_pass=refine)


def warm_up_plugin(vehicle, coefficients, refine):
    """The engine.WarmUp of a campaign: named after the vehicle file's content, so that a
    cluster that already warmed up for it (an earlier campaign) is not asked again."""
    name = ('auv_ident-warm-up-campaign-'
            + (f'{vehicle.name}-{vehicle.digest}' if vehicle else 'bag-metadata'))
    return engine.WarmUp(warm_up_bag, (vehicle, coefficients, refine), name=name)


def _digest(value):
    """First 16 hex digits of the sha256 of value's JSON."""
    return hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()[:16]


def bag_key(bag):
    """What a resumed row is trusted for: the bag's files (a folder's, recursively; or the
    .mcap file) by relative name, size and modification time in ns. Cheap on archives of
    many GB (nothing is read), and any rewrite, repair or copy over the bag changes it."""
    if os.path.isdir(bag):
        files = sorted(os.path.join(folder, f) for folder, _, names in os.walk(bag)
                       for f in names)
    else:
        files = [bag]
    stats = []
    for f in files:
        st = os.stat(f)
        stats.append([os.path.relpath(f, bag) if f != bag else '', st.st_size, st.st_mtime_ns])
    return _digest(stats)


def settings_key(vehicle, coefficients, refine):
    """The campaign settings a row was computed with (vehicle: VehicleText or None, the bag's
    metadata names it) as a digest."""
    return _digest([vehicle.digest if vehicle is not None else 'bag metadata',
                    str(coefficients), bool(refine)])


def read_table(path):
    """Rows (dicts of strings) of an existing campaign.csv, [] if there is none. ConfigError
    naming the file when it is not a campaign table (not UTF-8 text, not CSV, no 'bag'
    column, a row with more fields than the header)."""
    if not os.path.isfile(path):
        return []
    try:
        with open(path, newline='', encoding='utf-8') as fh:
            reader = csv.DictReader(fh)
            rows = list(reader)
            columns = reader.fieldnames or []
    except (UnicodeDecodeError, csv.Error) as err:
        raise ConfigError(f'{path}: not a campaign table ({err}); move it away or choose '
                          'another --out') from None
    if 'bag' not in columns or 'status' not in columns:
        raise ConfigError(f"{path}: not a campaign table (no 'bag' and 'status' columns); "
                          'move it away or choose another --out')
    for i, row in enumerate(rows):
        if None in row:
            raise ConfigError(f'{path}: not a campaign table (row {i + 2} has more fields '
                              'than the header); move it away or choose another --out')
    return rows


def write_table(path, rows):
    """Write campaign.csv atomically: the columns of HEAD_COLUMNS, every coefficient of any
    row with its _std after it, then TAIL_COLUMNS; rows sorted by bag."""
    coefs = []
    for r in rows:
        for k in r:
            if k not in HEAD_COLUMNS and k not in TAIL_COLUMNS and not k.endswith('_std') \
                    and k not in coefs:
                coefs.append(k)
    columns = list(HEAD_COLUMNS) + [c for n in coefs for c in (n, n + '_std')] \
        + list(TAIL_COLUMNS)
    text = io.StringIO(newline='')
    w = csv.DictWriter(text, columns, restval='')
    w.writeheader()
    for r in sorted(rows, key=lambda r: r['bag']):
        w.writerow(r)
    write_atomic(path, text.getvalue())


def run_campaign(bags, out, vehicle=None, coefficients='', refine=True, scheduler=None,
                 workers=2, progress_bar=None, warm_up=True, worker_env=None):
    """Identify every bag of `bags` (folder or glob, see find_bags) on the engine; write
    OUT/campaign.csv (every TABLE_EVERY_S s, and at the end) and OUT/trends.png. Bags with an
    'ok' row in an existing OUT/campaign.csv are skipped.

    vehicle : name or path of a vehicle file (its content goes to the workers), or None: the
    vehicle each bag's metadata names. progress_bar : progress_bar(number of bags to
    identify) returns a callable, called once per bag done. warm_up : compile on each worker
    before its first task (engine.WarmUp). worker_env : more environment variables for the
    workers of a local cluster.

    Returns a summary dict: bags, skipped, ok, error, workers, csv, trends, and the times in s:
    wall_s (all), start_s (cluster up and warmed up), tasks_s (first task submitted to last
    row written), warm_up_s ({worker address: s}, {} without warm-up)."""
    t0 = time.perf_counter()
    all_bags = find_bags(bags)
    os.makedirs(out, exist_ok=True)
    csv_path = os.path.join(out, CSV_NAME)
    vtext = engine.VehicleText.read(vehicle) if vehicle else None
    keys = {b: bag_key(b) for b in all_bags}
    settings = settings_key(vtext, coefficients, refine)
    rows = {r['bag']: r for r in read_table(csv_path)}
    done = {b for b, r in rows.items() if r.get('status') == 'ok' and b in keys
            and r.get('bag_key') == keys[b] and r.get('settings_key') == settings}
    todo = [b for b in all_bags if b not in done]
    for b in todo:                  # an old row of a bag to redo must not outlive an abort
        rows.pop(b, None)
    jobs = [{'bag': b, 'vehicle': vtext, 'coefficients': coefficients, 'refine': refine}
            for b in todo]
    used_workers, start_s, tasks_s, warm_up_s = 0, 0.0, 0.0, {}
    progress = progress_bar(len(jobs)) if progress_bar and jobs else None
    if jobs:
        with engine.dask_client(scheduler, workers, env=worker_env) as client:
            used_workers = len(client.scheduler_info()['workers'])
            if warm_up:
                plugin = warm_up_plugin(vtext, coefficients, refine)
                client.register_plugin(plugin)
                warm_up_s = engine.warm_up_times(client, plugin.name)
            start_s = time.perf_counter() - t0
            written = time.monotonic()
            try:
                for i, outcome in engine.run_tasks(client, identify_bag_row, jobs):
                    if isinstance(outcome, Exception):     # the task itself was lost
                        outcome = {'bag': jobs[i]['bag'], 'status': 'error',
                                   'error': engine.one_line(outcome)}
                    outcome.update(bag_key=keys[outcome['bag']], settings_key=settings)
                    rows[outcome['bag']] = outcome
                    if time.monotonic() - written > TABLE_EVERY_S:
                        write_table(csv_path, list(rows.values()))
                        written = time.monotonic()
                    if progress:
                        progress()
            finally:                 # interrupted too: what finished is kept
                write_table(csv_path, list(rows.values()))
            tasks_s = time.perf_counter() - t0 - start_s
    write_table(csv_path, list(rows.values()))
    trends = os.path.join(out, TRENDS_NAME)
    plot_trends(read_table(csv_path), trends)
    new = [rows[b] for b in todo]
    return {'bags': len(all_bags), 'skipped': len(all_bags) - len(todo),
            'ok': sum(r['status'] == 'ok' for r in new),
            'error': sum(r['status'] == 'error' for r in new), 'workers': used_workers,
            'wall_s': time.perf_counter() - t0, 'start_s': start_s, 'tasks_s': tasks_s,
            'warm_up_s': warm_up_s, 'csv': csv_path, 'trends': trends}
