"""Rate limit for the warnings of rejected messages (the live identifier node's log)."""
from collections import Counter
from collections.abc import Callable, Hashable


class WarningLimiter:
    """Rate limit for the warnings of rejected messages: at most one line per key (topic and
    rejection code) per `period` of `clock` (seconds), and that line says how many like it
    were suppressed since the previous one. The identifier node uses it with the steady clock,
    so every distinct problem is named within `period` even while another one floods."""

    def __init__(self, period: float, clock: Callable[[], float]) -> None:
        self.period = float(period)
        self.clock = clock
        self._last: dict[Hashable, float] = {}
        self.suppressed: Counter[Hashable] = Counter()

    def __call__(self, key: Hashable, text: str) -> str | None:
        """The line to log now for this occurrence, or None if it is suppressed."""
        now = self.clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period:
            self.suppressed[key] += 1
            return None
        self._last[key] = now
        n = self.suppressed.pop(key, 0)
        if n and last is not None:          # suppressed ones follow a logged one
            text += f' ({n} more like it in the last {now - last:.1f} s)'
        return text
