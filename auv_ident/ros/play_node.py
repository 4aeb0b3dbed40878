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
    ``input_map`` (string, default '')  an input map (config/inputs/NAME.yaml or a path,
        docs/your_data.md): its topics are played (with ``topics``, if given); a topic of the
        map the bag lacks, or records with another type, is an error naming the input.
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
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
import yaml

from auv_ident.bags.reader import bag_topics, read_bag
from auv_ident.ros.conversions import ns_to_stamp
from auv_ident.ros.toolkit import (
    CLOCK_QOS,
    declare_parameters,
    message_class,
    number,
    Param,
    required_string,
    resolve_topics,
    run_node,
    stream_qos,
    strings,
    SubscriberWait,
)
from auv_ident.session.input_map import InputMapError, load_input_map
from auv_ident.session.settings import ParameterError

NODE_NAME = 'player'
CLOCK_TOPIC = '/clock'

_PARAMETERS = (
    Param('bag', '', 'bag directory or .mcap file to play (required)',
          required_string('bags/run1')),
    Param('rate', 1.0, 'playback speed factor (> 0)', number(above=0.0)),
    Param('publish_clock', False, 'publish /clock from the log times'),
    Param('topics', Parameter.Type.STRING_ARRAY, 'topics to play; empty = all', strings()),
    Param('input_map', '', "play the topics of this input map (config/inputs/NAME.yaml or a "
                           "path; docs/your_data.md), with topics; '' = none"),
    Param('wait_for_subscribers', Parameter.Type.STRING_ARRAY,
          'topics that need a subscriber before playback starts', strings()),
    Param('wait_for_subscribers_s', 5.0, 'how long to wait for those subscribers [s]',
          number(minimum=0.0)),
    Param('start_delay_s', 0.0, 'delay before the first message [s]', number(minimum=0.0)),
    Param('loop', False, 'play again from the start at the end'),
    Param('allow_truncated', False, 'play the complete chunks of an unfinished bag'),
    Param('wait_for_all_acked_s', 5.0, 'wait this long at the end for acknowledgements [s]',
          number(minimum=0.0)),
)


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
        self._read_parameters()
        self.played = 0
        self._open_bag()

    # --- parameters ---

    def _read_parameters(self):
        value = declare_parameters(self, _PARAMETERS)
        self.bag = Path(value['bag']).expanduser()
        self.rate = value['rate']
        self.publish_clock = value['publish_clock']
        self.loop = value['loop']
        self.allow_truncated = value['allow_truncated']
        self.start_delay_s = value['start_delay_s']
        self.wait_for_subscribers_s = value['wait_for_subscribers_s']
        self.wait_for_all_acked_s = value['wait_for_all_acked_s']
        self.requested_topics = resolve_topics(self, 'topics', value['topics'])
        self.input_map = None
        if value['input_map'].strip():
            try:
                self.input_map = load_input_map(value['input_map'])
            except InputMapError as err:
                raise ParameterError('input_map', str(err)) from None
        self.wait_topics = resolve_topics(self, 'wait_for_subscribers',
                                          value['wait_for_subscribers'])

    # --- bag and publishers ---

    def _open_bag(self):
        present = bag_topics(self.bag, allow_truncated=self.allow_truncated)  # BagError
        if self.input_map is not None:
            try:
                self.input_map.check_topics(present, self.bag)
            except InputMapError as err:
                raise ParameterError('input_map', str(err)) from None
            self.requested_topics += [t for t in self.input_map.topic_types
                                      if t not in self.requested_topics]
        if self.requested_topics:
            absent = [t for t in self.requested_topics if t not in present]
            if absent:
                raise ParameterError('topics', f'{", ".join(absent)} not in {self.bag} (it has '
                                   f'{", ".join(sorted(present)) or "no topics"})')
            selected = list(self.requested_topics)
        else:
            selected = sorted(present)
        if self.publish_clock and CLOCK_TOPIC in selected:
            selected.remove(CLOCK_TOPIC)
            self.get_logger().warning(f'{self.bag} has {CLOCK_TOPIC}: not played, '
                                      'publish_clock generates it from the log times')
        if not selected:
            raise ParameterError('topics', f'nothing to play in {self.bag}')
        self.selected = selected
        self.types = {t: present[t] for t in selected}
        qos_by_topic = recorded_qos(self.bag)
        self.pubs = {}
        for topic in selected:
            cls = message_class(self.types[topic], topic)
            offered = qos_by_topic.get(topic) or []
            latched = bool(offered) and all(q.get('durability') == 'transient_local'
                                            for q in offered)
            self.pubs[topic] = self.create_publisher(cls, topic, stream_qos(latched=latched))
        self.clock_pub = None
        if self.publish_clock:
            self.clock_pub = self.create_publisher(Clock, CLOCK_TOPIC, CLOCK_QOS)
        waitable = set(self.pubs) | ({CLOCK_TOPIC} if self.publish_clock else set())
        unknown = [t for t in self.wait_topics if t not in waitable]
        if unknown:
            raise ParameterError('wait_for_subscribers', f'{", ".join(unknown)} not played '
                               f'(played: {", ".join(sorted(waitable))})')

    def _publisher(self, topic):
        return self.clock_pub if topic == CLOCK_TOPIC else self.pubs[topic]

    # --- playback ---

    def wait_for_subscribers(self, stop):
        """Wait (<= wait_for_subscribers_s) for a subscriber on each wait_for_subscribers."""
        if not self.wait_topics:
            return
        wait = SubscriberWait(self, [self._publisher(t) for t in self.wait_topics],
                              topics=self.wait_topics, timeout=self.wait_for_subscribers_s)
        if wait.wait(stop.event) is False:
            self.get_logger().warning(
                f'no subscriber on {", ".join(wait.missing)} after '
                f'{self.wait_for_subscribers_s:g} s; playing anyway')

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
    return run_node('play', args, __doc__, '-p bag:=run1', PlayNode,
                    lambda node, stop: node.play(stop))


if __name__ == '__main__':
    sys.exit(main())
