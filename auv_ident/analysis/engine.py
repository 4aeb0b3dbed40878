"""The distributed engine under `campaign` and `montecarlo`: many independent identifications
as tasks on a Dask cluster (docs/campaigns.md).

Why Dask: one identification takes seconds; a fleet's archive or a Monte Carlo campaign is
hundreds of them, and outgrows one machine. ``distributed`` runs the same tasks on a local
cluster (worker processes on loopback, the default) or on any existing cluster by its
scheduler's address, retries a task whose worker died, and needs no shared file system for
what we send (only bags are read by path: a shared or object-store path is the user's).

What a worker needs travels with the task or with the cluster registration:

- the vehicle file's content (:class:`VehicleText`), never its path: the worker writes it to
  a file of its own, named after the content's digest;
- the compiled numba kernels: :class:`WarmUp`, a worker plugin, runs one short
  identification on every worker (those that join later, e.g. a restarted one, too) before
  its first task, so that a worker compiles (or loads from its own numba cache) once, and no
  task's wall time carries the compilation;
- a local cluster speaks TLS with throw-away credentials (:func:`local_cluster`): its
  scheduler listens on loopback, where any local user could otherwise connect and run code in
  the workers;
- ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST in the environment of the workers it starts (the
  identification creates no ROS node, but nothing spawned here may leave loopback if it did);
- AUV_IDENT_THREADS in the same environment: the usable CPUs shared out among the local
  workers (:func:`difference_threads_env`), as each identification runs its finite
  differences on that many threads (core/identification/batch.py).
"""
import asyncio
import contextlib
from dataclasses import dataclass
import hashlib
import logging
import os
import time

from distributed import as_completed, Client, get_worker, LocalCluster
from distributed.diagnostics.plugin import WorkerPlugin

from auv_ident.core.errors import AuvIdentError, ConfigError
from auv_ident.core.identification.batch import difference_threads
from auv_ident.core.safe_files import ensure_content, private_dir
from auv_ident.vehicles import resolve_vehicle_path

WORKER_ENV = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
LOOPBACK = '127.0.0.1'
CONNECT_TIMEOUT_S = 10.0     # s to reach an existing scheduler (connection refused: retried)
WORKER_WAIT_S = 120.0        # s for the first worker to join an existing scheduler


class EngineError(AuvIdentError):
    """The Dask cluster cannot be reached or has no worker (names the address)."""


@dataclass(frozen=True)
class VehicleText:
    """A vehicle file's content, sent to the workers instead of a path they may not have.

    name : the file's name without '.yaml' (the vehicle's name when the file sets none)
    text : the YAML text
    """

    name: str
    text: str

    @classmethod
    def read(cls, name_or_path):
        """The content of a vehicle given by name (config/) or path, read on the client."""
        path = resolve_vehicle_path(name_or_path)
        with open(path, encoding='utf-8') as fh:
            return cls(os.path.splitext(os.path.basename(path))[0], fh.read())

    @property
    def digest(self):
        """The first 16 hex digits of the text's sha256: names what depends on the content."""
        return hashlib.sha256(self.text.encode()).hexdigest()[:16]

    def local_path(self):
        """Path of this content on the machine that calls it: in the user's private cache
        (core/safe_files.py: 0700, checked, never a guessable shared /tmp folder), in a folder
        named after the digest; written atomically, and again whenever what is there is not
        this content (a file changed behind our back is never used as is)."""
        return str(ensure_content(private_dir('vehicles', self.digest) / f'{self.name}.yaml',
                                  self.text))


class WarmUp(WorkerPlugin):
    """Run `func(*args)` once on every worker before its first task: the compilation of the
    numba kernels (tens of seconds cold, about a second from numba's on-disk cache) then
    happens once per worker process, not in a task. It runs in a thread, so the worker keeps
    answering the scheduler meanwhile. A failure is kept (`error`), not raised: the tasks then
    meet the same problem and report it on their rows. A cluster runs a plugin of a given
    `name` once per worker (idempotent): name it after what it warms up."""

    idempotent = True

    def __init__(self, func, args, name):
        self.func = func
        self.args = tuple(args)
        self.name = name
        self.seconds = None      # wall time of the warm-up on this worker, s
        self.error = None

    async def setup(self, worker):
        t0 = time.perf_counter()
        try:
            await asyncio.get_running_loop().run_in_executor(None, self.func, *self.args)
        except Exception as err:  # noqa: BLE001 - reported by the tasks themselves
            self.error = f'{type(err).__name__}: {err}'
        self.seconds = time.perf_counter() - t0


def warm_up_times(client, name):
    """{worker address: seconds its warm-up took} (None: not run there)."""
    def read(dask_worker):
        plugin = dask_worker.plugins.get(name)
        return None if plugin is None else plugin.seconds
    return client.run(read)


def worker_address():
    """The address of the Dask worker running the caller ('' outside a worker: in-process)."""
    try:
        return get_worker().address
    except ValueError:
        return ''


