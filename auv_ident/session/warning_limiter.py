"""Rate limit for the warnings of rejected messages (the live identifier node's log)."""
from collections import Counter


class WarningLimiter:
    """Rate limit for the warnings of rejected messages: at most one line per key (topic and
    rejection code) per `period` of `clock` (seconds), and that line says how many like it
    were suppressed since the previous one. The identifier node uses it with the steady clock,
    so every distinct problem is named within `period` even while another one floods."""

    def __init__(self, period, clock):
        self.period = float(period)
        self.clock = clock
        self._last = {}
        self.suppressed = Counter()

    def __call__(self, key, text):
        """The line to log now for this occurrence, or None if it is suppressed."""
        now = self.clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period:
            self.suppressed[key] += 1
            return None
        self._last[key] = now
        n = self.suppressed.pop(key, 0)
        if n:
            text += f' ({n} more like it in the last {now - last:.1f} s)'
        return text
