"""The identifier's input subscriptions and the order and time it takes their messages in
(setting ``intake_period_s``, docs/latency.md "Batched intake").

Batched (``intake_period_s`` > 0, the default 0.02 s): the executor is not woken for an
input message; a steady timer takes every message the input subscriptions hold, every
``intake_period_s``, and runs their callbacks in the order they were published. Why: on this
kind of machine the same per-message work costs about four times more CPU when the process
sleeps between messages than when it runs messages back to back (the raw-sensor session: 54 us
per message in a loop, 219 us with a 2 ms sleep after each; docs/latency.md), and an executor
that wakes for each message sleeps between all of them. At 400 Hz a 20 ms tick takes 8
messages at once. The cost: up to ``intake_period_s`` more between a message and its estimate,
far below the time the coefficients take to move (tens of seconds).

Each message (``callback(message, receive_ns)``) comes with its receive time, what a message
without a header is stamped with:
- with ``sim_clock`` (the node's use_sim_time and an input without a header): the /clock
  value taken last before it: /clock is one of the inputs (RELIABLE, depth 1000; rclpy's time
  source keeps only the newest /clock, BEST_EFFORT depth 1, so a command taken after a backlog
  got a later message's time: 73 of 543 commands of a played BlueROV2 bag up to 107 ms late);
  the node's clock until the first;
- else, batched: the message's DDS receive time (``received_timestamp`` of its MessageInfo,
  system clock, ns), the moment it arrived rather than the moment it was taken;
- else (``intake_period_s`` 0: each message as it arrives, an executor callback): the node's
  clock when it is taken.

The order, batched, is the order the messages were published in (``source_timestamp`` of
each message's info, set by the writer; the subscriptions' order, then arrival, breaking a
tie): a player publishes a message's /clock just before it, and that order is what stamps a
command as replay_bag does. Not the receive time: Fast DDS hands a burst to each reader in
turn, so across topics the receive times are not the publication order (a burst of 2000
/clock + command pairs from another process: 256 of 4000 out of place by received_timestamp,
none by source_timestamp). Publishers on other machines are ordered by their clocks, as far as
those agree (NTP, PTP). The subscriptions stay the node's (the graph shows it subscribed; a
player that waits for its subscribers finds it); :class:`IntakeNode` leaves them out of what
it gives an executor.
"""
import time

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMessage

from auv_ident.ros.toolkit import STREAM_QOS
from auv_ident.session.messages import NS_PER_S


class IntakeNode(Node):
    """A Node whose subscriptions in ``polled`` are not given to an executor (an
    :class:`Intake` takes their messages)."""

    def __init__(self, *args, **kwargs):
        self.polled = set()
        super().__init__(*args, **kwargs)

    @property
    def subscriptions(self):
        return (s for s in super().subscriptions if s not in self.polled)


class Intake:
    """The input subscriptions of ``node`` (an :class:`IntakeNode`), taken every ``period_s``
    (0: each as it arrives) with ``sim_clock`` as the module docstring says.

    ``callbacks``: the callback of each subscribed topic, as :meth:`subscribe` got it."""

    def __init__(self, node, period_s, sim_clock=False):
        self.node = node
        self.period_s = float(period_s)
        self.callbacks = {}
        self._polled = []          # (subscription, callback), in subscription order
        self._pending = []         # taken, received after the last take began: the next runs them
        self._arrivals = 0         # messages taken so far: the last tie-break of the order
        self.timer = None
        if self.period_s > 0.0:
            self.timer = node.create_timer(self.period_s, self.take,
                                           clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.clock_ns = None       # the last /clock taken (sim_clock)
        self.sub_clock = None
        if sim_clock:
            self.sub_clock = self.subscribe(ClockMessage, '/clock', self._on_clock, STREAM_QOS)

    @classmethod
    def for_inputs(cls, node, period_s, entries):
        """The intake of ``node``'s input-map inputs ``entries`` (session/input_map.py
        InputEntry), taken every ``period_s``: with ``sim_clock`` when the node runs on sim
        time (its ``use_sim_time`` parameter) and an input has no header, whose messages are
        then stamped with the /clock taken last before them (a played bag's commands get their
        log times, module docstring)."""
        sim_clock = bool(node.get_parameter('use_sim_time').value) and any(
            not e.stamped for e in entries)
        return cls(node, period_s, sim_clock=sim_clock)

    def subscribe(self, msg_type, topic, callback, qos, raw=False, **kwargs):
        """An input subscription (rclpy create_subscription's arguments); ``callback(message,
        receive_ns)``, the message's bytes with ``raw``."""
        self.callbacks[topic] = callback
        if self.period_s <= 0.0:
            return self.node.create_subscription(
                msg_type, topic, lambda msg: callback(msg, self.receive_ns()), qos, raw=raw,
                **kwargs)
        sub = self.node.create_subscription(msg_type, topic, _never_called, qos, raw=raw,
                                            **kwargs)
        self.node.polled.add(sub)
        self._polled.append((sub, callback))
        return sub

    def take(self):
        """Run the callbacks of every message the batched subscriptions received before this
        call, and of every message the previous call deferred, in the order they were published
        (module docstring); returns how many. A message received while the subscriptions are
        read waits for the next call: one read after another is not one instant, and a /clock
        published before a command but received after the read of /clock would otherwise come
        after the command. Which messages those are is told by their rmw receive time against
        the system clock, two clocks that may disagree; so what one call deferred the next runs
        whatever its receive time says: a receive clock ahead of ours delays a message by one
        period at most, never holds it."""
        start_ns = time.time_ns()
        ready = self._pending       # deferred by the last call: run now, unconditionally
        self._pending = []
        for index, (sub, callback) in enumerate(self._polled):
            with sub.handle:
                while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                    msg, info = taken
                    self._arrivals += 1
                    item = (info['source_timestamp'], index, self._arrivals,
                            info['received_timestamp'], msg, callback)
                    (ready if item[3] <= start_ns else self._pending).append(item)
        ready.sort(key=lambda item: item[:3])
        for _, _, _, received_ns, msg, callback in ready:
            callback(msg, received_ns if self.sub_clock is None else self.receive_ns())
        return len(ready)

    def _on_clock(self, msg, _receive_ns):
        self.clock_ns = msg.clock.sec * NS_PER_S + msg.clock.nanosec

    def receive_ns(self):
        """The receive time of a message taken now (int ns): the last /clock taken (sim_clock;
        the node's clock until the first), else the node's clock."""
        if self.clock_ns is not None:
            return self.clock_ns
        return self.node.get_clock().now().nanoseconds


def _never_called(_msg):
    # a batched subscription's callback: the executor never takes its messages (IntakeNode)
    raise AssertionError('a batched input subscription was given to an executor')
