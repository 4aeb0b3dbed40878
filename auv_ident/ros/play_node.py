"""Play a rosbag2 (MCAP) bag back onto the graph: ``ros2 run auv_ident play``.

rosbag2 is not on PyPI, so this node stands in for ``ros2 bag play`` in the wheel-based stack.
Each message is published as the CDR bytes stored in the bag (``read_bag(..., raw=True)`` into
``Publisher.publish(bytes)``): no decode/encode, so the subscribers get exactly what was
recorded.

Run::

    ros2 run auv_ident play --ros-args -p bag:=bags/run1 -p rate:=2.0 -p publish_clock:=true
    python -m auv_ident run play --ros-args -p bag:=run1 -p wait_for_subscribers:=[/odom]

Publications
    every (selected) topic of the bag with its recorded type; ``/clock``
    (rosgraph_msgs/Clock) with ``publish_clock``.

Parameters
    ``bag`` (string, required)  bag directory (metadata.yaml + .mcap) or a bare .mcap file.
    ``rate`` (float > 0, default 1.0)  playback speed factor: messages are sent at their
        recorded log-time spacing divided by ``rate``. The schedule is absolute (start time +
        offset / rate on the monotonic clock), so delays do not accumulate.
    ``publish_clock`` (bool, default false)  publish ``/clock`` = the log time of each
        message before it (once per distinct log time). A ``/clock`` topic recorded in the bag
        is then not played (one clock source).
    ``topics`` (string array, default empty = all)  topics to play; a topic not in the bag is
        an error.
    ``wait_for_subscribers`` (string array, default empty)  topics (played ones, or /clock)
        that must have a subscriber before playback starts, so nothing is lost at the start;
        then a 0.25 s settle lets the subscribers' side of the match complete as well.
    ``wait_for_subscribers_s`` (float >= 0, default 5.0)  how long to wait for them; on a
        timeout a warning names the topics and playback starts anyway.
    ``start_delay_s`` (float >= 0, default 0.0)  extra delay before the first message.
    ``loop`` (bool, default false)  start again at the end, until stopped.
    ``allow_truncated`` (bool, default false)  play the complete chunks of a bag whose
        recorder was killed (no metadata.yaml / MCAP summary) instead of refusing it.
    ``wait_for_all_acked_s`` (float >= 0, default 5.0)  at the end, keep the publishers alive
        until every reliable subscriber has acknowledged every message, for at most this long
        (rosbag2's ``--wait-for-all-acked``). Measured: exiting right after the last publish
        lost the last sample of some topics in 2 of 3 runs (the subscriber dropped it as the
        writer disappeared). Fast DDS acknowledges on its heartbeat period, so this adds up to
        ~3 s at the end; 0 skips it.

QoS
    Publishers are RELIABLE (compatible with RELIABLE and BEST_EFFORT subscribers), KEEP_LAST
    depth 1000 (no loss while a subscriber is still completing discovery: ros_stack.md section
    2), and TRANSIENT_LOCAL only if every recorded publisher of the topic offered it (so
    latched topics stay latched), else VOLATILE. ``/clock``: RELIABLE KEEP_LAST 100 VOLATILE
    (rclpy's time source subscribes BEST_EFFORT, which matches).

Exit status: 0 when the bag has been played (or on SIGINT/SIGTERM); 2 with one error line
naming the file or the parameter for a missing/corrupt bag or a bad parameter.
"""
from pathlib import Path
import sys
import time

from mcap.reader import make_reader
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
import yaml

from auv_ident.bags.reader import bag_topics, read_bag
from auv_ident.ros.conversions import ns_to_stamp
from auv_ident.ros.toolkit import declare_described, parameter_values
from auv_ident.ros.record_node import (message_class, number_param, param_error,
                                       run_with_stop_flag, string_list_param)

NODE_NAME = 'player'
CLOCK_TOPIC = '/clock'
PUBLISHER_DEPTH = 1000
SETTLE_S = 0.25       # after the publisher sees its subscribers (their side may lag)

