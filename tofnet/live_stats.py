"""What a live run measured (``LiveStats``), in memory that does not grow with the run.

The delays are counted in a fixed histogram (``DelayHistogram``), not kept one by one: a list of
every delay grew by ~140 MB per second of a 20 M events/s source (~40 bytes an estimate: ~2 GB an
hour at the real EVT3's 16,000 estimates a second), and a camera run may go on for hours. Docs: docs/live.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


class DelayHistogram:
    """Delays (µs) counted in bins 0.1 % wide, spaced geometrically from 1 µs to 2^40 µs (12.7 days; a delay
    below 1 µs counts in the first bin, one above in the last): 27,700 counts (220 kB) however many delays.

    Why geometric bins rather than exact counts per µs up to a cap: the delays span 3 ms (the floor) to
    hours (a run that fell behind), and a bin 0.1 % wide keeps every percentile within 0.05 % of
    ``np.percentile``'s at any of them; ``min_us`` and ``max_us`` (the 0th and 100th percentiles) are exact."""

    RATIO = 1.001
    BINS = math.ceil(40 * math.log(2) / math.log(RATIO)) + 1

    def __init__(self):
        self.counts = np.zeros(self.BINS, np.int64)
        self.count = 0
        self.min_us, self.max_us = math.inf, -math.inf

    def add(self, delays_us: np.ndarray) -> None:
        """Count the delays (µs) of an array."""
        d = np.asarray(delays_us, dtype=np.float64).ravel()
        if not len(d):
            return
        self.count += len(d)
        self.min_us, self.max_us = min(self.min_us, float(d.min())), max(self.max_us, float(d.max()))
        index = np.log(np.maximum(d, 1.0)) * (1 / math.log(self.RATIO))
        index = np.minimum(index, self.BINS - 1).astype(np.intp)
        low = int(index.min())
        counted = np.bincount(index - low)  # the packet's few bins, not all of them
        self.counts[low:low + len(counted)] += counted

    def percentile_us(self, q: float) -> float:
        """The ``q``-th percentile (0-100, µs) as ``np.percentile`` interpolates it (linear), each order
        statistic taken at its bin's geometric middle (within 0.05 %); NaN without delays."""
        if not self.count:
            return math.nan
        position = q / 100 * (self.count - 1)
        below = math.floor(position)
        value = self._ranked(below)
        if position > below:
            value += (self._ranked(below + 1) - value) * (position - below)
        return value

    def _ranked(self, rank: int) -> float:
        """The ``rank``-th smallest delay (from 0): exact at either end, else its bin's middle."""
        if rank <= 0:
            return self.min_us
        if rank >= self.count - 1:
            return self.max_us
        i = int(np.searchsorted(np.cumsum(self.counts), rank, side="right"))
        return min(max(self.RATIO ** (i + 0.5), self.min_us), self.max_us)


@dataclass
class LiveStats:
    """What a live run measured. Delays in µs on the source's clock."""

    delays: DelayHistogram = field(default_factory=DelayHistogram)
    events_in: int = 0
    packets: int = 0
    late_packets: int = 0
    dropped_events: int = 0
    dropped_packets: int = 0
    max_behind_us: float = 0.0
    behind_us: float = 0.0  # at the last packet
    depth_out: int = 0
    span_us: int = 0  # the source's time covered
    batches: int = 0  # feeds of several late packets at once (``catching_up``)
    wall_s: float = 0.0
    cpu_s: float = 0.0  # this process's CPU time (all threads) during the run
    speed: float = 1.0  # the replay's, times the recorded speed (a camera: 1)
    late_tolerance_us: float | None = None  # with drop_when_late: how late a packet's events are dropped
    interrupted: bool = False  # ended by Ctrl-C (``live._ctrl_c_stops``): the figures cover the run up to it

    def percentile_ms(self, q: float) -> float:
        """The ``q``-th percentile of the delays (ms); NaN without any."""
        return self.delays.percentile_us(q) * 1e-3

    def cpu_percent(self) -> float:
        """The CPU time over the wall time the source's span takes at its speed (source time / speed), in %
        of one core: above 100 % the run cannot keep up."""
        return 100 * self.cpu_s / max(self.span_us * 1e-6 / self.speed, 1e-9)

    def lines(self) -> list[str]:
        rate = self.events_in / self.wall_s if self.wall_s > 0 else 0.0
        out = [f"delay          p50 {self.percentile_ms(50):.2f} ms, p99 {self.percentile_ms(99):.2f} ms, "
               f"max {self.percentile_ms(100):.2f} ms  (event's step start -> estimate handed back, "
               f"{self.delays.count:,} estimates)",
               f"events         {self.events_in:,} in {self.wall_s:.3g} s ({rate:,.0f} events/s) for "
               f"{self.span_us * 1e-6:.3g} s of source time",
               f"cpu            {self.cpu_s:.3g} s for {self.span_us * 1e-6:.3g} s of source time"
               + (f" replayed at {self.speed:g}x in {self.span_us * 1e-6 / self.speed:.3g} s"
                  if self.speed != 1 else "")
               + f" ({self.cpu_percent():.0f} % of one core; above 100 % it cannot keep up)",
               f"packets        {self.packets:,}, late {self.late_packets:,} (fed more than one packet after "
               f"they were complete); behind at most {self.max_behind_us * 1e-3:.1f} ms, at the end "
               f"{self.behind_us * 1e-3:.1f} ms" + (f"; caught up {self.batches:,} times, several packets at once"
                                                     if self.batches else "")]
        if self.interrupted:
            out.append("ended          by Ctrl-C: these figures cover the run up to it")
        if self.dropped_packets:
            out.append(f"dropped        {self.dropped_events:,} events in {self.dropped_packets:,} packets fed more "
                       f"than {self.late_tolerance_us * 1e-3:g} ms late (--drop-when-late, --late-tolerance)")
        return out
