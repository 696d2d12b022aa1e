"""Monitors: a variable or a port recorded while a session runs (Lava's ``Monitor``)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from tofnet.errors import TofnetError

_TARGET = re.compile(r"^\s*(\w+)\.(\w+)\s*(?:@\s*(.+))?$")


@dataclass
class Monitor:
    """Records ``target`` (``"process.var"`` or ``"process.port"``) every ``every`` steps.

    A variable is sampled at the start of every step that is a multiple of ``every``
    (the state after the step before it). A port's records are kept when their step is
    a multiple of ``every``. ``pixels`` ``[(x, y), ...]`` keeps only those pixels
    (variables: ``values[sample, ..., pixel]``; ports: records at those pixels); None keeps
    them all. Memory grows with what is asked for: samples x pixels (x channels).
    """

    target: str
    every: int = 1
    pixels: list[tuple[int, int]] | None = None
    steps: list[int] = field(default_factory=list, repr=False)
    _values: list[np.ndarray] = field(default_factory=list, repr=False)
    kind: str = ""  # "var" or "port", set when the session binds it

    def __post_init__(self) -> None:
        if not isinstance(self.target, str) or not _TARGET.match(self.target) or "@" in self.target:
            raise TofnetError(f"monitor: expected a target 'PROCESS.VAR' or 'PROCESS.PORT', got {str(self.target)[:40]!r}")
        if isinstance(self.every, bool) or not isinstance(self.every, int) or self.every < 1:
            raise TofnetError(f"monitor {self.target}: every must be a positive whole number of steps, got {self.every!r}")
        if self.pixels is not None:
            self.pixels = [self._pixel(p) for p in self.pixels]

    def _pixel(self, pixel) -> tuple[int, int]:
        """``(x, y)``, two whole numbers >= 0 (the session checks them against the sensor)."""
        pair = tuple(pixel) if isinstance(pixel, (tuple, list, np.ndarray)) else ()
        if len(pair) != 2 or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 0
                                     for v in pair):
            raise TofnetError(f"monitor {self.target}: a pixel must be (x, y), two whole numbers >= 0, "
                              f"got {str(pixel)[:40]!r}")
        return int(pair[0]), int(pair[1])

    @classmethod
    def parse(cls, text: str, every: int = 1) -> "Monitor":
        """``"time_of_travel.counter@120,90;121,90"`` -> a monitor of those pixels (command-line form)."""
        match = _TARGET.match(text)
        if not match:
            raise TofnetError(f"--monitor: expected PROCESS.VAR or PROCESS.PORT, optionally @X,Y[;X,Y...], got {text!r}")
        process, name, where = match.groups()
        pixels = None
        if where:
            try:
                pixels = [tuple(int(v) for v in pair.split(",")) for pair in where.split(";")]
            except ValueError:
                pixels = []
            if not pixels or any(len(p) != 2 for p in pixels):
                raise TofnetError(f"--monitor {text}: pixels must be X,Y pairs separated by ';', got {where!r}")
        return cls(f"{process}.{name}", every, pixels)

    @property
    def process(self) -> str:
        return self.target.split(".")[0]

    @property
    def name(self) -> str:
        return self.target.split(".")[1]

    def record_var(self, step: int, value: np.ndarray) -> None:
        if step % self.every:
            return
        if self.pixels is not None and value.ndim >= 2:
            xs = np.array([p[0] for p in self.pixels], dtype=np.int64)
            ys = np.array([p[1] for p in self.pixels], dtype=np.int64)
            value = value[..., ys, xs]
        self.steps.append(step)
        self._values.append(np.array(value, copy=True))

    def record_port(self, records: np.ndarray) -> None:
        keep = records["step"] % self.every == 0
        if self.pixels is not None and "x" in records.dtype.names:
            at = np.zeros(len(records), dtype=bool)
            for x, y in self.pixels:
                at |= (records["x"] == x) & (records["y"] == y)
            keep &= at
        if keep.any():
            self._values.append(np.array(records[keep]))

    @property
    def values(self) -> np.ndarray:
        """Variables: ``[samples, ...]`` (stamps in ``steps``); ports: the kept records."""
        if not self._values:
            return np.empty(0)
        if self.kind == "port":
            return np.concatenate(self._values)
        return np.stack(self._values)

    def arrays(self) -> dict[str, np.ndarray]:
        """Plain arrays for a ``.npz``: ``step``, ``values`` (or the record fields), ``x``, ``y``."""
        if self.kind == "port":
            values = self.values
            return {name: values[name] for name in values.dtype.names} if values.size else {}
        out = {"step": np.asarray(self.steps, dtype=np.int64), "values": self.values}
        if self.pixels is not None:
            out["x"] = np.array([p[0] for p in self.pixels], dtype=np.int64)
            out["y"] = np.array([p[1] for p in self.pixels], dtype=np.int64)
        return out
