"""Simulated-time plumbing shared by the virtual devices: an outbox and a monotonic clock.

Devices never read the wall clock; every time here is the `now_s` a caller handed in.
"""

from __future__ import annotations

import heapq


class Outbox:
    """Bytes a device has scheduled to send, released in order of their simulated send time.

    Messages with the same time keep the order they were put in.
    """

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, bytes]] = []
        self._seq = 0

    def put(self, time_s: float, data: bytes) -> None:
        if data:
            heapq.heappush(self._heap, (time_s, self._seq, data))
            self._seq += 1

    def due(self, now_s: float) -> list[tuple[float, bytes]]:
        """Remove and return every message sent at or before `now_s`."""
        out: list[tuple[float, bytes]] = []
        while self._heap and self._heap[0][0] <= now_s:
            time_s, _, data = heapq.heappop(self._heap)
            out.append((time_s, data))
        return out

    def next_time_s(self) -> float | None:
        return self._heap[0][0] if self._heap else None


class SimClock:
    """The latest simulated time a device was driven at; refuses to go backwards."""

    def __init__(self, device: str) -> None:
        self.device = device
        self.now_s = 0.0

    def advance(self, now_s: float) -> None:
        if now_s < self.now_s:
            raise ValueError(
                f"{self.device}: now_s ({now_s}) must not be earlier than the device's "
                f"clock ({self.now_s})"
            )
        self.now_s = now_s


def earliest(*times_s: float | None) -> float | None:
    """The smallest of the given times, ignoring None; None if all are None."""
    present = [t for t in times_s if t is not None]
    return min(present) if present else None
