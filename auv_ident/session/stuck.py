"""The stuck-sensor rule: a measured channel group that repeats its values exactly.

Real sensor noise never repeats a value exactly, let alone three at once: a group of measured
channels whose values are bit-identical to those of the previous odometry sample is a value
republished (a frozen driver, a dead serial link that resends the last message with fresh
stamps, a slow sensor republished at a faster rate), not a new measurement. The groups, of
which only the measured members count (the ``measured`` setting, a planar vehicle's free
states):

    position (x y z), attitude (phi theta psi), linear velocity (u v w), angular velocity (p q r)

A group of which only one channel is measured is not judged alone (one channel may repeat
legitimately); the groups' lone measured channels are judged together instead (a planar
vehicle: position x y, linear velocity u v, and 'psi, r').

The rule of :class:`StuckDetector`, per group:

- an exact repeat of the group's previous values is NOT FED to the filter (its channels are
  NaN in that update, as unmeasured); when every measured group repeats, the message is
  rejected as ``repeated``. So no repeated value reaches the estimate, whether or not it
  becomes a fault. A whole group is required: a quantised sensor repeats single components
  (depth at 1 cm resolution while level), never x, y and z together while the vehicle moves;
- the repeat becomes a FAULT (a stuck sensor) once the same values have come in at least
  STUCK_SAMPLES (10) consecutive samples spanning at least STUCK_SECONDS (2 s) of stamps. Two
  conditions: a 1 Hz DVL republished at 20 Hz repeats 19 times within 1 s (not a fault),
  a slow stream (a glider at 0.25 Hz) needs 10 samples, not 2 s. While a fault is active the
  session's health is ERROR 'stuck sensor', no update becomes the last good estimate (nothing
  formed then is published or saved), and the session says so once when it starts and once
  when it ends (IdentSession.notices); it ends with the first sample whose group values differ.

A group held for a whole run (a driver that fills only the twist and leaves the orientation
at the identity quaternion, position at zero) is the same fault: never fed after its first
sample, ERROR from STUCK_SECONDS on, and offline the identification NOT consistent naming it
(analysis/bag_identify.py). Set ``measured`` to the channels the sensor really provides.

Not a fault by this rule: a group that changes in any bit. Commands are not measured channels
(drivers publish them on change) and are not judged. A noise-free source whose vehicle holds
a state exactly (a simulator without sensor noise, at rest or at a steady trim) reads as
stuck: give the simulated sensors noise (the package's simulators add it by default).

A sample whose stamp is not after the last fed one is not judged (the stream's time rules
reject it as a duplicate or out of order). The updates between a span's first repeat and the
fault (up to 2 s) may become good: they were formed without the repeats.

Defaults, not settings: 10 samples and 2 s are far beyond any noisy sensor (a repeat of three
noisy floats has probability ~0) and far below the 5 s spans of the faults it is for; the
repeats are not fed from the first one, so the thresholds decide only when ERROR is raised.
"""
from dataclasses import dataclass

from auv_ident.core.model.state import State, STATE_NAMES

STUCK_SAMPLES = 10      # consecutive samples with the same values (the first one included) ...
STUCK_SECONDS = 2.0     # ... spanning at least this many seconds of stamps: a stuck sensor

# the measured channel groups, in the order they are named
CHANNEL_GROUPS = (
    ('position', (State.X, State.Y, State.Z)),
    ('attitude', (State.PHI, State.THETA, State.PSI)),
    ('linear velocity', (State.U, State.V, State.W)),
    ('angular velocity', (State.P, State.Q, State.R)),
)


@dataclass
class StuckSpan:
    """A stuck-sensor fault: the group's name, the stamp (s, session time) of the sample whose
    values were then repeated (the last one fed), the stamp of the last repeat, the repeats
    not fed, and whether it is still going on."""

    group: str
    since: float
    last: float
    repeats: int
    active: bool = True

    @property
    def seconds(self) -> float:
        return self.last - self.since

    def describe(self) -> str:
        return describe_spans([self])


class _Group:
    """One channel group's state: its channels, the values last fed and since when."""

    __slots__ = ('name', 'channels', 'values', 'since', 'repeats', 'span')

    def __init__(self, name, channels):
        self.name = name
        self.channels = channels
        self.values = None      # tuple of the channels' values last seen changed
        self.since = 0.0        # stamp (s) of the sample that brought them
        self.repeats = 0        # samples since that repeated them
        self.span = None        # the active StuckSpan, if any


