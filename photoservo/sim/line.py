"""The serial line between host and bridge as the emulator models it (sim/emulator.py): byte
pacing at a baud rate and fault injection (dropped, corrupted, stalled bytes), one direction each.

Times are `time.monotonic()` seconds; probabilities are per byte.
"""

from __future__ import annotations

import time
from collections import deque

import numpy as np


class FaultInjector:
    """One direction of a faulty line: each byte is dropped with probability `drop`, has a
    random bit pattern XORed in with probability `corrupt`, and with probability `delay` stalls
    the stream (that byte and all after it) by `delay_ms`. Order is always kept."""

    def __init__(self, drop: float, corrupt: float, delay: float, delay_ms: float,
                 rng: np.random.Generator) -> None:
        self.drop, self.corrupt, self.delay, self.delay_s = drop, corrupt, delay, delay_ms / 1000
        self.rng = rng
        self._queue: deque[tuple[float, bytes]] = deque()
        self._last_release = 0.0
        self.dropped = self.corrupted = self.delays = 0

    @property
    def active(self) -> bool:
        return bool(self.drop or self.corrupt or self.delay)

    def push(self, data: bytes, now: float) -> None:
        if not data:
            return
        if not self.active:
            self._queue.append((max(now, self._last_release), data))
            return
        a = np.frombuffer(data, np.uint8).copy()
        u = self.rng.random((3, a.size))
        flip = u[1] < self.corrupt
        if flip.any():
            a[flip] ^= self.rng.integers(1, 256, int(flip.sum()), dtype=np.uint8)
            self.corrupted += int(flip.sum())
        stall = u[2] < self.delay
        keep = u[0] >= self.drop
        self.dropped += int((~keep).sum())
        cuts = np.flatnonzero(stall)
        release = max(now, self._last_release)
        start = 0
        for c in list(cuts) + [a.size]:
            part = a[start:c][keep[start:c]].tobytes()
            if part:
                self._queue.append((release, part))
            if c < a.size:
                self.delays += 1
                release += self.delay_s
            start = c
        self._last_release = release

    def pop(self, now: float) -> bytes:
        out = bytearray()
        while self._queue and self._queue[0][0] <= now:
            out += self._queue.popleft()[1]
        return bytes(out)

    def queued_bytes(self) -> int:
        """Bytes accepted by push() and not yet released by pop()."""
        return sum(len(b) for _, b in self._queue)

    def next_release(self) -> float | None:
        return self._queue[0][0] if self._queue else None


class Pacer:
    """Token bucket: bytes may pass at baud/10 per second (8N1). Unused capacity is kept up to
    `burst` bytes (a UART FIFO / DMA buffer), so a loop that wakes late does not lose line time."""

    def __init__(self, baud: int, burst: int = 256) -> None:
        self.rate = baud / 10.0
        self.burst = burst
        self.tokens = float(burst)
        self.t = time.monotonic()

    def allow(self, now: float) -> int:
        if self.rate <= 0:
            return 1 << 16
        self.tokens = min(self.burst, self.tokens + (now - self.t) * self.rate)
        self.t = now
        return int(self.tokens)

    def spend(self, n: int) -> None:
        if self.rate > 0:
            self.tokens -= n

    def wait_for(self, n: int) -> float:
        """Seconds until `n` bytes may pass."""
        if self.rate <= 0:
            return 0.0
        return max(0.0, (min(n, self.burst) - self.tokens) / self.rate)
