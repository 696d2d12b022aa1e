"""TimeSurfaceProcess: depth from the local slope of the time surface (beyond the paper; docs/time_surface.md)."""

from __future__ import annotations

from tofnet.core.counters import Count, reader_counts
from tofnet.core.params import Param
from tofnet.core.ports import Payload, PortSpec
from tofnet.core.process import Process
from tofnet.core.vars import Var
from tofnet.errors import NetworkError

#: Per estimate, beside its depth record (same step, pixel and order): the event's own time (µs),
#: the points the fit kept, their rms distance from it (px) and the gradient ∇T (s/px).
QUALITY = Payload("time_surface_quality", (("t_event", "<i8"), ("points", "<u2"), ("rms_px", "<f4"),
                                           ("gx", "<f4"), ("gy", "<f4")),
                  "the fit behind each time-surface estimate: event time µs, points kept, rms residual px, "
                  "gradient ∇T s/px (gx along u, gy along v)")

#: Fit models: lines of pixels along the image motion with their own offsets, or one plane.
MODELS = ("rows", "plane")
#: With burst-index surfaces: which later events of a burst are fitted.
BURST_FITS = ("all", "fitted", "emitted")
#: What the fit's surface is over: the camera's travel at the first events' times, or the times themselves.
COORDINATES = ("travel", "time")