_PARAMETERS = (
    ('bag', None, 'bag directory or .mcap file to play (required)'),
    ('rate', 1.0, 'playback speed factor (> 0)'),
    ('publish_clock', False, 'publish /clock from the log times'),
    ('topics', None, 'topics to play (string array; empty = all)'),
    ('wait_for_subscribers', None, 'topics that need a subscriber before playback starts'),
    ('wait_for_subscribers_s', 5.0, 'how long to wait for those subscribers [s]'),
    ('start_delay_s', 0.0, 'delay before the first message [s]'),
    ('loop', False, 'play again from the start at the end'),
    ('allow_truncated', False, 'play the complete chunks of an unfinished bag'),
    ('wait_for_all_acked_s', 5.0, 'wait this long at the end for acknowledgements [s]'),
)


def _bool(name, value):
    if not isinstance(value, bool):
        raise param_error(name, f'must be true or false, got {value!r}')
    return value


def recorded_qos(path):
    """Return {topic: [offered QoS dicts]} from the bag's MCAP channel metadata ({} if none).

    QoS only tunes the publishers, so any problem reading it just gives {}.
    """
    p = Path(path)
    files = [p] if p.is_file() else sorted(p.glob('*.mcap'))
    out = {}
    for f in files:
        try:
            with open(f, 'rb') as fh:
                summary = make_reader(fh).get_summary()
            for channel in (summary.channels.values() if summary else ()):
                profiles = yaml.safe_load(channel.metadata.get('offered_qos_profiles', ''))
                if isinstance(profiles, list):
                    out.setdefault(channel.topic, []).extend(
                        q for q in profiles if isinstance(q, dict))
        except Exception:  # a corrupt file: read_bag reports it properly
            continue
    return out


