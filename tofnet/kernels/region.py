"""Streaming state of the time-of-travel units and depth neurons of one rectangular region.

The API every event-driven backend uses: the full-sensor ``fixed`` and ``float``
backends run one region covering the sensor; a multi-core backend runs one
``TimeOfTravelKernel`` per compiled core, feeding each the spikes ``Region.feeds`` selects.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE, TOT_DTYPE
from tofnet.kernels import time_of_travel as tt
from tofnet.kernels.kernel_config import (MAX_VELOCITY_ROWS, KernelConfig, KernelOutput, Region,  # noqa: F401
                                          VelocityRows, _sample_tables, copy_records, velocity_rows)
from tofnet.kernels.input_filter import ACCEPTED, NEVER
from tofnet.kernels.order import WORDS as ORDER_WORDS, sort_by_pixel


def _as_array(values, kept: tuple, dtype) -> np.ndarray:
    """``values`` itself when a numpy array of one of the ``kept`` types, else a contiguous ``dtype`` copy."""
    if isinstance(values, np.ndarray) and values.ndim == 1 and values.dtype in kept:
        return values
    return np.ascontiguousarray(values, dtype=dtype)


#: The error of a packet out of time order (refused; nothing changed).
UNSORTED = ("events are not sorted by time (input spikes: by step): each packet must be in time order and follow "
            "the previous one; it was refused and the state is unchanged")


class TimeOfTravelKernel:
    """Units and depth neurons of one region, fed accepted spikes or raw events packet by packet.

    Memory is fixed by the region (one record of 32 B, 64 B with a refractory period per
    polarity, per pixel; a buffer of one step's facilitations) plus output buffers as
    large as the largest packet; it does not grow with the recording.
    """

    def __init__(self, config: KernelConfig, region: Region | None = None, t0_us: int = 0):
        config.check()
        self.config = config
        self.region = region if region is not None else Region.full(config.sensor_size)
        r, (width, height) = self.region, config.sensor_size
        if not (0 <= r.x0 < r.x1 <= width and 0 <= r.y0 < r.y1 <= height):
            raise BackendError(f"region {r} is not a non-empty part of the {width}x{height} sensor")
        (h, w), d, depth, flt = r.shape, config.units.distance, config.neurons, config.input_filter
        stride = tt.WORDS_PER_POLARITY if flt.per_polarity else tt.WORDS
        rows, cols, points = _sample_tables(config, r)
        n_samples, rec_size = len(points), (h + 4 * d) * (w + 4 * d) * stride
        sizes = {tt.AT_CURSOR: tt.N_CURSOR, tt.AT_COUNTS: tt.N_COUNTS, tt.AT_ROWS: h, tt.AT_COLS: w,
                 tt.AT_CACHE_J: n_samples, tt.AT_CACHE_W: 2 * n_samples,
                 tt.AT_PEND: (w + 2 * d) * (h + 2 * d)}  # at most one spike per pixel and step
        at = {slot: tt.N_IP + sum(list(sizes.values())[:i]) for i, slot in enumerate(sizes)}
        self._ints = ints = np.zeros(at[tt.AT_PEND] + sizes[tt.AT_PEND] + rec_size + 8, dtype=np.int64)
        start = at[tt.AT_PEND] + sizes[tt.AT_PEND]
        start += (-(ints.ctypes.data + 8 * start) % 64) // 8  # records on cache-line boundaries
        ip = ints[:tt.N_IP]
        for slot, offset in at.items():
            ip[slot] = offset
        ip[[tt.N_SAMPLES, tt.PEND_SIZE, tt.AT_REC, tt.REC_SIZE]] = n_samples, sizes[tt.AT_PEND], start, rec_size
        ip[tt.EMIT_DEPTH] = int(config.emit_depth)
        ip[[tt.X0, tt.Y0, tt.X1, tt.Y1, tt.DISTANCE, tt.COUNTER_MAX, tt.REBASE_AT, tt.UPDATE_EVERY]] = (
            r.x0, r.y0, r.x1, r.y1, d, config.counter_max, tt.REBASE_AFTER, config.update_every)
        fmt = config.fixed
        if fmt is not None:
            ip[[tt.FIXED, tt.FRAC_BITS, tt.PAYLOAD_BITS, tt.MIN_RAW, tt.MAX_RAW]] = (
                1, fmt.frac_bits, fmt.payload_bits, fmt.quantize(depth.min_depth), fmt.quantize(depth.max_depth))
        ip[[tt.T0, tt.DT, tt.REFRACTORY_US, tt.PER_POLARITY, tt.WIDTH, tt.HEIGHT, tt.STRIDE, tt.ROW]] = (
            t0_us, config.timestep_us, flt.refractory_us, flt.per_polarity, width, height,
            stride, w + 4 * d)
        self._floats = np.concatenate([[*depth.intrinsics, config.seconds_per_count, depth.min_depth,
                                        depth.max_depth], points.ravel(), np.zeros(2 * n_samples)])
        (self._ip, self._cursor, self._counts, self._rows, self._cols, cache_j, _, self._pend, self._rec,
         *_) = tt.views(self._ints, self._floats)
        self._rows[:], self._cols[:] = rows, cols
        cache_j[:] = -1  # no velocity update cached yet
        self._cursor[[tt.CURRENT, tt.T_HI]] = -1, NEVER
        self._rec[:] = NEVER
        self._stamp = self._rec.view(np.int32)
        self._stamp.reshape(-1, 2 * stride)[:, :4] = tt.IDLE
        self.rejected = self._counts[tt.REJECTED:tt.EMITTED]  # the rejection reasons' order (a view)
        self._out, self._raw, self._tot = np.empty(0, DEPTH_DTYPE), np.empty(0, np.int64), np.empty(0, TOT_DTYPE)
        self._broken = False
        # Scalars and empty arrays the per-packet path needs, looked up once.
        self._t0, self._dt, self._u = int(t0_us), config.timestep_us, config.update_every
        self._span_us = (MAX_VELOCITY_ROWS - 2) * config.update_every * config.timestep_us
        self._band = None if self.region == Region.full(config.sensor_size) else r.kinds(d)  # ``tt.process``' band
        self._no_raw, self._no_velocity = np.empty(0, np.int64), np.zeros((0, 3))
        self._held_velocity = np.zeros(4)
        self._held_omega = np.zeros(3)  # rad/s: no rotation before the first angular velocity update
        # eq. 7: (min_share, min_share_raw, fx, fy, cx, cy of B ω); empty for eq. 8
        self._rotation = np.zeros(0) if depth.min_share is None else np.array(
            [depth.min_share, float(fmt.quantize(depth.min_share) if fmt is not None else 0),
             *(depth.rotation_intrinsics or depth.intrinsics)])
        self._scratch = np.empty((0, ORDER_WORDS), np.uint32)  # the canonical sort's (kernels/order.py)
        self._row_start = np.zeros(config.sensor_size[1] + 1, np.int64)

    @property
    def t0_us(self) -> int:
        """Start of input step 0 (µs): the depth stamps and the input filter's steps count from it."""
        return self._t0

    @t0_us.setter
    def t0_us(self, value: int) -> None:
        self._t0 = self._ip[tt.T0] = int(value)

    @property
    def _rebase_after(self) -> int:
        return int(self._ip[tt.REBASE_AT])

    @_rebase_after.setter
    def _rebase_after(self, steps: int) -> None:  # tests rebase often
        self._ip[tt.REBASE_AT] = steps

    @property
    def tot_spikes(self) -> int:
        """Time-of-travel spikes sent so far."""
        return int(self._counts[tt.TOT_SPIKES])

    @property
    def accepted(self) -> int:
        """Events ``process_events`` accepted so far."""
        return int(self._counts[ACCEPTED])

    @property
    def drops(self) -> np.ndarray:
        """Events ``process_events`` dropped so far, by drop slot (a view)."""
        return self._counts[:ACCEPTED]

    def _reserve(self, n_out: int, n_spikes: int) -> None:
        """Room for ``n_out`` estimates and the time-of-travel spikes of ``n_spikes`` input spikes."""
        if n_out > len(self._out):  # reused across calls, grown geometrically
            size = max(n_out, 2 * len(self._out))
            self._out, self._raw = np.empty(size, DEPTH_DTYPE), np.empty(size, np.int64)
        if 4 * n_spikes > len(self._tot):
            self._tot = np.empty(max(4 * n_spikes, 2 * len(self._tot)), TOT_DTYPE)

    def _call(self, ts, xs, ys, ps, filtering: bool, table: np.ndarray, first_update: int,
              out: np.ndarray, raw: np.ndarray, n_out: int, record_tot: bool, n_tot: int) -> tuple[int, int, int]:
        return tt.process(ts, xs, ys, ps, filtering, self._ints, self._floats, table, first_update, out, raw, n_out,
                          record_tot, self._tot, n_tot, None, self._band)

    def _raise_for(self, status: int, table: np.ndarray, first_update: int) -> None:
        if status == tt.NO_VELOCITY:
            first, last = ((int(self._cursor[slot]) + 1) // self._u for slot in (tt.NEED_FIRST, tt.NEED_LAST))
            raise BackendError(f"velocity table holds updates [{first_update}, {first_update + len(table)}); "
                               f"these spikes need [{first}, {last + 1})")
        if status == tt.UNSORTED:
            raise BackendError(UNSORTED)
        if status == tt.PENDING_FULL:
            self._broken = True
            raise BackendError("more than one input spike for one pixel in one step "
                               "(feed the spikes InputFilter accepted)")

    def _output(self, out: np.ndarray, raw: np.ndarray, lo: int, hi: int, n_tot: int, record_tot: bool,
                spikes_before: int, copy: bool) -> KernelOutput:
        depth, z_raw = out[lo:hi], raw[lo:hi] if len(raw) else raw
        tot = self._tot[:n_tot] if record_tot else None
        if copy:
            depth, z_raw = copy_records(depth), z_raw.copy()
            tot = copy_records(tot) if record_tot else None
        return KernelOutput(depth, z_raw, tot, int(self._counts[tt.TOT_SPIKES]) - spikes_before)

    def process(self, steps: np.ndarray, xs: np.ndarray, ys: np.ndarray, ps: np.ndarray,
                velocity_table: np.ndarray, first_update: int, *, record_tot: bool = False,
                copy: bool = True) -> KernelOutput:
        """Run accepted input spikes (input step, x, y, polarity) through the region.

        Spikes must be sorted by step and continue the previous call's; at most one per
        pixel and step (what ``InputFilter.feed`` returns). Spikes from anywhere on the
        sensor are accepted; those that neither trigger nor facilitate here are ignored.
        ``velocity_table[j - first_update]`` is the camera velocity (m/s, camera frame) of
        update ``j`` and must cover ``velocity_rows(steps, update_every)``; the same update
        must get the same row in every call (``A t`` is cached per update). ``copy=False``
        returns views of internal buffers, valid until the next call.
        """
        if self._broken:
            raise BackendError("kernel state is invalid after an earlier error; start a new one")
        spikes_before = self.tot_spikes
        # the fields of spike records (int64 steps, uint16 pixels) go in as they are, strided
        # views included, with the types the fused kernel reads events with: no copies
        steps = _as_array(steps, (np.int64,), np.int64)
        xs, ys = _as_array(xs, (np.uint16, np.int64), np.int64), _as_array(ys, (np.uint16, np.int64), np.int64)
        ps = _as_array(ps, (np.uint8,), np.uint8)
        table = np.ascontiguousarray(velocity_table, dtype=np.float64)
        self._reserve(len(steps), len(steps) if record_tot else 0)
        n_out, n_tot, status = self._call(steps, xs, ys, ps, False, table, first_update, self._out, self._raw, 0,
                                          record_tot, 0)
        self._raise_for(status, table, first_update)
        self._order(self._out, self._raw, 0, n_out)
        return self._output(self._out, self._raw, 0, n_out, n_tot, record_tot, spikes_before, copy)

    def process_events(self, events: np.ndarray, velocity: VelocityRows, *, record_tot: bool = False,
                       copy: bool = True, into: np.ndarray | None = None, offset: int = 0) -> KernelOutput:
        """Run raw events (``EVENT_DTYPE``) through the input filter and the region, in one pass.

        The filter's state (refractory period, one event per pixel and step, drop counts:
        ``drops``, ``accepted``) lives in the kernel. A region smaller than the sensor (a band,
        ``tofnet.backends.bands``) filters the events of its halo too but counts only its own
        pixels' (and those outside the sensor in its rows or past the sensor's last row, which
        only the first band is given); events beyond its halo are skipped.
        Events the filter may accept must be in time order, also across calls; a packet
        that is not is refused before any state changes. ``velocity`` supplies velocity
        rows (``VelocityRows``). Estimates go to ``into[offset:]`` when given (capacity
        ``offset + len(events)``; no ``z_raw``), else to an internal buffer.
        """
        spikes_before = int(self._counts[tt.TOT_SPIKES])
        end, n_tot = self.run_events(events, velocity, into, offset, record_tot)
        if into is None:
            return self._output(self._out, self._raw, 0, end, n_tot, record_tot, spikes_before, copy)
        return self._output(into, self._no_raw, offset, end, n_tot, record_tot, spikes_before, copy)

    def run_events(self, events: np.ndarray, velocity: VelocityRows, into: np.ndarray | None = None,
                   offset: int = 0, record_tot: bool = False, span: tuple[int, int] | None = None,
                   canonical: bool = True, index: np.ndarray | None = None) -> tuple[int, int]:
        """``process_events`` without the ``KernelOutput`` (the per-packet path of a stream).

        Returns the end of the estimates in ``into`` (from ``offset``), or in ``buffers()[0]``
        (from 0) when ``into`` is None, and how many time-of-travel spikes ``buffers()[2]`` holds.
        ``span``: the packet's first and last event times (µs) when the caller has them already.
        ``canonical=False`` leaves the estimates in the order of their trigger events (a live
        stream's caller who does not need each step in pixel order spares the sort). ``index``
        (int64, increasing): only those events run (a band's, ``kernels.bands.select_rows``, which has
        checked the packet's time order over all its events: every band refuses the same packets).
        """
        if self._broken:
            raise BackendError("kernel state is invalid after an earlier error; start a new one")
        n = len(events)
        if into is None:
            if n > len(self._out) or (record_tot and 4 * n > len(self._tot)):
                self._reserve(n, n if record_tot else 0)
            out, raw, offset = self._out, self._raw, 0
        else:
            if len(into) < offset + n:
                raise BackendError(f"output buffer holds {len(into)} estimates, {offset + n} may be written")
            if record_tot and 4 * n > len(self._tot):
                self._reserve(0, n)
            out, raw = into, self._no_raw
        if n == 0:
            return offset, 0
        if len(self._scratch) < n:  # the kernel sorts a call's estimates (at most one per event)
            self._scratch = np.empty((max(n, 2 * len(self._scratch)), ORDER_WORDS), np.uint32)
        if span is None:
            t = events["t"]
            span = int(t[0]), int(t[-1])
        first, last = span
        if last - first < self._span_us:  # one velocity table is enough (the usual case)
            n_out, n_tot = self._events(events, first, last, velocity, out, raw, offset, record_tot, 0, canonical,
                                        index)
            if canonical and len(raw):  # the kernel sorts estimates alone; with their fixed-point values, here
                self._order(out, raw, offset, n_out)
            return n_out, n_tot
        n_out, n_tot = offset, 0
        for lo, hi in self._pieces(events["t"]):
            piece = events[lo:hi]
            part = None if index is None else index[np.searchsorted(index, lo):np.searchsorted(index, hi)] - lo
            n_out, n_tot = self._events(piece, int(piece["t"][0]), int(piece["t"][-1]), velocity, out, raw, n_out,
                                        record_tot, n_tot, False, part)
        if canonical:
            self._order(out, raw, offset, n_out)  # a step may run across pieces
        return n_out, n_tot

    def _order(self, out: np.ndarray, raw: np.ndarray, lo: int, hi: int) -> None:
        """Put the estimates ``out[lo:hi]`` of each step in pixel order (the canonical order)."""
        if hi - lo < 2:
            return
        if len(raw):  # keep z_raw with its estimate: sort positions, then both arrays
            order = np.lexsort((out["x"][lo:hi], out["y"][lo:hi], out["step"][lo:hi]))
            out[lo:hi], raw[lo:hi] = out[lo:hi][order], raw[lo:hi][order]
            return
        if len(self._scratch) < hi - lo:
            self._scratch = np.empty((max(hi - lo, 2 * len(self._scratch)), ORDER_WORDS), np.uint32)
        sort_by_pixel(out, lo, hi, self.config.sensor_size[1], self._scratch, self._row_start)

    def join_packets(self, depth: np.ndarray, seams: list[int]) -> np.ndarray:
        """Estimates of consecutive calls (each in canonical order), put in canonical order in place:
        only a step that runs across a seam (the offset where a call's estimates began) is sorted."""
        step = depth["step"]
        for seam in seams:
            if 0 < seam < len(depth) and step[seam - 1] == step[seam]:
                self._order(depth, self._no_raw, *_run_around(step, seam))
        return depth

    def promise(self, until_us: int) -> None:
        """No event before ``until_us`` will come: a later packet that starts earlier is refused."""
        self._cursor[tt.T_HI] = max(int(self._cursor[tt.T_HI]), int(until_us))

    def buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The internal output buffers: estimates, their fixed-point values, time-of-travel spikes."""
        return self._out, self._raw, self._tot

    def _updates(self, first_step: int, last_step: int) -> tuple[int, int]:
        """``(first_update, n_updates)`` the depth neurons of input steps ``first_step .. last_step`` hold."""
        first = (first_step + 1) // self._u
        return first, max((last_step + 1) // self._u - first + 1, 1)

    def _pieces(self, t: np.ndarray) -> Iterator[tuple[int, int]]:
        """Split time-ordered events so that no piece needs more than ``MAX_VELOCITY_ROWS`` velocity rows."""
        t0, dt, u, lo, n = self._t0, self._dt, self._u, 0, len(t)
        while lo < n:
            first = ((max(int(t[lo]), t0) - t0) // dt + 1) // u
            cut = t0 + ((first + MAX_VELOCITY_ROWS) * u - 1) * dt  # first time whose update is first + MAX
            hi = n if int(t[n - 1]) < cut else max(int(np.searchsorted(t[lo:], cut)) + lo, lo + 1)
            yield lo, hi
            lo = hi

    def _events(self, events, first_t: int, last_t: int, velocity: VelocityRows, out, raw, n_out: int,
                record_tot: bool, n_tot: int, canonical: bool, index: np.ndarray | None = None) -> tuple[int, int]:
        """One piece of ``run_events`` (``first_t``, ``last_t``: its first and last event times;
        ``canonical``: the kernel sorts the piece's estimates; ``index``: the events that run)."""
        t0 = self._t0
        if last_t >= t0:  # rows for every event from the first to the last (exact when in order)
            table, first = velocity(*self._updates((max(first_t, t0) - t0) // self._dt, (last_t - t0) // self._dt))
        else:
            table, first = self._no_velocity, 0
        n_out2, n_tot2, status = tt.process_events(events, self._ints, self._floats, table, first, out, raw, n_out,
                                                   record_tot, self._tot, n_tot, self._scratch, self._row_start,
                                                   canonical, index, self._band)
        if status == tt.OK:
            return n_out2, n_tot2
        if status == tt.NO_VELOCITY:  # events out of time order outside the sensor: ask for what is needed
            table, first = velocity(*self._updates(int(self._cursor[tt.NEED_FIRST]), int(self._cursor[tt.NEED_LAST])))
            n_out2, n_tot2, status = tt.process_events(events, self._ints, self._floats, table, first, out, raw,
                                                       n_out, record_tot, self._tot, n_tot, self._scratch,
                                                       self._row_start, canonical, index, self._band)
        self._raise_for(status, table, first)
        return n_out2, n_tot2

    def process_counts(self, counts: np.ndarray, velocity: np.ndarray, rotation: np.ndarray | None = None
                       ) -> np.ndarray:
        """Depth estimates (``DEPTH_DTYPE``, a copy) of counter spikes, the depth layer alone.

        ``counts`` (``TOT_DTYPE``) sorted by step with each pixel's spikes of a step together;
        ``velocity`` the ``velocity_term`` updates (``step``, ``tx``, ``ty``, ``tz``) sent over
        the same steps, sorted by step; ``rotation`` likewise the ``rotation_term`` updates
        (``step``, ``wx``, ``wy``, ``wz``) when the config has ``min_share`` (eq. 7). See
        ``depth_counts.depth_from_counts``.
        """
        from tofnet.kernels.depth_counts import depth_from_counts

        if self._broken:
            raise BackendError("kernel state is invalid after an earlier error; start a new one")
        n = len(counts)
        self._reserve(n, 0)
        v_t = np.empty((len(velocity), 3))
        if len(velocity):
            v_t[:, 0], v_t[:, 1], v_t[:, 2] = velocity["tx"], velocity["ty"], velocity["tz"]
        if (rotation is not None) != (self.config.neurons.min_share is not None):
            raise BackendError("angular velocity updates need a kernel configured with min_share (eq. 7), "
                               "and such a kernel needs them" if rotation is not None else
                               "this kernel computes eq. 7 (min_share is set): pass the angular velocity updates")
        w_omega = np.empty((0 if rotation is None else len(rotation), 3))
        w_step = np.zeros(0, np.int64) if rotation is None else np.ascontiguousarray(rotation["step"])
        if rotation is not None and len(rotation):
            w_omega[:, 0], w_omega[:, 1], w_omega[:, 2] = rotation["wx"], rotation["wy"], rotation["wz"]
        # the counter spikes as records (the kernel reads their fields in place) and the updates' steps
        # contiguous (a few): the same argument types whatever the number of either (one compiled signature)
        n_out, status = depth_from_counts(
            np.ascontiguousarray(counts, dtype=TOT_DTYPE), np.ascontiguousarray(velocity["step"], dtype=np.int64), v_t,
            self._held_velocity, w_step, w_omega, self._held_omega, self._rotation, self._ints, self._floats,
            self._out, self._raw, 0)
        if status:
            raise BackendError("counter spikes are not sorted by step")
        return copy_records(self._out[:n_out])

    @property
    def outcomes(self) -> np.ndarray:
        """Depth neurons reached so far by outcome: the rejection reasons, then emitted (a view)."""
        return self._counts[tt.REJECTED:tt.EMITTED + 1]

    def unit_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Per unit of the region (``[H, W, 4]``): step of its last facilitation (-1: idle) and polarity.

        For tests and debugging; facilitations of a step still buffered are not included.
        """
        d = self.config.units.distance
        h, w = self.region.shape
        stamps = self._stamp.reshape(h + 4 * d, w + 4 * d, -1)[2 * d:2 * d + h, 2 * d:2 * d + w, :4]
        stamp = stamps.astype(np.int64)
        idle = stamp == tt.IDLE
        step = np.where(idle, -1, (stamp >> 1) + self._cursor[tt.BASE])
        return step, np.where(idle, 0, stamp & 1).astype(np.int8)

    @property
    def current_step(self) -> int:
        """Input step of the latest spike processed (-1 before the first)."""
        return int(self._cursor[tt.CURRENT])


def _run_around(step: np.ndarray, at: int) -> tuple[int, int]:
    """``(lo, hi)``: the records of ``step[at]``'s step in ``step`` (sorted); only a window
    around ``at`` is searched, as ``step`` is a strided field that a search would copy whole."""
    value, n, width = step[at], len(step), 256
    while at - width > 0 and step[at - width] == value:
        width *= 2
    lo = max(at - width, 0)
    lo += int(np.searchsorted(step[lo:at], value, "left"))
    width = 256
    while at + width < n and step[at + width] == value:
        width *= 2
    hi = at + int(np.searchsorted(step[at:min(at + width, n)], value, "right"))
    return lo, hi