class TimeSurfaceProcess(Process):
    """Reads the camera's events and fits, per first event of an edge, the local time surface.

    ``td = ∇T`` (s/px) is the time of travel, so ``Z = (A t)·∇T`` (paper eq. 8), or
    ``(A t)·∇T / (1 − (B ω)·∇T)`` (eq. 7) with ``b_w`` connected. Per event, in time order
    and with microsecond times (no 1 ms quantisation): an event that ends a silence of its
    pixel and polarity (``burst_ratio``, ``refractory_depth``: the pixel's own events only)
    starts an edge and the surface takes its time; any other event, or one less than the
    pixel's hold after its last fitted one, is part of a burst (dropped); else the recent
    first events of the same polarity within ``radius`` px that the edge has crossed are
    fitted (lines along the image motion, or a plane), outliers dropped, and the fit checked
    (points, spread, rms). A burst's k-th later event (0 < k < ``burst_surfaces``, 4 by default) is
    fitted the same way on surface k, where its edge's first event was emitted. A host process (off-chip): it reads the events itself, like the
    input process, and answers in the step after each event (latency 1).
    ``A t`` comes from ``a_t`` as the sender samples it (per pixel or per patch); the
    defaults were chosen by sweeps over every built-in scenario (docs/time_surface.md).
    Every event ends in one count: ``events_in = accepted + out_of_bounds + before_t0 +
    burst``, ``accepted`` = first events = ``emitted`` + the rejections.
    """

    inports = (
        PortSpec("a_t", Payload.VELOCITY_TERM, 2, "A t from the velocity process, px*m/s"),
        PortSpec("b_w", Payload.ROTATION_TERM, 2, "B ω from an angular velocity process, px/s: eq. 7 when "
                 "connected, eq. 8 when not", required=False),
    )
    outports = (
        PortSpec("depth", Payload.DEPTH, 1, "depth estimate per accepted first event, metres"),
        PortSpec("quality", QUALITY, 1, "the fit behind each estimate (aligned with depth)"),
    )
    counters = (*reader_counts("first events of an edge at a pixel"),
                Count("burst", "dropped", "not the first event of an edge (within the burst window)"),
                *(Count(reason, "rejected", "an estimate the fit refused: " + reason.replace("_", " "))
                  for reason in ("no_motion", "nothing_behind", "too_few_points", "ill_conditioned", "bad_fit",
                                 "rotation_dominated", "too_near", "too_far", "inconsistent", "same_step")),
                Count("emitted", "output", "estimates sent"))
    params = (
        Param("sensor_size", "size", (240, 180), unit="px", doc="sensor (width, height)"),
        Param("timestep", "duration", "1ms", unit="s", doc="duration of one network step", minimum=1e-6),
        Param("t0", "duration", None, unit="s", optional=True,
              doc="start of step 0; the first event's time when omitted"),
        Param("model", "str", "rows", doc="fit lines along the image motion with their own offsets (rows) or one "
              "plane (Benosman et al. 2014)", choices=MODELS),
        Param("coordinates", "str", "travel", doc="fit the first events' travel (the camera's displacement along the "
              "image motion at their times: straight when the speed changes) or their times", choices=COORDINATES),
        Param("radius", "int", 3, unit="px", doc="the fit looks at the (2 radius + 1)² square around the event",
              minimum=1),
        Param("ahead_px", "float", -0.5, unit="px", doc="pixels more than this ahead of the event along the image "
              "motion are not used (they still hold an older edge's times)"),
        Param("window", "duration", 0.0, unit="s", doc="a fixed lower bound on the age of the oldest point used",
              minimum=0.0),
        Param("window_depth", "length", 10.0, unit="m", doc="oldest point used: the travel (coordinates travel; "
              "else the time) a surface this deep takes to move radius px", minimum=0.0),
        Param("window_px", "float", 6.0, unit="px", doc="nor older than the time the edge takes to move this far "
              "at its own pace, as the two pixels behind it measured (an older point is another edge's; 0: off)",
              minimum=0.0),
        Param("turn", "float", 0.2, doc="coordinates time: a velocity change beyond this fraction of the speed "
              "starts a new motion epoch; no point from before it is used (0: never)", minimum=0.0),
        Param("min_points", "int", 8, doc="points on lines of two or more a fit needs", minimum=1),
        Param("min_spread", "float", 0.5, unit="px²", doc="variance along the motion within the lines a fit needs",
              minimum=0.0),
        Param("outlier_px", "float", 0.25, unit="px", doc="drop the farthest point while farther than this from the "
              "fit", minimum=0.0),
        Param("iterations", "int", 2, doc="at most this many points dropped as outliers", minimum=0),
        Param("max_rms_px", "float", 0.25, unit="px", doc="fits with a larger rms distance are rejected (bad_fit)",
              minimum=0.0),
        Param("trim_px", "float", 0.0, unit="px", doc="plane model: drop points fitted within this of the window's "
              "ends and refit (0: off)", minimum=0.0),
        Param("hold_px", "float", 3.0, unit="px", doc="a pixel's burst hold: this many times the time per pixel "
              "its last fit measured", minimum=0.0),
        Param("burst_ratio", "float", 4.0, doc="an event starts an edge at its pixel when the silence before it "
              "is this many times the gap before the event ahead (or, after an edge's first event, at least the "
              "silence before that over this), or at least the refractory period; from the pixel's own events only",
              minimum=1.0),
        Param("hold_fit_rms_px", "float", 0.5, unit="px", doc="only a fit at most this far (rms) from its points "
              "sets the pixel's hold: a worse one, e.g. in noise, measured no crossing time", minimum=0.0),
        Param("max_turn", "float", 60.0, unit="deg", doc="coordinates travel: no point from before the translation's "
              "image motion at the event's pixel turned by more than this from its direction now (90: back to a "
              "reversal only)",
              minimum=1.0, maximum=180.0),
        Param("behind_depth", "length", 10.0, unit="m", doc="fit a first event only when the two pixels just "
              "behind it along the motion fired, in either order, within the travel (coordinates travel; else the "
              "time) a surface this deep takes to move that far (an edge crossed them; noise did not; 0: off)", minimum=0.0),
        Param("refractory_depth", "length", 10.0, unit="m", doc="before a pixel has a fit, its hold is the time a "
              "surface this deep takes to move one pixel; a silence that long always starts an edge", minimum=0.0),
        Param("refractory", "duration", 0.0, unit="s", doc="a fixed lower bound on that first hold", minimum=0.0),
        Param("max_hold", "duration", 1.0, unit="s", doc="upper bound of any hold", minimum=0.0),
        Param("consistency", "float", 0.0, doc="emit only when the pixel's previous estimate agrees within this "
              "fraction (0: off)", minimum=0.0),
        Param("consistency_window", "duration", 0.25, unit="s", doc="how recent that previous estimate must be",
              minimum=0.0),
        Param("min_depth", "length", 0.05, unit="m", doc="estimates at or below are rejected", minimum=0.0),
        Param("max_depth", "length", 20.0, unit="m", doc="estimates at or above are rejected", minimum=0.0),
        Param("burst_surfaces", "int", 4, doc="burst-index surfaces K: a burst's k-th later event (k < K) "
              "writes surface k of its pixel and is fitted on it as a first event is on surface 0 (1: first events "
              "only, 15-20 % faster on noise, half the estimates; docs/time_surface.md 7e)", minimum=1, maximum=16,
              selects_code=True),
        Param("burst_fit", "str", "emitted", doc="with burst_surfaces > 1, which later events are fitted: all, only "
              "those whose edge's first event was fitted (passed the hold), or only those whose first event was "
              "emitted", choices=BURST_FITS),
        Param("min_denominator", "float", 0.1, doc="with b_w: estimates whose translational share 1 - (B ω)·∇T is "
              "below are rejected (rotation_dominated)", minimum=0.0),
    )
    vars = (Var("last_first_event", "channels", "int64", "µs", "time of the pixel's last event that started an edge "
                "(the first-event rule), per polarity (channel 0 OFF, 1 ON): the time surface; -2**62 before the first",
                channels=2, settable=True, low=-(1 << 62), high=(1 << 61) - 1),
            Var("hold", "channels", "int64", "µs", "the burst hold the pixel's last fit measured, per polarity "
                "(0: none yet, the refractory_depth hold applies)", channels=2, settable=True,
                low=0, high=(1 << 31) - 1))
    placement = "host"
    added_latency_steps = 1  # it answers in the step after the event

    def _check(self) -> None:
        values = self._values
        if values["min_depth"] >= values["max_depth"]:
            raise NetworkError(f"{self.name}: min_depth ({values['min_depth']:g} m) must be below "
                               f"max_depth ({values['max_depth']:g} m)")
        if values["window"] <= 0 and values["window_depth"] <= 0:
            raise NetworkError(f"{self.name}: window (s) or window_depth (m) must be above 0: the fit needs a window")
        if values["radius"] < 2:  # the two pixels behind an event are read by these
            needs = [name for name, on in (("coordinates: travel", values["coordinates"] == "travel"),
                                           ("behind_depth", values["behind_depth"] > 0),
                                           ("window_px", values["window_px"] > 0)) if on]
            if needs:
                raise NetworkError(f"{self.name}.radius: {', '.join(needs)} need radius >= 2 (the two pixels "
                                   f"behind an event), got {values['radius']}")
        if values["min_denominator"] >= 1.0:
            raise NetworkError(f"{self.name}.min_denominator: expected a share below 1, got "
                               f"{values['min_denominator']:g}")
