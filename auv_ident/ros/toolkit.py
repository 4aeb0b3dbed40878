"""The node toolkit: what the four node executables (simulator, identifier, record, play) share.

Entry point
    :func:`run_node` is the one harness of every node's ``main``: ``-h``/``--help`` prints the
    node's docstring (exit 0); a malformed ``--ros-args`` or a stray argument is one error line
    (exit 2); ``rclpy.init`` with rclpy's signal handlers off and :class:`StopFlag` instead,
    so SIGINT/SIGTERM *request* a stop: the node's work function returns, ``finish(node)``
    runs with the context still valid (files written, final lines logged), the node is
    destroyed, exit 0. A second signal interrupts at once (KeyboardInterrupt, ``finish`` still
    runs), and so does a signal while the node is still being built (exit 0, nothing to
    finish). A bad parameter (or bag) is one line ``[prog] error: parameter 'name': ...``, exit 2.

Parameters
    One style for every node: a table of :class:`Param` (name, default or type, description,
    check). :func:`declare_parameters` declares each one read-only (the nodes read them once at
    start-up, so ``ros2 param set`` is refused rather than silently ignored) and statically
    typed (the type of the default, or the ``Parameter.Type`` given for one unset by default),
    with its description, then reads it and runs its check. A wrong type or a bad value raises
    :class:`ParameterError` naming the parameter. Checks are small functions ``(name, value)
    -> value`` (:func:`number`, :func:`choice`, :func:`strings`, :func:`required_string`,
    :func:`optional_list`); checks that involve several parameters stay in the node and raise
    the same error.

QoS (defined once here)
    :data:`STREAM_QOS`: data streams (odometry, commands, truth; the identifier's inputs; play
    and record): RELIABLE, KEEP_LAST depth 1000, VOLATILE (:func:`stream_qos` adapts reliability
    and durability for record and play). Depth 1000 because KEEP_LAST + RELIABLE gives no
    back-pressure: measured on this stack (shared/ros_stack.md section 2) depth 1 lost 1-3 % at
    200 Hz and depth 10 the first samples after matching, depth 100+ nothing; 1000 holds 5 s
    of a 200 Hz stream while a reader is busy. :data:`LATCHED_QOS`: latest value for late
    joiners (RELIABLE, TRANSIENT_LOCAL, depth 1). :data:`DIAGNOSTICS_QOS`: RELIABLE depth 10.
    :data:`CLOCK_QOS`: ``/clock``, RELIABLE depth 100 (rclpy's time source subscribes
    BEST_EFFORT depth 1, which a RELIABLE writer serves).

Waiting for subscribers
    :class:`SubscriberWait`: before publishing a stream, wait (polled or blocking) until named
    nodes subscribe to our topics and/or named topics have a subscriber, and every subscription
    the graph shows on the watched publishers is matched by them; then ``settle`` s more for
    the readers' side of the match (ros_stack.md section 2: the writer can see the match
    first and lose the first samples).

Spinning
    :func:`spin` runs a node on rclpy's EventsExecutor (``rclpy.experimental``, C++; in the
    load test it cut the identifier's CPU per sample by 0.3-0.45 ms against the
    SingleThreadedExecutor of ``rclpy.spin``, docs/latency.md) in ``spin_once`` slices, until a
    stop is requested or ``done()``: its ``spin()`` does not return on a signal in Jazzy
    (measured), and callbacks that take the MessageInfo fail in it (``SystemError``,
    measured), so the recorder keeps the SingleThreadedExecutor.

Only the public rclpy API is used: rcl's RCLError is a RuntimeError subclass, caught as such
around the two calls that parse ``--ros-args``.
"""
import importlib
import math
import re
import signal
import sys
import threading
import time
from typing import Any, Callable, NamedTuple, Optional

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor
import rclpy
from rclpy.exceptions import InvalidParameterTypeException, ParameterUninitializedException
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from auv_ident.bags.schema import BagError, normalize_msgtype
from auv_ident.core.errors import AuvIdentError, ConfigError
from auv_ident.session.settings import ParameterError

STREAM_DEPTH = 1000
POLL_S = 0.1          # spin slice: how long a stop request can wait to be seen
DRAIN_IDLE_S = 0.1    # after a stop, drain until this long without a new message
DRAIN_MAX_S = 2.0     # and never for longer than this
SETTLE_S = 0.25       # after SubscriberWait is satisfied: the readers' side of the match
GRAPH_POLL_S = 0.05   # how often SubscriberWait re-reads the graph


