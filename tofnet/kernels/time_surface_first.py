"""The time-surface estimator's first-event rule (numba; used by ``tofnet.kernels.time_surface``).

A pixel fires a burst of events per edge; only the first says when the edge arrived. An event
starts an edge when, from the pixel's own events and ``A t`` only, the silence before it is long
against the pace of the events before (``ratio``) or at least the refractory period; it is
fitted when the pixel's hold (from its last fit) has passed. Reading nothing from other pixels
keeps a band of rows plus the fit's ``radius`` exact. The rule and why: docs/time_surface.md,
section 1a. State per pixel and polarity: one 32-byte row of ``bursts`` (``B_*``, int64 µs,
the hold beside them; 64 bytes with the burst index, ``B_INDEX``), so an event touches one cache line of state.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: "No event yet" (µs), as the surface's ``time_surface.NEVER``.
NEVER = -(1 << 62)

#: ``bursts[y * w + x, p]``: the pixel's last event, the silence before it (negative when it
#: continued a burst), its last fitted event, its hold (µs; 0: none yet, set by ``time_surface``'s fits).
B_LAST, B_GAP, B_FITTED, B_HOLD, N_B = range(5)
#: With burst-index surfaces (``burst_surfaces`` K > 1) a row is ``N_B_LAYERED`` words, a cache line: its words
#: ``B_*``, then ``B_INDEX``, the index of the pixel's last event in its edge's burst (0: it started the edge; K:
#: beyond the surfaces, or no edge yet), so that an event reads and writes one line of state as with K = 1.
B_INDEX, N_B_LAYERED = N_B, 8
#: A flag beside the index there: the edge's first event was emitted.
B_EMITTED = 1 << 8


@njit(cache=True, inline="always")
def first_event(flat_bursts, at: int, t: int, ratio: float, refractory_us: int, refractory_reach: float,
                speed2: float) -> tuple[bool, bool]:
    """``(starts an edge, is fitted)`` for an event at ``t`` µs at a pixel whose state is
    ``flat_bursts[at:at + N_B]`` (updated; its hold ``B_HOLD`` µs, 0: none yet, the refractory period
    then); ``speed2`` is ``|A t|²`` there. The refractory period is ``refractory_us`` and, with
    ``refractory_reach`` (the refractory depth, m, times 1e6) and motion, the time per pixel at
    that depth. Without branches but the caller's one: each test is a coin toss on noise. The indices are
    read as unsigned: numba fixes up every signed index for negative values (instructions on every event)."""
    gap = t - flat_bursts[np.uint64(at + B_LAST)]  # the pixel's first event's: since ``NEVER``, so its second event
    before = flat_bursts[np.uint64(at + B_GAP)]  # starts an edge only after the refractory period (a burst's does not)
    age = t - flat_bursts[np.uint64(at + B_FITTED)]
    held = flat_bursts[np.uint64(at + B_HOLD)]
    reach2 = refractory_reach * refractory_reach
    moving = (refractory_reach > 0.0) & (speed2 > 0.0)
    # a silence after an edge's first event (``before`` > 0) at least 1 / ratio of the one before it,
    # after a burst's event at least ratio times its gap, or at least the refractory period
    paced = ((before > 0) & (float(gap) * ratio >= float(before))) | ((before <= 0) & (float(gap) >= -ratio
                                                                                          * float(before)))
    after = float(gap + 1)  # gap >= D / |A t| without a root or a division: (gap + 1)² |A t|² > D²
    refractory = (gap >= refractory_us) & ((refractory_us > 0) | moving) & (
        (~moving) | (after * after * speed2 > reach2))
    edge = paced | refractory
    after = float(age + 1)
    early = (age < refractory_us) | (moving & ((after <= 0.0) | (after * after * speed2 <= reach2)))
    fitted = edge & ((held == 0) & ~early | (held != 0) & (age >= held))
    flat_bursts[np.uint64(at + B_LAST)] = t
    flat_bursts[np.uint64(at + B_GAP)] = gap if edge else -gap
    flat_bursts[np.uint64(at + B_FITTED)] = t if fitted else flat_bursts[np.uint64(at + B_FITTED)]
    return edge, fitted


@njit(cache=True, nogil=True, _nrt=False)  # not inlined: the kernel's loop without burst surfaces stays as it was
def later_event(flat_bursts, flat_surface, at: int, at_cell: int, plane_size: int, edge: bool, fitted: bool,
                planes: int, which: int) -> tuple[int, bool, bool]:
    """With ``planes`` = K > 1 burst-index surfaces: ``(at_cell, writes, fitted)`` for an event whose first-event
    rule said ``(edge, fitted)``, at a pixel whose state row is at ``at`` and whose cell on surface 0 of its
    polarity is ``at_cell``. Its index k in its edge's burst (0 when it starts an edge, else one more than the
    pixel's last, at most K; ``B_INDEX``, from the pixel's own events) picks its surface, ``at_cell + 2 k
    plane_size``; an event of 0 < k < K writes it and is fitted there when ``which`` says (0: all; 1: its edge's
    first event was fitted; 2: it was emitted, the ``B_EMITTED`` flag the kernel leaves beside the index)."""
    slot = np.uint64(at + B_INDEX)
    kept = flat_bursts[slot]
    index = 0 if edge else min((kept & (B_EMITTED - 1)) + 1, planes)
    flat_bursts[slot] = index if edge else index | (kept & B_EMITTED)
    if 0 < index < planes:
        fitted = (which == 0 or (which == 2 and kept >= B_EMITTED)
                  or (which == 1 and flat_bursts[np.uint64(at + B_FITTED)] == flat_surface[np.uint64(at_cell)]))
        return at_cell + 2 * index * plane_size, True, fitted
    return at_cell, edge, fitted
