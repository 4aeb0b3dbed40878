"""Record topics into a rosbag2 (Jazzy, MCAP) bag: ``ros2 run auv_ident record``.

rosbag2 is not on PyPI, so this node stands in for ``ros2 bag record`` in the wheel-based stack;
the bag it writes is the rosbag2 MCAP layout of :mod:`auv_ident.bags.writer`. Messages are recorded
as the serialized CDR bytes DDS delivers (``raw=True``): no decode/encode on the way.

Run::

    ros2 run auv_ident record --ros-args -p topics:=[/odom,/actuators] -p output:=bags/run1
    ros2 run auv_ident record --ros-args -p input_map:=odom_actuators -p output:=bags/run1
    python -m auv_ident run record --ros-args -p topics:=[/odom] -p output:=run1

Subscriptions
    every topic in ``topics``, with the type discovered from the graph (or given in ``types``).

Parameters
    ``topics`` (string array, required unless ``input_map`` is given)  topics to record;
        relative names are resolved against the node namespace (remappings apply).
    ``input_map`` (string, default '')  an input map (config/inputs/NAME.yaml or a path,
        docs/your_data.md): its topics are recorded too, with the map's types (no discovery
        needed, so the recorder can start before the vehicle's drivers).
    ``output`` (string, required)  bag directory to create; must not exist.
    ``compression`` ('zstd' | 'none', default 'zstd')  MCAP chunk compression.
    ``wait_for_topics_s`` (float >= 0, default 5.0)  how long to wait (one deadline for all)
        for the types of the topics not in ``types`` to appear in the graph; a topic still
        unknown then is an error, exit 2 (start its publisher first, or give its type).
    ``types`` (string array, default empty)  ``'topic=pkg/msg/Type'`` entries that skip
        discovery for those topics (record before the publisher exists).
    ``flush_period_s`` (float > 0, default 0.5)  period of the wall-clock (steady) timer that
        closes the MCAP chunk in progress: a SIGKILL loses at most about this much data.
    ``use_sim_time`` (bool, rclpy's)  see "Log time".

Log time
    As in Jazzy's rosbag2 recorder: the MCAP log time (and publish time) of a message is its
    *receive* time, not its ``header.stamp``: the rmw ``received_timestamp`` (system clock,
    taken when DDS received the sample, so executor delays do not skew it), or the node clock
    (``/clock``) at the callback when ``use_sim_time`` is true. Header stamps stay inside the
    payloads, untouched.

QoS
    Subscriptions are KEEP_LAST depth 1000 (a recorder must not drop while the executor is
    busy writing; ros_stack.md section 2 measured losses with depth 1-10). Reliability is
    RELIABLE unless a discovered publisher offers BEST_EFFORT (a RELIABLE reader gets nothing
    from a BEST_EFFORT writer); durability is TRANSIENT_LOCAL only if every discovered
    publisher offers it (to catch latched samples), else VOLATILE: rosbag2's adaptation rule.
    The bag stores the publishers' offered profiles (``get_publishers_info_by_topic``) in
    ``offered_qos_profiles``, as rosbag2 does; for a topic without a discovered publisher
    (given in ``types``) it stores bags.schema.DEFAULT_QOS (RELIABLE, VOLATILE, KEEP_LAST 10).

Stopping
    SIGINT and SIGTERM both stop recording: the samples DDS has already received are drained
    from the reader queues, then the bag is closed (MCAP summary + metadata.yaml), exit status
    0. A second signal skips the drain. SIGKILL leaves a bag without metadata.yaml whose
    complete chunks ``read_bag(..., allow_truncated=True)`` recovers (flushed every
    ``flush_period_s``). Bad parameters print one line naming the parameter and exit with 2.
"""
import os
import sys
import time

from rclpy.clock import Clock, ClockType
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from auv_ident.bags.schema import BagError, normalize_msgtype
from auv_ident.bags.writer import BagWriter
from auv_ident.core.errors import ConfigError
from auv_ident.ros.toolkit import (
    choice,
    declare_parameters,
    message_class,
    number,
    Param,
    POLL_S,
    required_string,
    resolve_topics,
    run_node,
    spin,
    stream_qos,
    strings,
)
from auv_ident.session.input_map import InputMapError, load_input_map
from auv_ident.session.settings import ParameterError

NODE_NAME = 'recorder'