def stream_qos(reliable=True, latched=False, depth=STREAM_DEPTH):
    """KEEP_LAST ``depth``; RELIABLE (or BEST_EFFORT), VOLATILE (or TRANSIENT_LOCAL)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=(ReliabilityPolicy.RELIABLE if reliable
                                   else ReliabilityPolicy.BEST_EFFORT),
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                                  else DurabilityPolicy.VOLATILE))


STREAM_QOS = stream_qos()
LATCHED_QOS = stream_qos(latched=True, depth=1)
DIAGNOSTICS_QOS = stream_qos(depth=10)
CLOCK_QOS = stream_qos(depth=100)


# --- parameters -------------------------------------------------------------------------------


class Param(NamedTuple):
    """One node parameter: default value (or the Parameter.Type of one unset by default),
    description (units in brackets) and check ``(name, value) -> value`` (None: as read)."""
    name: str
    default: Any
    description: str
    check: Optional[Callable[[str, Any], Any]] = None


_TYPE_WORDS = {
    'BOOL': 'true or false', 'INTEGER': 'an integer',
    'DOUBLE': 'a floating-point number (write 5.0, not 5)', 'STRING': 'a string',
    'BYTE_ARRAY': 'a byte array', 'BOOL_ARRAY': 'a list of true/false',
    'INTEGER_ARRAY': 'a list of integers',
    'DOUBLE_ARRAY': 'a list of floating-point numbers (write [1.0, 2.0], not [1, 2])',
    'STRING_ARRAY': 'a list of strings, e.g. [a, b]',
}
_GOT_RE = re.compile(r"to '(.*)' of type '(\w+)'", re.S)


def declare_parameters(node, table):
    """Declare every Param of ``table`` (module docstring) and return {name: checked value}.

    Unset parameters (ROS turns ``[]`` into "not set") read as None. Raises ParameterError
    naming the first parameter of the wrong type or with a bad value."""
    values = {}
    for p in table:
        try:
            node.declare_parameter(p.name, p.default, ParameterDescriptor(
                description=p.description, read_only=True))
        except InvalidParameterTypeException as err:
            expected = (p.default if isinstance(p.default, Parameter.Type)
                        else Parameter.Type.from_parameter_value(p.default)).name
            got = _GOT_RE.search(str(err))
            raise ParameterError(p.name, f'expected {_TYPE_WORDS.get(expected, expected)}'
                                 + (f', got {got.group(1)!r} ({got.group(2).lower()})'
                                    if got else '')) from None
        try:
            value = node.get_parameter(p.name).value
        except ParameterUninitializedException:
            value = None
        values[p.name] = value if p.check is None else p.check(p.name, value)
    return values


def number(minimum=None, above=None):
    """Check: a finite number, >= ``minimum`` and/or > ``above``."""
    def check(name, value):
        if value is None or isinstance(value, bool) or not math.isfinite(value):
            raise ParameterError(name, f'{value!r} must be a finite number')
        if minimum is not None and value < minimum:
            raise ParameterError(name, f'{value!r} must be >= {minimum:g}')
        if above is not None and value <= above:
            raise ParameterError(name, f'{value!r} must be > {above:g}')
        return value
    return check


def choice(options):
    """Check: one of ``options``."""
    def check(name, value):
        if value not in options:
            raise ParameterError(name, f'{value!r}; use one of {", ".join(options)}')
        return value
    return check


def strings(required=False, example='[a, b]'):
    """Check: a list of non-empty strings (stripped); unset = [] unless ``required``."""
    def check(name, value):
        items = [v.strip() for v in (value or [])]
        if not items and required:
            raise ParameterError(name, f'required, e.g. -p {name}:={example}')
        if not all(items):
            raise ParameterError(name, f'empty entry in {list(value)!r}')
        return items
    return check


def required_string(example):
    """Check: a non-empty string (stripped)."""
    def check(name, value):
        if not value or not value.strip():
            raise ParameterError(name, f'required, e.g. -p {name}:={example}')
        return value.strip()
    return check


def resolve_topics(node, name, topics):
    """The topics resolved against the node namespace (remappings apply), without repeats;
    ParameterError naming ``name`` for an invalid topic name."""
    out = []
    for t in topics:
        try:
            resolved = node.resolve_topic_name(t)
        except Exception:  # rclpy raises several types for invalid names
            raise ParameterError(name, f'invalid topic name {t!r}') from None
        if resolved not in out:
            out.append(resolved)
    return out


def optional_list(name, value):
    """Check: a list, or None when unset (= the default of whoever reads it)."""
    return None if value is None or len(value) == 0 else list(value)


# --- waiting for subscribers ------------------------------------------------------------------


class SubscriberWait:
    """Wait until our publishers have their subscribers (module docstring).

    ``publishers``: the publishers watched; ``nodes``: node names (plain, or fully qualified
    '/ns/name') each of which must subscribe to at least one of their topics; ``topics``:
    topic names (as the publishers resolve them) each of which needs a matched subscriber. In
    all cases every subscription the graph shows on a watched topic must be matched by our
    publisher of it. :meth:`poll` never blocks (for a timer callback); :meth:`wait` does."""

    def __init__(self, node, publishers, nodes=(), topics=(), timeout=5.0, settle=SETTLE_S,
                 clock=time.monotonic):
        self.node = node
        self.publishers = list(publishers)
        self.nodes = [n for n in nodes if n]
        self.topics = list(topics)
        self.timeout = timeout
        self.settle = settle
        self.clock = clock
        self.missing = []
        self._t0 = clock()
        self._ready_at = None
        self._next_poll = 0.0

    def check(self):
        """The names still missing now ([] = satisfied)."""
        missing = set(self.nodes)
        for pub in self.publishers:
            infos = self.node.get_subscriptions_info_by_topic(pub.topic_name)
            for info in infos:
                missing.discard(info.node_name)
                missing.discard(info.node_namespace.rstrip('/') + '/' + info.node_name)
            matched = pub.get_subscription_count()
            if pub.topic_name in self.topics and matched == 0:
                missing.add(pub.topic_name)
            elif matched < len(infos):
                missing.add(f'{pub.topic_name} (matching)')
        return sorted(missing)

    def poll(self):
        """None while waiting; True once satisfied and settled; False on the timeout."""
        now = self.clock()
        if self._ready_at is not None:
            return True if now - self._ready_at >= self.settle else None
        if now < self._next_poll:
            return None
        self._next_poll = now + GRAPH_POLL_S
        self.missing = self.check()
        if not self.missing:
            self._ready_at = now
            return True if self.settle <= 0 else None
        if now - self._t0 > self.timeout:
            return False
        return None

    def wait(self, stop=None):
        """Block until :meth:`poll` decides (True/False); None if ``stop`` was set first."""
        while True:
            result = self.poll()
            if result is not None:
                return result
            if stop is not None and stop.wait(GRAPH_POLL_S / 2):
                return None
            if stop is None:
                time.sleep(GRAPH_POLL_S / 2)


# --- spinning ---------------------------------------------------------------------------------


def spin(node, stop, done=None, executor=None, taken=None):
    """Run ``node``'s callbacks until ``stop`` is set, the context shuts down or ``done()``.

    ``executor``: rclpy's EventsExecutor by default (module docstring). ``taken``: a count of
    the messages the node's callbacks have taken; given, a stop request is followed by
    :func:`drain` (a stop must not lose the samples DDS has already received and
    acknowledged: the player's last ones, when it is stopped right after the bag's end)."""
    executor = EventsExecutor(context=node.context) if executor is None else executor
    executor.add_node(node)
    try:
        while not stop.is_set() and node.context.ok() and not (done and done()):
            executor.spin_once(timeout_sec=POLL_S)
        if taken is not None and stop.is_set() and node.context.ok():
            drain(executor, taken)
    finally:
        executor.remove_node(node)


def drain(executor, taken, idle_s=DRAIN_IDLE_S, max_s=DRAIN_MAX_S):
    """Run the callbacks of the samples DDS already holds, until ``taken()`` (the node's count
    of messages taken) has not grown for ``idle_s`` s, and never for longer than ``max_s``
    (a publisher that goes on must not keep a stopped node alive)."""
    start = idle_since = time.monotonic()
    last = taken()
    while True:
        executor.spin_once(timeout_sec=0.02)
        now = time.monotonic()
        if taken() != last:
            last, idle_since = taken(), now
        elif now - idle_since >= idle_s or now - start >= max_s:
            return


# --- entry point ------------------------------------------------------------------------------


class StopFlag:
    """SIGINT/SIGTERM handlers that request a clean stop; a second signal interrupts.

    rclpy's own handlers shut the context down at once: a recorder would drop the samples
    received but not yet taken, and the identifier could no longer log its final estimate.
    With this flag the node ends its work first."""

    def __init__(self):
        self.event = threading.Event()
        self.signum = None
        self.armed = False      # until the node's work starts, a signal interrupts at once
        self.holding = False
        self._previous = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._handle)

    def _handle(self, signum, frame):
        if self.holding:
            return  # finishing (files being closed): let it finish
        if self.event.is_set() or not self.armed:
            # a second signal, or one while the node is still being built (nothing to finish
            # yet; the identifier may be compiling its EKF): stop now, finally blocks still run
            raise KeyboardInterrupt
        self.signum = signum
        self.event.set()

    def is_set(self):
        return self.event.is_set()

    def wait(self, timeout):
        """Sleep up to ``timeout`` s; True if a stop was requested."""
        return self.event.wait(timeout)

    def hold(self):
        """Ignore further signals (while finishing)."""
        self.holding = True

    def restore(self):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def check_command_line(args, prog, doc, example):
    """Handle the non-ROS command line before rclpy.init: None to go on, or an exit status
    (0 after printing ``doc`` for -h/--help; 2 after one error line for a malformed
    --ros-args or stray arguments)."""
    argv = sys.argv if args is None else list(args)
    try:
        extra = remove_ros_args(argv)[1:]
    except RuntimeError as err:     # rcl's RCLError: unparsable --ros-args
        print(f'[{prog}] error: bad --ros-args: {str(err).splitlines()[0]}', file=sys.stderr)
        return 2
    if not extra:
        return None
    if extra[0] in ('-h', '--help'):
        print(doc)
        return 0
    print(f'[{prog}] error: unexpected argument(s) {extra}; parameters go after --ros-args, '
          f'e.g. --ros-args {example}', file=sys.stderr)
    return 2


def run_node(prog, args, doc, example, make_node, work, finish=None):
    """The entry harness of every node (module docstring); returns the exit status.

    ``make_node()`` builds the node (ParameterError or another AuvIdentError: exit 2);
    ``work(node, stop)`` does the job until it is over or ``stop`` is set; ``finish(node)``,
    if given, runs before the node is destroyed (also after an error in ``work``) and returns
    False on failure (exit 2)."""
    status = check_command_line(args, prog, doc, example)
    if status is not None:
        return status
    stop = StopFlag()
    rc = 0
    try:
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except RuntimeError as err:     # rcl's RCLError (already checked: a safety net)
            print(f'[{prog}] error: bad --ros-args: {str(err).splitlines()[0]}',
                  file=sys.stderr)
            return 2
        node = None
        try:
            node = make_node()
            stop.armed = True
            work(node, stop)
        except KeyboardInterrupt:
            pass
        except AuvIdentError as err:
            print(f'[{prog}] error: {err}', file=sys.stderr)
            rc = 2
        finally:
            stop.hold()
            if node is not None:
                if finish is not None and finish(node) is False:
                    rc = 2
                node.destroy_node()
            rclpy.try_shutdown()
    finally:
        stop.restore()
    return rc


def message_class(msgtype, topic):
    """The rclpy class of 'pkg/msg/Type'; a ConfigError naming the topic if it cannot be
    imported."""
    try:
        pkg, ns, name = normalize_msgtype(msgtype).split('/')
        return getattr(importlib.import_module(f'{pkg}.{ns}'), name)
    except (BagError, ImportError, AttributeError):
        raise ConfigError(f'topic {topic}: message type {msgtype!r} is not installed '
                          '(no importable rclpy class)') from None


IDENTIFIER_STATUS_NAME = 'auv_ident identifier'
_LEVELS = {'OK': DiagnosticStatus.OK, 'WARN': DiagnosticStatus.WARN,
           'ERROR': DiagnosticStatus.ERROR}


def identifier_status(health, hardware_id, values):
    """The identifier's DiagnosticStatus (both paths, ros/identifier_node.py docstring): a
    session's Health (level 'OK' / 'WARN' / 'ERROR', message), the vehicle's name and the
    (key, value) text pairs."""
    return DiagnosticStatus(level=_LEVELS[health.level], name=IDENTIFIER_STATUS_NAME,
                            message=health.message, hardware_id=hardware_id,
                            values=[KeyValue(key=k, value=v) for k, v in values])