def difference_threads_env(workers):
    """AUV_IDENT_THREADS for each of `workers` local workers: the usable CPUs shared out
    (at least 1), so that the threaded finite differences of core/identification/batch.py do not
    put more
    threads on the machine than it has cores; {} when the user set AUV_IDENT_THREADS."""
    if os.environ.get('AUV_IDENT_THREADS', '').strip():
        return {}
    return {'AUV_IDENT_THREADS': str(max(1, difference_threads() // max(1, workers)))}


def local_cluster(workers, silence_logs=logging.ERROR, env=None, secure=True):
    """A distributed.LocalCluster of `workers` single-threaded worker processes, everything on
    127.0.0.1, no dashboard. The scheduler still serves its small HTTP API (health, metrics):
    on a free loopback port, not on 8787, which another cluster may hold. env : more
    environment variables for the workers (tools/campaign_bench.py: empty compile caches).

    Security: every connection is TLS with a key and self-signed certificate made for this
    cluster and held in memory only (distributed's Security.temporary; needs `cryptography`).
    Loopback keeps the network out but not the machine's other users: without this, anyone on
    the machine could connect to the scheduler's port and run code in the workers. A client
    connects with the cluster object (``Client(cluster)``), which carries the credentials.
    secure=False: plain TCP, as an existing cluster reached by its address (`--scheduler`) may
    be; the tests use it to stand in for one.

    Scratch folders: the scheduler, the nannies and the workers each put their scratch folder
    first on their sys.path (distributed's ServerNode, for uploaded files), and by default that
    folder is <temp>/dask-scratch-space, a name anyone on the machine can create first (distributed
    uses it as found when it is writable): a module planted there would be imported in place of
    the one asked for, in the workers and in this process. So they live in the user's private
    folder 'dask' (core/safe_files.py: 0700, checked)."""
    scratch = str(private_dir('dask'))
    return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                        host=LOOPBACK, dashboard_address=None, security=True if secure else None,
                        env=dict(WORKER_ENV, **difference_threads_env(workers), **(env or {})),
                        silence_logs=silence_logs, local_directory=scratch,
                        scheduler_kwargs={'dashboard_address': f'{LOOPBACK}:0',
                                          'local_directory': scratch})


@contextlib.contextmanager
def dask_client(scheduler=None, workers=2, env=None):
    """A distributed.Client: on the existing cluster at `scheduler` (an address such as
    tcp://host:8786, or a scheduler file written by `dask scheduler --scheduler-file`), else on
    a LocalCluster of `workers` single-threaded worker processes on 127.0.0.1 with no
    dashboard (env: more environment variables for its workers). Closed (and the local
    cluster shut down) on the way out."""
    cluster = None
    if scheduler:
        where = ({'scheduler_file': scheduler} if os.path.isfile(scheduler)
                 else {'address': scheduler})
        try:
            client = Client(**where, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as err:
            raise EngineError(f'cannot reach the Dask scheduler {scheduler!r}: '
                              f'{str(err).splitlines()[0] if str(err) else type(err).__name__}'
                              ) from None
        try:
            client.wait_for_workers(1, timeout=WORKER_WAIT_S)
        except TimeoutError:
            client.close()
            raise EngineError(f'no Dask worker joined the scheduler {scheduler!r} within '
                              f'{WORKER_WAIT_S:.0f} s (start one: dask worker {scheduler})'
                              ) from None
    else:
        if workers < 1:
            raise ConfigError(f'--workers {workers}: need at least 1 worker process')
        cluster = local_cluster(workers, env=env)
        client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_tasks(client, func, items, retries=1):
    """Run func(item) for every item; yield (index of the item, outcome) as they finish,
    outcome being func's return value, or the exception the task ended with (a worker that
    died three times running it: distributed's KilledWorker). A task whose worker dies is
    run again elsewhere by the scheduler; `retries` more attempts are allowed for a task that
    raises. client None: the items one after the other in this process (the serial
    reference, in order)."""
    if client is None:
        for i, item in enumerate(items):
            try:
                yield i, func(item)
            except Exception as err:  # noqa: BLE001 - the same outcome as on a worker
                yield i, err
        return
    futures = client.map(func, list(items), pure=False, retries=retries)
    index = {f.key: i for i, f in enumerate(futures)}
    for fut in as_completed(futures):
        try:
            outcome = fut.result()
        except Exception as err:  # noqa: BLE001 - the caller makes a row of it
            outcome = err
        yield index[fut.key], outcome
        fut.release()


def one_line(err):
    """The error of a task as one line: the message of our own errors (they name the
    culprit), 'Type: message' for anything else."""
    text = str(err).strip().splitlines()
    text = text[0] if text else ''
    if isinstance(err, (AuvIdentError, OSError)) and text:
        return text
    return f'{type(err).__name__}: {text}' if text else type(err).__name__
