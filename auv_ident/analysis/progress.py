"""A progress bar on stderr, shown only when stderr is a terminal (silent in CI logs)."""
import sys
import time


class Progress:
    def __init__(self, total, label, stream=None):
        self.total = max(1, int(total))
        self.label = label
        self.stream = stream or sys.stderr
        self.enabled = hasattr(self.stream, 'isatty') and self.stream.isatty()
        self.n = 0
        self._last = 0.0

    def update(self, n=1):
        self.n = min(self.total, self.n + n)
        now = time.monotonic()
        if self.enabled and (now - self._last > 0.1 or self.n == self.total):
            self._last = now
            frac = self.n / self.total
            bar = '#' * int(30 * frac)
            self.stream.write(f'\r{self.label} [{bar:<30}] {100 * frac:5.1f}%')
            self.stream.flush()

    def close(self):
        if self.enabled:
            self.stream.write('\r' + ' ' * (len(self.label) + 42) + '\r')
            self.stream.flush()
