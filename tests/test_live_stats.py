"""tofnet live's statistics: the delays in a fixed histogram (percentiles as np.percentile's within a bin),
so a run of any length keeps them in the same memory."""

import pickle

import numpy as np
import pytest

from tofnet.events import EVENT_DTYPE
from tofnet.io.recording import Intrinsics, Recording
from tofnet.live import run_live
from tofnet.live_stats import DelayHistogram
from tofnet.networks import depth_network
from tofnet.testing import moving_pattern

SENSOR = (64, 48)


def test_delay_percentiles_are_numpy_s_within_a_tenth_of_a_percent():
    rng = np.random.default_rng(1)
    delays = np.concatenate([np.full(5000, 3000.0), rng.lognormal(np.log(4000), 1.0, 200_000),
                             rng.uniform(0.2, 2.0, 30), [7.3e9]])  # the floor, a spread, below 1 µs, hours behind
    rng.shuffle(delays)
    histogram = DelayHistogram()
    for part in np.array_split(delays, 997):  # packet by packet
        histogram.add(part)
    assert histogram.count == len(delays)
    assert histogram.percentile_us(0) == delays.min() and histogram.percentile_us(100) == delays.max()
    for q in (0.1, 1, 10, 50, 90, 99, 99.9, 99.999):
        assert histogram.percentile_us(q) == pytest.approx(np.percentile(delays, q), rel=6e-4), q
    assert np.percentile(delays, 0.001) < histogram.percentile_us(0.001) <= 1.001  # below 1 µs: the first bin
    assert np.isnan(DelayHistogram().percentile_us(50))


class _NeverLate:
    """A texture sliding across a small sensor for ``packets`` 1 ms packets, its clock at each packet's end
    (never late): as many estimates as the machine runs, however slowly."""
    packet_us, t0_us = 1000, 0

    def __init__(self, packets: int):
        self.events = moving_pattern(SENSOR, (300.0, 200.0), 100_000, sample_us=500)
        self.count, self.now = packets, 0.0

    def metadata(self):
        return Recording(events=np.empty(0, EVENT_DTYPE), intrinsics=Intrinsics(50.0, 50.0, 32.0, 24.0),
                         sensor_size=SENSOR, source="synthetic")

    def now_us(self):
        return self.now

    def packets(self):
        t = self.events["t"]
        for i in range(self.count):
            loop, start = divmod(i * 1000, 100_000)
            packet = self.events[np.searchsorted(t, start):np.searchsorted(t, start + 1000)].copy()
            packet["t"] += loop * 100_000
            self.now = (i + 1) * 1000
            yield packet, (i + 1) * 1000


def test_a_ten_times_longer_run_keeps_statistics_of_the_same_size():
    """A list of every delay grew by 140 MB per second of a 20 M events/s source (docs/live.md, *Memory*)."""
    network = depth_network(SENSOR, velocity={"source": "constant", "velocity": [0.5, 0, 0]})
    kept = {}
    for packets in (100, 1000):
        stats, _ = run_live(_NeverLate(packets), network, backend="fixed")
        kept[packets] = (stats.depth_out, len(pickle.dumps(stats)))
    assert kept[1000][0] > 8 * kept[100][0] > 0  # ten times the estimates...
    assert abs(kept[1000][1] - kept[100][1]) < 100  # ...in the same bytes (a few digits of the counts)


def test_the_cpu_share_is_of_the_wall_time_the_replay_takes_at_its_speed():
    """At --speed 0.5 the line said 192 % of one core ("cannot keep up") for a run that kept up."""
    from tofnet.live_stats import LiveStats
    stats = LiveStats(cpu_s=0.958, span_us=500_000)
    stats.speed = 0.5  # 0.5 s of source replayed in 1 s
    cpu = next(line for line in stats.lines() if line.startswith("cpu"))
    assert cpu == ("cpu            0.958 s for 0.5 s of source time replayed at 0.5x in 1 s (96 % of one core; "
                   "above 100 % it cannot keep up)")
    stats.speed = 1.0
    cpu = next(line for line in stats.lines() if line.startswith("cpu"))
    assert "for 0.5 s of source time (192 % of one core" in cpu