_PARAMETERS = (
    Param('topics', Parameter.Type.STRING_ARRAY,
          'topics to record (required unless input_map is given)',
          strings(example='[/odom,/actuators]')),
    Param('input_map', '', 'input map whose topics are recorded, with its types (config/inputs/'
                           "NAME.yaml or a path; docs/your_data.md); '' = none"),
    Param('output', '', 'bag directory to create; must not exist (required)',
          required_string('bags/run1')),
    Param('compression', 'zstd', "MCAP chunk compression: 'zstd' or 'none'",
          choice(('zstd', 'none'))),
    Param('wait_for_topics_s', 5.0, 'time to wait for the topic types to be discovered [s]',
          number(minimum=0.0)),
    Param('types', Parameter.Type.STRING_ARRAY,
          "'topic=pkg/msg/Type' entries that skip discovery", strings()),
    Param('flush_period_s', 0.5, 'wall-clock period of closing the MCAP chunk in progress [s]',
          number(above=0.0)),
)


class RecordNode(Node):
    """Record topics as raw CDR into a rosbag2 MCAP bag (see the module docstring)."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        try:
            self._read_parameters()
        except BaseException:
            # run_node never gets this node to destroy: release its DDS entities before
            # rclpy shuts down (a record with a bad input map once printed its error and
            # did not exit within 30 s in CI)
            self.destroy_node()
            raise
        self.writer = None
        self.counts = {}
        self.received = 0
        self.write_errors = 0
        self._subscriptions = []
        self._flush_timer = None

    # --- parameters ---

    def _read_parameters(self):
        value = declare_parameters(self, _PARAMETERS)
        map_types = self._map_types(value['input_map'])
        if not value['topics'] and not map_types:
            raise ParameterError('topics', 'required unless input_map is given, e.g. -p '
                                           'topics:=[/odom,/actuators]')
        self.topics = resolve_topics(self, 'topics', value['topics'] + list(map_types))
        output = os.path.abspath(os.path.expanduser(value['output']))
        if os.path.lexists(output):
            raise ParameterError('output', f'{output} exists already (not overwriting a bag)')
        self.output = output
        self.compression = None if value['compression'] == 'none' else 'zstd'
        self.wait_for_topics_s = value['wait_for_topics_s']
        self.flush_period_s = value['flush_period_s']
        self.given_types = {resolve_topics(self, 'input_map', [t])[0]: typ
                            for t, typ in map_types.items()}
        for entry in value['types']:
            topic, sep, msgtype = entry.partition('=')
            if not sep or not topic.strip() or not msgtype.strip():
                raise ParameterError('types', f"entry {entry!r} is not 'topic=pkg/msg/Type'")
            try:
                msgtype = normalize_msgtype(msgtype.strip())
            except BagError as exc:
                raise ParameterError('types', f'entry {entry!r}: {exc}') from None
            topic = resolve_topics(self, 'types', [topic.strip()])[0]
            if topic not in self.topics:
                raise ParameterError('types', f'topic {topic} is not in topics {self.topics}')
            self.given_types[topic] = msgtype
        self.use_sim_time = bool(self.get_parameter('use_sim_time').value)

    def _map_types(self, name):
        """{topic: type} of the input map named (its topics as the map writes them:
        relative ones resolve in the node's namespace); {} for ''."""
        if not name.strip():
            return {}
        try:
            imap = load_input_map(name)
        except InputMapError as err:
            raise ParameterError('input_map', str(err)) from None
        return {e.topic: e.type for e in imap.inputs}

    # --- start: discovery, bag, subscriptions ---

    def discover_types(self, stop=None):
        """Return {topic: 'pkg/msg/Type'} for every topic, waiting for discovery if needed.

        Returns None if ``stop`` was set while waiting; raises ConfigError on a timeout or on
        a topic with several types.
        """
        types = dict(self.given_types)
        deadline = time.monotonic() + self.wait_for_topics_s
        while True:
            graph = dict(self.get_topic_names_and_types())
            for topic in self.topics:
                if topic in types or topic not in graph:
                    continue
                found = sorted(set(graph[topic]))
                if len(found) > 1:
                    raise ConfigError(f'topic {topic}: publishers disagree on the type '
                                      f'({", ".join(found)}); give it with -p types:=')
                if found:
                    types[topic] = normalize_msgtype(found[0])
            missing = [t for t in self.topics if t not in types]
            if not missing:
                return types
            if stop is not None and stop.is_set():
                return None
            if time.monotonic() >= deadline:
                raise ParameterError('topics', f'type of {", ".join(missing)} not discovered '
                                   f'within {self.wait_for_topics_s:g} s (no publisher?); '
                                   'start the publisher first, raise wait_for_topics_s, or '
                                   'give it with -p types:=[topic=pkg/msg/Type]')
            time.sleep(POLL_S)

    def _qos(self, topic):
        """Return (subscription QoSProfile, offered profiles for the bag or None)."""
        offered = [p.qos_profile for p in self.get_publishers_info_by_topic(topic)]
        best_effort = any(q.reliability == ReliabilityPolicy.BEST_EFFORT for q in offered)
        latched = bool(offered) and all(
            q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
        return stream_qos(reliable=not best_effort, latched=latched), (offered or None)

    def start(self, stop=None):
        """Discover types, create the bag and subscribe; False if stopped while waiting."""
        types = self.discover_types(stop)
        if types is None:
            return False
        classes = {topic: message_class(types[topic], topic) for topic in self.topics}
        self.writer = BagWriter(self.output, compression=self.compression)
        self.writer.set_custom_data('auv_ident.recorded_by', 'auv_ident record')
        for topic in self.topics:
            qos, offered = self._qos(topic)
            self.writer.add_topic(topic, types[topic], qos=offered)
            self.counts[topic] = 0
            self._subscriptions.append(self.create_subscription(
                classes[topic], topic, self._make_callback(topic), qos, raw=True))
            self.get_logger().info(
                f'recording {topic} ({types[topic]}, {qos.reliability.name.lower()}, '
                f'{qos.durability.name.lower()}, {len(offered or [])} publisher(s))')
        # Steady (wall) clock: with use_sim_time a node-clock timer would follow /clock.
        self._flush_timer = self.create_timer(
            self.flush_period_s, self.flush, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f'writing {self.output}')
        return True

    def _make_callback(self, topic):
        def callback(payload, info):
            self.on_message(topic, payload, info)
        return callback

    def on_message(self, topic, payload, info):
        """Write one serialized message with its receive time (see "Log time")."""
        self.received += 1
        if self.use_sim_time:
            t_ns = self.get_clock().now().nanoseconds
        else:
            t_ns = (info or {}).get('received_timestamp') or time.time_ns()
        try:
            self.writer.write(topic, int(t_ns), payload)
        except (BagError, OSError) as exc:
            self.write_errors += 1
            if self.write_errors <= 3:
                self.get_logger().error(f'{topic}: message not recorded: {exc}')
            return
        self.counts[topic] += 1

    def flush(self):
        """Close the MCAP chunk in progress (the flush timer's callback)."""
        if self.writer is not None:
            try:
                self.writer.flush()
            except (BagError, OSError) as exc:
                self.get_logger().error(f'flush failed: {exc}')

    def close(self):
        """Finish the bag (summary + metadata.yaml); idempotent, safe in ``finally``."""
        if self._flush_timer is not None:
            self.destroy_timer(self._flush_timer)
            self._flush_timer = None
        for sub in self._subscriptions:
            self.destroy_subscription(sub)
        self._subscriptions = []
        if self.writer is not None and not self.writer.closed:
            self.writer.close()
            per_topic = ', '.join(f'{t}: {n}' for t, n in self.counts.items())
            self.get_logger().info(f'closed {self.output}: {self.writer.message_count} '
                                   f'messages ({per_topic})')


def _record(node, stop):
    if node.start(stop):
        # The SingleThreadedExecutor: the callbacks take the MessageInfo (receive time), which
        # rclpy's EventsExecutor cannot pass in Jazzy (ros/toolkit.py).
        executor = SingleThreadedExecutor(context=node.context)
        spin(node, stop, executor=executor,
             taken=(lambda: node.received) if node.writer is not None else None)


def _close(node):
    try:
        node.close()
    except (BagError, OSError) as exc:
        print(f'[record] error: {exc}', file=sys.stderr)
        return False
    return True


def main(args=None):
    """Entry point of ``record``; returns the exit status (0, or 2 on bad parameters)."""
    return run_node('record', args, __doc__, '-p topics:=[/odom] -p output:=run1', RecordNode,
                    _record, _close)


if __name__ == '__main__':
    sys.exit(main())
