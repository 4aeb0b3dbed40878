"""The Dask engine under `campaign` and `montecarlo`, on a real distributed.LocalCluster (worker
processes, TCP on 127.0.0.1, no dashboard): the rows of good and corrupt bags, a worker killed
mid-campaign, resuming, Monte Carlo equal to the serial loop; and (slow) a campaign on a real
`dask scheduler` + `dask worker` started from the venv, through the command line."""
import csv
import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

from distributed import Client
import numpy as np
import pytest

from auv_ident.analysis import engine
from auv_ident.analysis.bag_identify import identify_bag
from auv_ident.analysis.campaign import bag_key, find_bags, run_campaign, settings_key
from auv_ident.analysis.experiments import identify_simulated, montecarlo
from auv_ident.analysis.results import make_config
from auv_ident.core.errors import ConfigError
from auv_ident.core.model.hydrodynamics import Model
from auv_ident.core.simulation.simulate import simulate
from auv_ident.offline.sim_bag import SIM_EPOCH_NS, write_run_bag
from auv_ident.session.settings import IdentifierSettings
from auv_ident.vehicles import load_vehicle

DAY_NS = 86_400 * 1_000_000_000
BAG_S = 30.0                  # s of each test bag: an identification of well under a second
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _bag(path, seed, day):
    run = simulate(Model(load_vehicle('nps_auv2')), 'ident', duration=BAG_S, seed=seed)
    return write_run_bag(run, str(path), epoch_ns=SIM_EPOCH_NS + day * DAY_NS)


@pytest.fixture(scope='module')
def archive(tmp_path_factory):
    """A fleet archive: three good bags on three days, in nested folders, and two corrupt
    ones (garbage named .mcap; a bag folder whose MCAP file is cut short)."""
    root = tmp_path_factory.mktemp('archive')
    good = [_bag(root / 'auv1' / f'mission{k}', seed=k, day=k) for k in range(3)]
    (root / 'garbage.mcap').write_bytes(b'this is not an MCAP file\n' * 40)
    cut = root / 'auv1' / 'cut'
    shutil.copytree(good[0], cut)
    mcap = next(cut.glob('*.mcap'))
    mcap.write_bytes(mcap.read_bytes()[:3000])
    return root, [os.path.abspath(g) for g in good], [str(root / 'garbage.mcap'), str(cut)]


@pytest.fixture(scope='module')
def cluster():
    # stands in for an existing cluster reached by its address (--scheduler): plain TCP, as a
    # user's own cluster may be; the campaign's own local cluster is TLS (test below)
    with engine.local_cluster(2, secure=False) as c:
        yield c


def test_the_local_cluster_runs_no_code_for_another_local_process():
    """A process on the machine that knows the scheduler's port cannot run code in the workers,
    with no credentials, over plain TCP or with self-made ones; with the cluster's own
    credentials it can (so the check can fail)."""
    from distributed.security import Security

    def runs_code(address, security):
        try:
            outsider = Client(address, timeout=5, security=security)
        except Exception:       # noqa: BLE001 - refused, whatever distributed raises
            return False
        try:
            return bool(outsider.run(lambda: 'ran'))
        except Exception:       # noqa: BLE001
            return False
        finally:
            outsider.close()

    with engine.local_cluster(1) as lc:
        address = lc.scheduler_address
        assert address.startswith('tls://127.0.0.1:')
        assert runs_code(address, lc.security)
        assert not runs_code(address, None)
        assert not runs_code(address.replace('tls://', 'tcp://'), None)
        assert not runs_code(address, Security.temporary())


def _rows(out):
    with open(os.path.join(out, 'campaign.csv'), newline='', encoding='utf-8') as fh:
        return {r['bag']: r for r in csv.DictReader(fh)}


def test_find_bags_walks_folders_and_globs(archive):
    root, good, bad = archive
    assert find_bags(str(root)) == sorted(good + bad)
    assert find_bags(str(root / 'auv1' / 'mission*')) == good
    with pytest.raises(ConfigError, match='no bag there'):
        find_bags(str(root / 'nothing*'))


