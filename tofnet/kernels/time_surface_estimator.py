"""Streaming time-surface depth estimator: configuration, state and packet API (numba core: ``time_surface``).

Feed time-ordered event packets, split anywhere; the output does not depend on the split.
Each emitted estimate is a ``DEPTH_DTYPE`` record stamped like every depth record
(``step`` = the event's input step + ``latency_steps``, ``t`` = end of that step, µs) plus
a ``QUALITY_DTYPE`` record with the event's own time (µs, unquantised), the fit's points,
rms residual and gradient, and the index of the event in the stream.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np

from tofnet.errors import BackendError
from tofnet.events import DEPTH_DTYPE
from tofnet.kernels.cache_hints import line_aligned_full
from tofnet.kernels import time_surface as ts
from tofnet.kernels.time_surface_first import B_FITTED, B_HOLD, B_LAST, N_B, N_B_LAYERED
from tofnet.kernels.time_surface_fit import N_L
from tofnet.kernels.time_surface_travel import N_R, N_S, NOT_YET, RING
from tofnet.kernels.kernel_config import microseconds
from tofnet.kernels.lens import SAMPLE_COLUMNS, Lens, sample_table

#: Per estimate, aligned with the depth records: event time µs, points kept by the fit,
#: their rms distance from the plane (px), the gradient ∇T (s/px), the event's index in the stream, the
#: reason (``record_rejected``) and the event's index in its edge's burst (0 but with ``burst_surfaces`` > 1).
QUALITY_DTYPE = np.dtype([("t_event", "<i8"), ("points", "<u2"), ("rms_px", "<f4"), ("gx", "<f4"), ("gy", "<f4"),
                          ("index", "<i8"), ("reason", "u1"), ("burst", "u1")])

#: ``rows(first_update, n_updates) -> (table, table_first)``: camera velocity per update, row ``i``
#: is update ``table_first + i``; 3 columns (tx, ty, tz m/s) or 6 (+ wx, wy, wz rad/s, camera frame).
VelocityRows = Callable[[int, int], tuple[np.ndarray, int]]
#: What the fit's surface is over: the camera's travel at the first events' times, or the times themselves.
COORDINATES = ("time", "travel")
MAX_VELOCITY_ROWS = 1 << 16


@dataclass(frozen=True)
class TimeSurfaceConfig:
    """Parameters of the estimator (plain data, picklable).

    Times in seconds (the clock, ``timestep_us``, in whole µs), lengths in pixels (px), depths
    in metres; "the time a surface at depth D takes per pixel" is ``D / |A t|`` seconds at the
    event's pixel. What each field does, its unit, default and what it was chosen on:
    docs/time_surface.md, section 3 (the rules it enters: section 1). ``sensor_size`` (width, height) px; ``intrinsics`` and
    ``rotation_intrinsics`` ``(fx, fy, cx, cy)`` px.
    """

    sensor_size: tuple[int, int]
    intrinsics: tuple[float, float, float, float]
    radius: int = 3
    window: float = 0.0
    window_depth: float = 10.0
    min_points: int = 8
    outlier_px: float = 0.25
    iterations: int = 2
    max_rms_px: float = 0.25
    min_spread: float = 0.5
    refractory: float = 0.0
    refractory_depth: float = 10.0
    hold_px: float = 3.0
    burst_ratio: float = 4.0
    hold_fit_rms_px: float = 0.5
    behind_depth: float = 10.0
    window_px: float = 6.0
    max_hold: float = 1.0
    ahead_px: float = -0.5
    turn: float = 0.2
    trim_px: float = 0.0
    model: str = "rows"
    coordinates: str = "travel"
    consistency: float = 0.0
    consistency_window: float = 0.25
    min_depth: float = 0.05
    max_depth: float = 20.0
    min_denominator: float = 0.1
    max_turn: float = 60.0
    burst_surfaces: int = 4
    burst_fit: str = "emitted"
    timestep_us: int = 1000
    latency_steps: int = 1
    update_every: int = 1
    per_pixel: bool = True
    patch_size: int = 30
    rotation_intrinsics: tuple[float, float, float, float] | None = None
    lens: Lens | None = None

    def __post_init__(self) -> None:
        problems = []
        if self.model not in ts.MODELS:
            problems.append(f"model: expected one of {ts.MODELS}, got {self.model!r}")
        if self.coordinates not in COORDINATES:
            problems.append(f"coordinates: expected one of {COORDINATES}, got {self.coordinates!r}")
        if self.coordinates == "travel" and int(self.radius) < 2:
            problems.append(f"coordinates: travel needs radius >= 2 (two pixels behind), got radius {self.radius!r}")
        if self.burst_fit not in ts.BURST_FITS:
            problems.append(f"burst_fit: expected one of {ts.BURST_FITS}, got {self.burst_fit!r}")
        if not 1 <= int(self.burst_surfaces) <= 16:
            problems.append(f"burst_surfaces: expected an integer 1 .. 16, got {self.burst_surfaces!r}")
        for name in ("radius", "min_points", "update_every", "patch_size", "latency_steps"):
            if int(getattr(self, name)) < 1:
                problems.append(f"{name}: expected an integer >= 1, got {getattr(self, name)!r}")
        for name in ("iterations",):
            if int(getattr(self, name)) < 0:
                problems.append(f"{name}: expected an integer >= 0, got {getattr(self, name)!r}")
        for name in ("window", "window_depth", "outlier_px", "max_rms_px", "min_spread", "refractory",
                     "refractory_depth", "consistency", "consistency_window", "min_depth", "hold_px",
                     "max_hold", "hold_fit_rms_px", "behind_depth", "window_px"):
            if not float(getattr(self, name)) >= 0:
                problems.append(f"{name}: expected a number >= 0, got {getattr(self, name)!r}")
        if not 1 <= float(self.max_turn) <= 180:
            problems.append(f"max_turn: expected degrees from 1 to 180, got {self.max_turn!r}")
        if not float(self.burst_ratio) >= 1:
            problems.append(f"burst_ratio: expected a number >= 1, got {self.burst_ratio!r}")
        if not int(self.timestep_us) >= 1:
            problems.append(f"timestep_us: expected whole µs >= 1, got {self.timestep_us!r}")
        if not self.max_depth > self.min_depth:
            problems.append(f"max_depth ({self.max_depth:g} m) must exceed min_depth ({self.min_depth:g} m)")
        for name in ("behind_depth", "window_px"):
            if getattr(self, name) > 0 and int(self.radius) < 2:
                problems.append(f"{name}: needs radius >= 2 (two pixels behind), got radius {self.radius!r}")
        if self.window <= 0 and self.window_depth <= 0:
            problems.append("window: give window (s) or window_depth (m) > 0")
        if problems:
            raise BackendError("time surface: " + "; ".join(problems))

    def replace(self, **changes) -> "TimeSurfaceConfig":
        return TimeSurfaceConfig(**{**asdict(self), **changes})


def cos_turn(max_turn_deg: float) -> float:
    """``max_turn`` (degrees) as the kernel takes it (``time_surface.F_COS_TURN``): its cosine, exactly 0 at 90°
    and beyond (the window stops where the image motion along ``f`` reverses, as without the bound)."""
    return 0.0 if max_turn_deg >= 90.0 else math.cos(math.radians(max_turn_deg))


def reach(depth_m: float) -> float:
    """A depth (m) as the kernel takes it (``time_surface.F_*_REACH``): times 1e6 µs/s, so that over
    ``|A t|`` (px m/s) it is the time in µs a surface that deep takes per pixel."""
    return depth_m * 1e6


class TimeSurfaceEstimator:
    """One sensor's time-surface state; ``feed`` packets of ``EVENT_DTYPE`` events in time order.

    ``t0_us`` is the start of input step 0 (µs); None takes the first event's time.
    ``rows`` ``(y0, y1)``: a band of rows (``tofnet.backends.bands``) whose events this
    estimator counts and answers, holding the state of ``radius`` rows more either side, whose
    events build the surface its fits read (the first-event rule reads a pixel's own events
    only, so the band's output is the whole sensor's for its rows); it is fed its rows' events and at
    least the first event of every step within the sensor (they move its clock: the travel ring and
    the motion epochs; ``tofnet.kernels.bands.clocked_columns``), or every event (quality's ``index``
    counts the events it was fed).
    Memory is fixed by the rows held (about 96 B per pixel; with ``burst_surfaces`` K > 1, 16 (K - 1) + 64 B
    more) plus output buffers as large as the largest packet.
    """

    def __init__(self, config: TimeSurfaceConfig, t0_us: int | None = None, rows: tuple[int, int] | None = None):
        self.config = c = config
        width, sensor_height = (int(s) for s in c.sensor_size)
        own0, own1 = (0, sensor_height) if rows is None else (int(rows[0]), int(rows[1]))
        #: The rows whose state is held: the band's, widened by the fit's reach.
        self.held = max(own0 - int(c.radius), 0), min(own1 + int(c.radius), sensor_height)
        height = self.held[1] - self.held[0]
        self._ip = np.zeros(ts.N_IP, np.int64)
        self._ip[[ts.I_WIDTH, ts.I_HEIGHT, ts.I_RADIUS, ts.I_DT, ts.I_LATENCY, ts.I_UPDATE_EVERY, ts.I_MIN_POINTS,
                  ts.I_ITERATIONS, ts.I_REFRACTORY, ts.I_WINDOW, ts.I_CONSISTENCY_WINDOW, ts.I_MAX_HOLD, ts.I_MODEL,
                  ts.I_PER_PIXEL, ts.I_PINHOLE, ts.I_TRAVEL, ts.I_BURST_FIT]] = (
            width, height, c.radius, c.timestep_us, c.latency_steps, c.update_every, c.min_points, c.iterations,
            microseconds(c.refractory), microseconds(c.window), microseconds(c.consistency_window),
            microseconds(c.max_hold), ts.MODELS.index(c.model),
            c.per_pixel, c.per_pixel and c.lens is None, c.coordinates == "travel", ts.BURST_FITS.index(c.burst_fit))
        self._ip[[ts.I_HEIGHT, ts.I_ROW0, ts.I_ROWS, ts.I_OWN0, ts.I_OWN1]] = (
            sensor_height, self.held[0], height, own0, own1 if own1 < sensor_height else 1 << 16)
        self._fp = np.zeros(ts.N_FP, np.float64)
        self._fp[[ts.F_FX, ts.F_FY, ts.F_CX, ts.F_CY, ts.F_OUTLIER, ts.F_MAX_RMS, ts.F_MIN_SPREAD, ts.F_MIN_DEPTH,
                  ts.F_MAX_DEPTH, ts.F_MIN_DENOMINATOR, ts.F_WINDOW_DEPTH, ts.F_REFRACTORY_REACH, ts.F_CONSISTENCY,
                  ts.F_HOLD_PX, ts.F_AHEAD_PX, ts.F_TURN, ts.F_TRIM_PX, ts.F_RFX, ts.F_RFY, ts.F_RCX, ts.F_RCY,
                  ts.F_HOLD_RMS, ts.F_BEHIND_REACH, ts.F_WINDOW_PX, ts.F_BURST_RATIO, ts.F_COS_TURN]] = (
            *c.intrinsics, c.outlier_px, c.max_rms_px, c.min_spread, c.min_depth, c.max_depth, c.min_denominator,
            c.window_depth, reach(c.refractory_depth), c.consistency, c.hold_px, c.ahead_px, c.turn, c.trim_px,
            *(c.intrinsics if c.rotation_intrinsics is None else c.rotation_intrinsics), c.hold_fit_rms_px,
            reach(c.behind_depth), c.window_px, c.burst_ratio, cos_turn(c.max_turn))
        r, pixels, planes = int(c.radius), width * height, int(c.burst_surfaces)
        # per burst index k < K and polarity p, [k, p] (k = 0: the first events, ``last_first_event``); with K = 1
        # [p] only: the kernel compiled for that type has no burst-index code at all
        shape = (planes, 2) if planes > 1 else (2,)
        self._surface = np.full(shape + ((height + 2 * r) * (width + 2 * r),), ts.NEVER, np.int64)
        # the first-event rule's rows, the holds in them (0: none yet); with K > 1 a row is a cache line with the
        # burst index in it (``time_surface_first.B_INDEX``)
        row_words = N_B_LAYERED if planes > 1 else N_B
        self._burst_state = line_aligned_full(pixels * 2 * row_words, 0).reshape(pixels, 2, row_words)  # one line
        self._burst_state[:, :, [B_LAST, B_FITTED]] = ts.NEVER
        self._burst_state[:, :, N_B:] = planes  # no edge yet: beyond the surfaces
        self._bursts = self._burst_state[:, :, :N_B]
        self._prev = np.zeros((pixels if c.consistency > 0 else 1, 2), np.float64)
        self._last_step = np.full(pixels, ts.NEVER, np.int64)
        self._motion = np.zeros(ts.N_MOTION)
        self._motion[ts.M_UPDATE] = -1
        self._ring = np.zeros((RING if c.coordinates == "travel" else 1, N_R))  # 425 kB
        self._ring_state = np.full(N_S, NOT_YET, np.int64)
        self._sample_of, self._points = sample_tables(c.per_pixel, c.patch_size, width, sensor_height,
                                                      tuple(c.intrinsics), c.lens)
        size = 2 * (2 * r + 1) ** 2
        lines = 4 * r + 3  # lines across the motion within the square (|w| <= r * sqrt(2)), centred
        self._scratch = (np.empty(size + 1), np.empty(size + 1), np.empty(size + 1), np.zeros(size + 1, np.int64),
                         np.zeros((lines, N_L)), np.zeros(lines, np.int64))
        self._counts = np.zeros(ts.N_COUNTS, np.int64)
        self._t0 = None if t0_us is None else int(t0_us)
        self._ip[ts.I_T0] = 0 if t0_us is None else int(t0_us)
        self._t_hi = ts.NEVER
        self.events_in = 0

    @property
    def _hold(self) -> np.ndarray:
        """The holds ``[pixels held, 2]`` (µs, 0: none yet): a view into the first-event rule's state."""
        return self._bursts[:, :, B_HOLD]

    @property
    def t0_us(self) -> int | None:
        """Start of input step 0 (µs); set by the first event when not given."""
        return self._t0

    @property
    def counts(self) -> dict[str, int]:
        """Where every event fed so far ended (``time_surface.COUNT_NAMES``); they sum to ``events_in``."""
        return {name: int(v) for name, v in zip(ts.COUNT_NAMES, self._counts)}

    @property
    def emitted(self) -> int:
        return int(self._counts[ts.EMITTED])

    @property
    def first_events(self) -> int:
        """Events taken as the first event of an edge (emitted or rejected)."""
        return int(self._counts[list(ts.REJECT_SLOTS)].sum() + self._counts[ts.EMITTED])

    def _updates(self, t_first: int, t_last: int) -> tuple[int, int]:
        """``(first_update, n_updates)`` the output steps of events at ``t_first .. t_last`` µs hold."""
        c, t0 = self.config, self._t0
        steps = (max(t_first, t0) - t0) // c.timestep_us + c.latency_steps, (t_last - t0) // c.timestep_us + \
            c.latency_steps
        first, last = ((s - 1) // c.update_every for s in steps)
        return first, max(last - first + 1, 1)

    def feed(self, events: np.ndarray, velocity: VelocityRows, *,
             record_rejected: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Estimates of one packet: ``(depth DEPTH_DTYPE, quality QUALITY_DTYPE)``, in event order.

        ``record_rejected`` also returns the first events whose estimate was rejected, with
        ``z`` NaN and ``quality["reason"]`` the slot in ``time_surface.COUNT_NAMES`` (for
        diagnosis; emitted ones have ``EMITTED``).

        ``events`` must continue the previous packets in time order (a ``BackendError``
        otherwise, with the state of the events before the offending one kept).
        """
        return self.feed_columns(*event_columns(events), velocity, record_rejected=record_rejected)

    def feed_columns(self, t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, velocity: VelocityRows, *,
                     record_rejected: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``feed`` for events given as contiguous columns (``event_columns``): t µs int64, x, y uint16, p uint8."""
        n = len(t)
        depth, quality = np.empty(n, DEPTH_DTYPE), np.empty(n, QUALITY_DTYPE)
        if n == 0:
            return depth, quality
        if self._t0 is None:
            self._t0 = int(t[0])
            self._ip[ts.I_T0] = self._t0
        self._ip[ts.I_RECORD_REJECTED] = record_rejected
        n_out, lo = 0, 0
        while lo < n:
            hi = self._piece_end(t, lo)
            table, first = self._table(velocity, int(t[lo]), int(t[hi - 1]))
            n_out, status, self._t_hi = ts.process(
                t[lo:hi], x[lo:hi], y[lo:hi], p[lo:hi], self._ip, self._fp, self._surface, self._burst_state,
                self._prev, self._last_step, self._motion, self._ring, self._ring_state, self._sample_of, self._points,
                table, first, *self._scratch, self._counts, depth, quality, n_out, self.events_in + lo, self._t_hi)
            if status == ts.UNSORTED:
                done = lo + int(np.argmax(t[lo:hi] < self._t_hi))
                self.events_in += done
                raise BackendError(f"time surface: event {self.events_in} (t = {int(t[done])} µs) is earlier than "
                                   f"the one before ({self._t_hi} µs); feed events in time order")
            if status == ts.NO_VELOCITY:
                raise BackendError(f"time surface: velocity rows from update {first} ({len(table)} of them) do not "
                                   f"cover the events at {int(t[lo])}-{int(t[hi - 1])} µs")
            lo = hi
        self.events_in += n
        return depth[:n_out], quality[:n_out]

    def _piece_end(self, t: np.ndarray, lo: int) -> int:
        """End of the piece from ``lo`` whose events need at most ``MAX_VELOCITY_ROWS`` velocity rows."""
        c = self.config
        span = (MAX_VELOCITY_ROWS - 2) * c.update_every * c.timestep_us
        start = max(int(t[lo]), self._t_hi, self._t0)
        if int(t[-1]) < start + span:  # the usual packet: all of it
            return len(t)
        return max(int(np.searchsorted(t, start + span, side="left")), lo + 1)

    def _table(self, velocity: VelocityRows, t_first: int, t_last: int) -> tuple[np.ndarray, int]:
        first, count = self._updates(max(t_first, self._t0), max(t_last, self._t0))
        table, table_first = velocity(first, count)
        table = np.ascontiguousarray(table, dtype=np.float64)
        if table.ndim != 2 or table.shape[1] not in (3, 6):
            raise BackendError(f"time surface: velocity rows must have 3 or 6 columns, got shape {table.shape}")
        return table, int(table_first)


def event_columns(events: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The columns ``t`` (µs, int64), ``x``, ``y``, ``p`` of ``EVENT_DTYPE`` events as contiguous arrays (copies)."""
    return (np.ascontiguousarray(events["t"], dtype=np.int64), np.ascontiguousarray(events["x"]),
            np.ascontiguousarray(events["y"]), np.ascontiguousarray(events["p"]))


def sample_tables(per_pixel: bool, patch_size: int, width: int, height: int,
                  camera: tuple[float, float, float, float], lens: Lens | None) -> tuple[np.ndarray, np.ndarray]:
    """``sample_of`` (per pixel, row-major: the index of the point its ``A t`` is taken at) and
    ``points`` (per sample, the ``tofnet.kernels.lens.sample_table`` row of each pixel or of its
    patch: where ``A t`` is evaluated, through the lens)."""
    table = sample_table(per_pixel, patch_size, (width, height), camera, lens).reshape(-1, SAMPLE_COLUMNS)
    if per_pixel:  # one sample per pixel, in pixel order
        return np.arange(width * height, dtype=np.int64), np.ascontiguousarray(table)
    ys, xs = np.mgrid[0:height, 0:width]
    columns = -(-width // patch_size)
    sample_of = ((ys // patch_size) * columns + xs // patch_size).ravel().astype(np.int64)
    first = np.unique(sample_of, return_index=True)[1]
    return sample_of, np.ascontiguousarray(table[first])


def constant_velocity(velocity, omega=None) -> VelocityRows:
    """``VelocityRows`` of a constant camera velocity (m/s) and optional angular velocity (rad/s)."""
    row = np.asarray(tuple(velocity) + (tuple(omega) if omega is not None else ()), dtype=np.float64)

    def rows(first: int, count: int) -> tuple[np.ndarray, int]:
        return np.tile(row, (count, 1)), first

    return rows