class StuckDetector:
    """The stuck-sensor rule (module docstring) over the measured channels.

    measured_states : the measured State indices; a group counts those of its members only;
        a group with one measured member is not judged alone: such members form one group
        together (named by their channels, e.g. 'psi, r' for a planar vehicle), judged if
        there are two or more

    Per odometry sample the session asks :meth:`held` which groups repeat, counts them with
    :meth:`repeat` (the whole message rejected when every group is held), feeds the rest and,
    if the filter took the sample, hands it to :meth:`renew`: the values compared with are
    those of the last sample the filter took, so a message re-sent after a rejection (no
    command yet, say) is not a repeat. ``spans`` lists
    every fault since start-up (StuckSpan, the active ones last updated), ``notices`` the
    one-time lines to log (the caller moves them on and clears them)."""

    def __init__(self, measured_states):
        measured = set(measured_states)
        self.groups = []
        singles = []
        for name, channels in CHANNEL_GROUPS:
            ours = tuple(i for i in channels if i in measured)
            if len(ours) >= 2:
                self.groups.append(_Group(name, ours))
            else:
                singles.extend(ours)
        # one measured channel of a group alone may repeat (a quantised heading on a straight
        # course): such channels are judged together (a planar vehicle's psi and r)
        if len(singles) >= 2:
            self.groups.append(_Group(', '.join(STATE_NAMES[i] for i in singles),
                                      tuple(singles)))
        self.spans = []
        self.notices = []
        self.repeats = 0        # group-samples not fed because they repeated

    def held(self, x12):
        """The groups (list of _Group) whose measured values in x12 (a list of 12 floats,
        finite on the measured channels) equal the previous sample's exactly."""
        return [g for g in self.groups
                if g.values is not None and tuple(x12[i] for i in g.channels) == g.values]

    def channels(self, groups):
        """The State indices of these groups' measured channels."""
        return [i for g in groups for i in g.channels]

    def all_held(self, groups):
        return len(groups) == len(self.groups)

    def repeat(self, t, groups):
        """These groups (held()) repeat at stamp t (s) and are not fed: count them, and start
        a fault where the rule says so (said once, one notice for the groups that start
        together)."""
        self.repeats += len(groups)
        started = []
        for g in groups:
            g.repeats += 1
            if g.span is not None:
                g.span.last, g.span.repeats = t, g.repeats
            elif g.repeats + 1 >= STUCK_SAMPLES and t - g.since >= STUCK_SECONDS:
                g.span = StuckSpan(g.name, g.since, t, g.repeats)
                self.spans.append(g.span)
                started.append(g.span)
        if started:
            self.notices.append(
                f'odom: {describe_spans(started)}: a stuck sensor? Its repeats are not fed to '
                'the filter; health ERROR and no estimate taken as good until it changes')

    def faults_among(self, groups):
        """The active faults (StuckSpan) of these groups."""
        return [g.span for g in groups if g.span is not None]

    def renew(self, t, x12, groups):
        """The filter took the sample at stamp t (s), x12 a list of 12 floats, without
        `groups` (held()): the other groups' values are the ones to compare with from now on,
        and a fault of theirs ends (said once)."""
        held = {id(g) for g in groups}
        ended = []
        for g in self.groups:
            if id(g) in held:
                continue
            if g.span is not None:
                g.span.active = False
                ended.append(g.span)
                g.span = None
            values = tuple(x12[i] for i in g.channels)
            # a channel the message did not measure (NaN) leaves nothing to repeat
            g.values = values if all(v == v for v in values) else None
            g.since, g.repeats = t, 0
        if ended:
            self.notices.append(f'odom: changes again at t = {t:.3f} s after '
                                f'{describe_spans(ended)}')

    def active(self):
        """The active faults (StuckSpan), in group order."""
        return [g.span for g in self.groups if g.span is not None]

    def describe_active(self):
        """One clause naming the active faults ('' if none)."""
        return describe_spans(self.active())


def describe_spans(spans):
    """The faults (StuckSpan) in words, groups stuck over the same span named together:
    'position, attitude repeated exactly for 5.0 s from t = 19.950 s (100 samples not fed)';
    '' for none."""
    together = {}
    for span in spans:
        together.setdefault((span.since, span.last, span.repeats), []).append(span.group)
    return '; '.join(f'{", ".join(groups)} repeated exactly for {last - since:.1f} s from t = '
                     f'{since:.3f} s ({repeats} samples not fed)'
                     for (since, last, repeats), groups in together.items())