def test_good_and_corrupt_bags_give_their_rows(archive, cluster, tmp_path):
    root, good, bad = archive
    out = tmp_path / 'out'
    summary = run_campaign(str(root), str(out), vehicle='nps_auv2',
                           scheduler=cluster.scheduler_address)
    assert (summary['bags'], summary['ok'], summary['error'], summary['skipped']) == (5, 3, 2, 0)
    rows = _rows(out)
    assert sorted(rows) == sorted(good + bad)
    with Client(cluster.scheduler_address) as client:
        workers = set(client.scheduler_info()['workers'])
    # the same bag, in this process
    doc, _ = identify_bag(good[1], IdentifierSettings.from_values(vehicle='nps_auv2'))
    for k, bag in enumerate(good):
        r = rows[bag]
        assert r['status'] == 'ok' and r['error'] == '' and r['worker'] in workers
        assert r['vehicle'] == 'nps_auv2' and r['consistent'] in ('True', 'False')
        assert float(r['duration_s']) == pytest.approx(BAG_S, abs=0.1)
        assert r['start_time'] == f'2024-01-0{1 + k}T00:00:00.000Z'
        assert float(r['wall_s']) > 0
        for name in doc['coefficients']:
            assert np.isfinite(float(r[name])) and float(r[name + '_std']) > 0
    for name, c in doc['coefficients'].items():      # a worker computes what we compute
        assert float(rows[good[1]][name]) == c['estimate']
        assert float(rows[good[1]][name + '_std']) == c['std']
    for bag in bad:
        r = rows[bag]
        assert r['status'] == 'error' and r['worker'] in workers
        assert os.path.basename(bag) in r['error'] and '\n' not in r['error']
        assert r['Z_w'] == '' and r['consistent'] == ''
    with open(out / 'trends.png', 'rb') as fh:
        assert fh.read(8) == PNG_SIGNATURE


def test_resume_skips_the_bags_already_done(archive, cluster, tmp_path):
    """An 'ok' row of an earlier run stays as it was (its bag is not run again); an 'error' row
    is tried again; a campaign with nothing left to do starts no cluster."""
    root, good, bad = archive
    out = tmp_path / 'out'
    out.mkdir()
    earlier = [{'bag': good[0], 'status': 'ok', 'worker': 'an earlier run', 'wall_s': '1',
                'start_time': '2024-01-01T00:00:00.000Z', 'duration_s': '30', 'vehicle':
                'nps_auv2', 'Z_w': '-0.25', 'Z_w_std': '0.01', 'consistent': 'True', 'error': '',
                'bag_key': bag_key(good[0]), 'settings_key': settings_key(None, '', True)},
               {'bag': good[1], 'status': 'error', 'worker': 'an earlier run', 'error': 'boom'}]
    with open(out / 'campaign.csv', 'w', newline='', encoding='utf-8') as fh:
        w = csv.DictWriter(fh, list(earlier[0]))
        w.writeheader()
        w.writerows(earlier)
    # no --vehicle: the bags' metadata name it
    summary = run_campaign(str(root / 'auv1' / 'mission*'), str(out),
                           scheduler=cluster.scheduler_address)
    assert (summary['bags'], summary['skipped'], summary['ok']) == (3, 1, 2)
    rows = _rows(out)
    assert rows[good[0]]['worker'] == 'an earlier run' and rows[good[0]]['Z_w'] == '-0.25'
    assert rows[good[1]]['status'] == 'ok' and rows[good[1]]['worker'].startswith('tcp://')
    assert rows[good[1]]['vehicle'] == 'nps_auv2' and float(rows[good[1]]['K_v_std']) > 0
    assert rows[good[2]]['status'] == 'ok'
    # all done: a third run identifies nothing and starts no cluster
    again = run_campaign(str(root / 'auv1' / 'mission*'), str(out),
                         scheduler='tcp://127.0.0.1:9')
    assert (again['skipped'], again['ok'], again['error'], again['workers']) == (3, 0, 0, 0)


