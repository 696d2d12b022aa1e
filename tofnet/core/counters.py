"""What a process counts: a declaration per count, so that results and reports add them up
without knowing the process (no execution code here)."""

from __future__ import annotations

from dataclasses import dataclass

#: What a count is. ``read``: events the process read (every event of the recording);
#: ``accepted``: events it took; ``dropped``: inputs it dropped, one count per reason;
#: ``rejected``: estimates it rejected, one count per reason; ``output``: records it sent;
#: ``other``: anything else (not summed anywhere).
KINDS = ("read", "accepted", "dropped", "rejected", "output", "other")


@dataclass(frozen=True)
class Count:
    """One count a process keeps: its ``name`` (a key of the model's ``counts()``), its ``kind``
    (``KINDS``), what it counts (``doc``) and, for an ``output``, the run summary's total it adds to
    (``total``, e.g. ``"tot_spikes"``; empty: none). ``warning``: what a report says after the
    number when the count is not 0 (``{width}`` and ``{height}``: the sensor's size)."""

    name: str
    kind: str
    doc: str = ""
    total: str = ""
    warning: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise TypeError(f"Count {self.name!r}: kind {self.kind!r} is not one of {', '.join(KINDS)}")


def names_of(counts: tuple[Count, ...], kind: str) -> tuple[str, ...]:
    """The names of the counts of ``kind``, in declaration order (a drop or reject vocabulary)."""
    return tuple(c.name for c in counts if c.kind == kind)


def kinds_of(counts: tuple[Count, ...]) -> dict[str, dict]:
    """Plain data for a result: ``{name: {"kind": kind, "total": total[, "warning": warning]}}`` in
    declaration order."""
    return {c.name: {"kind": c.kind, "total": c.total, **({"warning": c.warning} if c.warning else {})}
            for c in counts}


def reader_counts(accepted: str) -> tuple[Count, ...]:
    """The counts every process that reads the recording's events keeps: all it read, those it took
    (``accepted``: what they are), and the drops any reader has (outside the sensor, before step 0).
    A reader adds its own drops after these."""
    return (Count("events_in", "read", "events of the recording"),
            Count("accepted", "accepted", accepted),
            Count("out_of_bounds", "dropped", "outside sensor_size",
                  warning="events lay outside the {width}x{height} sensor (if the recording is larger, "
                          "--sensor-size says how large)"),
            Count("before_t0", "dropped", "before the start of step 0"))