class PlayNode(Node):
    """Publish the messages of a bag with their recorded timing (see the module docstring)."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self._declare_parameters()
        self._read_parameters()
        self.played = 0
        self._open_bag()

    # --- parameters ---

    def _declare_parameters(self):
        declare_described(self, _PARAMETERS, dynamic_typing=True)

    def _read_parameters(self):
        value = parameter_values(self, _PARAMETERS)
        bag = value['bag']
        if not isinstance(bag, str) or not bag.strip():
            raise param_error('bag', 'required: a bag directory or .mcap file, e.g. '
                               '-p bag:=bags/run1')
        self.bag = Path(bag.strip()).expanduser()
        self.rate = number_param('rate', value['rate'], 0.0, strict=True)
        self.publish_clock = _bool('publish_clock', value['publish_clock'])
        self.loop = _bool('loop', value['loop'])
        self.allow_truncated = _bool('allow_truncated', value['allow_truncated'])
        self.start_delay_s = number_param('start_delay_s', value['start_delay_s'], 0.0,
                                     strict=False)
        self.wait_for_subscribers_s = number_param(
            'wait_for_subscribers_s', value['wait_for_subscribers_s'], 0.0, strict=False)
        self.wait_for_all_acked_s = number_param(
            'wait_for_all_acked_s', value['wait_for_all_acked_s'], 0.0, strict=False)
        self.requested_topics = self._resolve('topics', value['topics'])
        self.wait_topics = self._resolve('wait_for_subscribers', value['wait_for_subscribers'])

    def _resolve(self, name, value):
        out = []
        for t in string_list_param(name, value, required=False):
            try:
                resolved = self.resolve_topic_name(t)
            except Exception:  # rclpy raises several types for invalid names
                raise param_error(name, f'invalid topic name {t!r}') from None
            if resolved not in out:
                out.append(resolved)
        return out

    # --- bag and publishers ---

    def _open_bag(self):
        present = bag_topics(self.bag, allow_truncated=self.allow_truncated)  # BagError
        if self.requested_topics:
            absent = [t for t in self.requested_topics if t not in present]
            if absent:
                raise param_error('topics', f'{", ".join(absent)} not in {self.bag} (it has '
                                   f'{", ".join(sorted(present)) or "no topics"})')
            selected = list(self.requested_topics)
        else:
            selected = sorted(present)
        if self.publish_clock and CLOCK_TOPIC in selected:
            selected.remove(CLOCK_TOPIC)
            self.get_logger().warning(f'{self.bag} has {CLOCK_TOPIC}: not played, '
                                      'publish_clock generates it from the log times')
        if not selected:
            raise param_error('topics', f'nothing to play in {self.bag}')
        self.selected = selected
        self.types = {t: present[t] for t in selected}
        qos_by_topic = recorded_qos(self.bag)
        self.pubs = {}
        for topic in selected:
            cls = message_class(self.types[topic], topic)
            offered = qos_by_topic.get(topic) or []
            latched = bool(offered) and all(q.get('durability') == 'transient_local'
                                            for q in offered)
            qos = QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=PUBLISHER_DEPTH,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                            else DurabilityPolicy.VOLATILE))
            self.pubs[topic] = self.create_publisher(cls, topic, qos)
        self.clock_pub = None
        if self.publish_clock:
            self.clock_pub = self.create_publisher(
                Clock, CLOCK_TOPIC, QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                                               reliability=ReliabilityPolicy.RELIABLE))
        waitable = set(self.pubs) | ({CLOCK_TOPIC} if self.publish_clock else set())
        unknown = [t for t in self.wait_topics if t not in waitable]
        if unknown:
            raise param_error('wait_for_subscribers', f'{", ".join(unknown)} not played '
                               f'(played: {", ".join(sorted(waitable))})')

    def _publisher(self, topic):
        return self.clock_pub if topic == CLOCK_TOPIC else self.pubs[topic]

    # --- playback ---

    def wait_for_subscribers(self, stop):
        """Wait (<= wait_for_subscribers_s) for a subscriber on each wait_for_subscribers."""
        if not self.wait_topics:
            return
        deadline = time.monotonic() + self.wait_for_subscribers_s
        while True:
            missing = [t for t in self.wait_topics
                       if self._publisher(t).get_subscription_count() == 0]
            if not missing:
                stop.event.wait(SETTLE_S)
                return
            if time.monotonic() >= deadline:
                self.get_logger().warning(
                    f'no subscriber on {", ".join(missing)} after '
                    f'{self.wait_for_subscribers_s:g} s; playing anyway')
                return
            if stop.event.wait(0.02):
                return

    def play(self, stop):
        """Play the bag (again and again with ``loop``) until done or stopped."""
        self.wait_for_subscribers(stop)
        if self.start_delay_s > 0 and stop.event.wait(self.start_delay_s):
            return
        self.get_logger().info(f'playing {self.bag} ({len(self.selected)} topics) at rate '
                               f'{self.rate:g}')
        started = time.monotonic()
        while not stop.is_set():
            if self._play_once(stop) == 0 or not self.loop:
                break
        if not stop.is_set() and self.wait_for_all_acked_s > 0:
            self.wait_for_acks(stop)
        self.get_logger().info(f'played {self.played} messages in '
                               f'{time.monotonic() - started:.2f} s')

    def _play_once(self, stop):
        count = 0
        t_first = wall_first = None
        last_clock = None
        for topic, t_ns, payload in read_bag(self.bag, self.selected, raw=True,
                                             allow_truncated=self.allow_truncated):
            if t_first is None:
                t_first, wall_first = t_ns, time.monotonic()
            delay = wall_first + (t_ns - t_first) * 1e-9 / self.rate - time.monotonic()
            if delay > 0 and stop.event.wait(delay):
                break
            if stop.is_set():
                break
            if self.clock_pub is not None and t_ns != last_clock:
                self.clock_pub.publish(Clock(clock=ns_to_stamp(t_ns)))
                last_clock = t_ns
            self.pubs[topic].publish(payload)
            count += 1
            self.played += 1
        return count

    def wait_for_acks(self, stop):
        """Wait (<= wait_for_all_acked_s) until the subscribers acknowledged everything."""
        deadline = time.monotonic() + self.wait_for_all_acked_s
        pubs = list(self.pubs.values()) + ([self.clock_pub] if self.clock_pub else [])
        pending = []
        for pub in pubs:
            # short slices: signals are handled between them
            while not pub.wait_for_all_acked(Duration(nanoseconds=50_000_000)):
                if stop.is_set() or time.monotonic() >= deadline:
                    pending.append(pub.topic_name)
                    break
        if pending and not stop.is_set():
            self.get_logger().warning(f'{", ".join(pending)}: not acknowledged by every '
                                      f'subscriber within {self.wait_for_all_acked_s:g} s')


def main(args=None):
    """Entry point of ``play``; returns the exit status (0, or 2 on a bad bag/parameter)."""
    return run_with_stop_flag('play', args, __doc__, '-p bag:=run1', PlayNode,
                              lambda node, stop: node.play(stop))


if __name__ == '__main__':
    sys.exit(main())