@pytest.mark.slow
def test_resume_redoes_an_edited_bag_and_changed_settings(archive, cluster, tmp_path):
    """A row is trusted for its bag's content and the campaign's settings only (#27 item 10:
    resume trusted rows by path alone): a bag rewritten since (here: its metadata.yaml edited,
    same path) is identified again, the others kept; other settings (coefficients, vehicle
    file) redo every bag."""
    root, good, _ = archive
    bags = tmp_path / 'bags'
    for g in good[:2]:
        shutil.copytree(g, bags / os.path.basename(g))
    out = tmp_path / 'out'
    fast = dict(scheduler=cluster.scheduler_address, refine=False, warm_up=False)
    first = run_campaign(str(bags), str(out), **fast)
    assert (first['skipped'], first['ok']) == (0, 2)
    before = _rows(out)
    meta = bags / os.path.basename(good[1]) / 'metadata.yaml'
    meta.write_text(meta.read_text(encoding='utf-8') + '\n', encoding='utf-8')
    edited = run_campaign(str(bags), str(out), **fast)
    assert (edited['skipped'], edited['ok']) == (1, 1)
    after = _rows(out)
    kept, redone = (str(bags / os.path.basename(g)) for g in good[:2])
    assert after[kept] == before[kept] and after[redone]['bag_key'] != before[redone]['bag_key']
    other = run_campaign(str(bags), str(out), coefficients='Z_w,M_ds', **fast)
    assert (other['skipped'], other['ok']) == (0, 2)
    assert set(_rows(out)[kept]).issuperset({'Z_w', 'M_ds'}) and not _rows(out)[kept].get('K_v')
    vehicle = run_campaign(str(bags), str(out), coefficients='Z_w,M_ds', vehicle='nps_auv2',
                           **fast)
    assert (vehicle['skipped'], vehicle['ok']) == (0, 2)
    assert settings_key(None, '', True) != settings_key(None, '', False)    # --no-refine


@pytest.mark.parametrize('content, needle', [
    (b'\xff\xfe\x00garbage\x89', 'not a campaign table'),
    (b'name,value\n1,2\n', "no 'bag' and 'status' columns"),
    (b'bag,status\n/x,ok,extra\n', 'row 2 has more fields than the header'),
])
def test_a_corrupt_campaign_table_is_one_clear_error(archive, tmp_path, content, needle):
    """A campaign.csv that is not ours (binary, another table, broken rows): one ConfigError
    naming it, no UnicodeDecodeError (#27 item 6); the CLI prints it on one line, exit 2."""
    root, _, _ = archive
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'campaign.csv').write_bytes(content)
    with pytest.raises(ConfigError, match=needle) as info:
        run_campaign(str(root / 'auv1' / 'mission*'), str(out), scheduler='tcp://127.0.0.1:9')
    assert str(out / 'campaign.csv') in str(info.value)
    proc = subprocess.run([sys.executable, '-m', 'auv_ident', 'campaign', '--bags',
                           str(root / 'auv1' / 'mission*'), '--out', str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=120)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and needle in lines[0], proc.stderr


def test_a_worker_killed_mid_campaign_loses_no_bag(archive, tmp_path):
    """SIGKILL to the worker process running a bag: the scheduler runs that bag again on a
    worker still alive (or the one the nanny restarts); every bag gets its 'ok' row."""
    root, good, _ = archive
    out = tmp_path / 'out'
    with engine.local_cluster(2, secure=False) as lc, Client(lc) as client:
        pids = client.run(os.getpid)
        result = {}
        campaign = threading.Thread(target=lambda: result.update(run_campaign(
            str(root / 'auv1' / 'mission*'), str(out), vehicle='nps_auv2',
            scheduler=lc.scheduler_address)))
        campaign.start()
        killed, lost = None, []
        deadline = time.monotonic() + 120
        while killed is None and campaign.is_alive() and time.monotonic() < deadline:
            busy = {w: keys for w, keys in client.processing().items() if keys}
            if busy:
                killed, lost = next(iter(busy.items()))
                os.kill(pids[killed], signal.SIGKILL)
            time.sleep(0.01)
        campaign.join(300)
    assert killed is not None and lost, 'no bag was seen running'
    assert result['ok'] == 3 and result['error'] == 0
    rows = _rows(out)
    assert sorted(rows) == good and all(r['status'] == 'ok' for r in rows.values())
    assert sum(r['worker'] == killed for r in rows.values()) == 0


def test_montecarlo_on_dask_gives_the_numbers_of_the_serial_loop(cluster):
    kw = dict(seeds=2, offsets=(0.5, -0.5), duration=BAG_S, refine_pass=False)
    serial = montecarlo('nps_auv2', ['Z_w', 'M_ds'], jobs=1, **kw)
    on_dask = montecarlo('nps_auv2', ['Z_w', 'M_ds'], scheduler=cluster.scheduler_address, **kw)
    for st in (serial, on_dask):
        st.pop('wall_s')
        for r in st['runs']:
            r.pop('wall_s')
    assert on_dask == serial
    assert serial['cases'] == 4 and serial['diverged'] == 0
    # and a case is what identify_simulated gives with the vehicle by name (no engine at all)
    cfg = make_config(['Z_w', 'M_ds'], initial_offset=-0.5)
    res = identify_simulated('nps_auv2', ['Z_w', 'M_ds'], cfg, seed=1, duration=BAG_S,
                             refine_pass=False).result
    run = next(r for r in serial['runs'] if (r['seed'], r['offset']) == (1, -0.5))
    assert run['error_pct'] == res.error_pct().tolist()


def test_vehicle_text_becomes_a_file_of_the_same_content():
    vt = engine.VehicleText.read('nps_auv2')
    path = vt.local_path()
    assert os.path.basename(path) == 'nps_auv2.yaml' and path != load_vehicle('nps_auv2').path
    with open(path, encoding='utf-8') as fh:
        assert fh.read() == vt.text
    assert load_vehicle(path).name == 'nps_auv2'


def test_a_vehicle_file_changed_behind_the_workers_back_is_not_used(tmp_path, monkeypatch):
    """The worker's copy lives in the user's private cache, and a copy whose content is not the
    task's is written again before use (a planted or edited file changed campaign results)."""
    monkeypatch.setenv('AUV_IDENT_CACHE', str(tmp_path / 'cache'))
    vt = engine.VehicleText.read('nps_auv2')
    path = vt.local_path()
    assert path.startswith(str(tmp_path / 'cache' / 'vehicles'))
    with open(path, 'a', encoding='utf-8') as fh:
        fh.write('# planted\n')
    assert vt.local_path() == path
    with open(path, encoding='utf-8') as fh:
        assert fh.read() == vt.text


def test_an_unreachable_scheduler_is_one_clear_error(archive, tmp_path):
    root, good, _ = archive
    proc = subprocess.run(
        [sys.executable, '-m', 'auv_ident', 'campaign', '--bags', good[0], '--out',
         str(tmp_path / 'out'), '--scheduler', 'tcp://127.0.0.1:9'],
        capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 2
    assert proc.stderr.strip().count('\n') == 0
    assert "cannot reach the Dask scheduler 'tcp://127.0.0.1:9'" in proc.stderr


def test_a_folder_without_bags_is_one_clear_error(tmp_path):
    (tmp_path / 'empty').mkdir()
    proc = subprocess.run(
        [sys.executable, '-m', 'auv_ident', 'campaign', '--bags', str(tmp_path / 'empty'),
         '--out', str(tmp_path / 'out')], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 2
    assert proc.stderr == f'error: --bags {tmp_path / "empty"}: no bag there (a folder with ' \
                          'metadata.yaml, or a .mcap file)\n'


def _wait_for_file(path, proc, timeout=60.0):
    deadline = time.monotonic() + timeout
    while not os.path.exists(path):
        assert proc.poll() is None, f'{proc.args[1:3]} exited with {proc.returncode}'
        assert time.monotonic() < deadline, f'no {path} after {timeout} s'
        time.sleep(0.1)


@pytest.mark.slow
def test_campaign_on_a_real_dask_scheduler_and_worker(archive, tmp_path):
    """`dask scheduler` and `dask worker` from the venv, as on a multi-host cluster (here on
    127.0.0.1): `campaign --scheduler FILE` over two good bags and a corrupt one."""
    root, good, bad = archive
    bags = tmp_path / 'bags'
    bags.mkdir()
    for src in good[:2]:
        shutil.copytree(src, bags / os.path.basename(src))
    shutil.copy(bad[0], bags / 'corrupt.mcap')
    dask = os.path.join(os.path.dirname(sys.executable), 'dask')
    sched_file = str(tmp_path / 'scheduler.json')
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               PYTHONPATH=os.pathsep.join(p for p in (REPO, os.environ.get('PYTHONPATH')) if p))
    log = open(tmp_path / 'dask.log', 'w', encoding='utf-8')
    sched = subprocess.Popen([dask, 'scheduler', '--host', '127.0.0.1', '--port', '0',
                              '--no-dashboard', '--dashboard-address', '127.0.0.1:0',
                              '--scheduler-file', sched_file],
                             env=env, stdout=log, stderr=subprocess.STDOUT)
    worker = None
    try:
        _wait_for_file(sched_file, sched)
        worker = subprocess.Popen([dask, 'worker', '--scheduler-file', sched_file,
                                   '--host', '127.0.0.1', '--no-dashboard', '--nworkers', '1',
                                   '--nthreads', '1'],
                                  env=env, stdout=log, stderr=subprocess.STDOUT)
        with open(sched_file, encoding='utf-8') as fh:
            address = json.load(fh)['address']
        with Client(address, timeout=30) as client:
            client.wait_for_workers(1, timeout=60)
            workers = set(client.scheduler_info()['workers'])
        out = tmp_path / 'out'
        proc = subprocess.run([sys.executable, '-m', 'auv_ident', 'campaign', '--bags',
                               str(bags), '--vehicle', 'nps_auv2', '--scheduler', sched_file,
                               '--out', str(out)],
                              env=env, capture_output=True, text=True, timeout=300, cwd=REPO)
        assert proc.returncode == 0, proc.stderr
        assert '2 ok, 1 error, on 1 worker(s)' in proc.stdout
        rows = _rows(out)
        assert len(rows) == 3
        ok = [r for r in rows.values() if r['status'] == 'ok']
        assert len(ok) == 2
        for r in ok:
            assert r['worker'] in workers and r['worker'].startswith('tcp://127.0.0.1:')
            assert np.isfinite(float(r['Z_w'])) and float(r['Z_w_std']) > 0
        err = rows[str(bags / 'corrupt.mcap')]
        assert err['status'] == 'error' and 'corrupt.mcap' in err['error']
    finally:
        for p in (worker, sched):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in (worker, sched):
            if p is not None:
                try:
                    p.wait(30)
                except subprocess.TimeoutExpired:
                    p.kill()
        log.close()


def test_local_workers_share_the_cores_for_the_finite_differences(cluster, monkeypatch):
    """Each of the 2 local workers gets AUV_IDENT_THREADS = usable CPUs // 2 (at least 1): the
    threaded Jacobians of core/identification/batch.py then do not oversubscribe the machine; a
    value the
    user set is left alone."""
    from distributed import Client
    with Client(cluster) as client:
        seen = set(client.run(lambda: os.environ.get('AUV_IDENT_THREADS')).values())
    cpus = len(os.sched_getaffinity(0))
    assert seen == {str(max(1, cpus // 2))}
    monkeypatch.setenv('AUV_IDENT_THREADS', '3')
    assert engine.difference_threads_env(2) == {}


def _planted_module():
    import importlib.util
    spec = importlib.util.find_spec('planted_by_another_user')
    return None if spec is None else spec.origin


def test_a_module_planted_in_the_shared_temp_folder_is_never_importable(tmp_path, monkeypatch):
    """Another local user creates <temp>/dask-scratch-space (open to all) with a module in it
    before the campaign starts: distributed would use that folder as found and put it first on
    the import path of this process and of every worker; the cluster's scratch folders are in
    the user's private cache instead, so the module is found nowhere."""
    shared = tmp_path / 'shared_tmp'
    planted = shared / 'dask-scratch-space'
    planted.mkdir(parents=True)
    os.chmod(shared, 0o1777)
    os.chmod(planted, 0o777)
    (planted / 'planted_by_another_user.py').write_text('RAN = True\n', encoding='utf-8')
    monkeypatch.setattr(tempfile, 'tempdir', str(shared))
    monkeypatch.setenv('AUV_IDENT_CACHE', str(tmp_path / 'cache'))
    with engine.local_cluster(1) as lc, Client(lc) as client:
        assert _planted_module() is None
        assert list(client.run(_planted_module).values()) == [None]
        scratch = client.run(lambda dask_worker: dask_worker.local_directory)
    assert all(pathlib.Path(d).is_relative_to(tmp_path / 'cache' / 'dask')
               for d in scratch.values())
