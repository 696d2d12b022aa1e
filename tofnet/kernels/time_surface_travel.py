"""Travel coordinates for the time-surface fit (numba; used by ``tofnet.kernels.time_surface``).

An edge at depth ``Z`` reaches the pixel ``s`` px along the image motion when the camera's
*travel* ``S = Aᵀf · ∫ t dt`` (px·m) is ``c + Z s``, whatever the speed did in between, so fitting
travel instead of time keeps the line straight when the speed changes and its slope is the depth.
The displacement (and, with a rotation, ``∫ ω dt``) is kept per input step in a ring of ``RING``
steps, so a point's travel is one row read and a multiply-add. Derivation, the rotation's term
and the packet-independence rule: docs/time_surface.md, section 7a.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Steps of displacement kept (a power of two): the oldest point a travel fit can use.
RING = 4096
MASK = RING - 1
# Ring columns: displacement at the step's start (m), the step's velocity (m/s), the rotation at the step's start
# (rad, camera frame) and the step's angular velocity (rad/s; zero without one).
R_PX, R_PY, R_PZ, R_VX, R_VY, R_VZ, R_AX, R_AY, R_AZ, R_WX, R_WY, R_WZ, N_R = range(13)
# Ring state (``state``): the last step written, the first, the last whose velocity differs from the step's
# before it (from there on the travel is the speed times the time).
S_LAST, S_FIRST, S_CHANGE, N_S = range(4)
NOT_YET = -1


@njit(cache=True)
def advance(ring, state, k: int, row, dt_s: float) -> None:
    """Write the ring's rows up to step ``k`` after ``state[S_LAST]`` (``NOT_YET``: none); ``row`` is the
    step's velocity row (tx, ty, tz m/s[, wx, wy, wz rad/s])."""
    last = state[S_LAST]
    rotating = row.shape[0] >= 6
    if last == NOT_YET:
        r = k & MASK
        for c in range(N_R):
            ring[r, c] = 0.0
        ring[r, R_VX], ring[r, R_VY], ring[r, R_VZ] = row[0], row[1], row[2]
        if rotating:
            ring[r, R_WX], ring[r, R_WY], ring[r, R_WZ] = row[3], row[4], row[5]
        state[S_LAST], state[S_FIRST], state[S_CHANGE] = k, k, k
        return
    if k <= last:
        return
    p = last & MASK
    for m in range(max(last + 1, k - RING + 1), k + 1):  # the steps between had no events: the last velocity
        done = (m - last) * dt_s
        r = m & MASK
        for c in (R_PX, R_PY, R_PZ, R_AX, R_AY, R_AZ):  # a position's velocity is 3 columns on
            ring[r, c] = ring[p, c] + ring[p, c + 3] * done
        for c in (R_VX, R_VY, R_VZ, R_WX, R_WY, R_WZ):
            ring[r, c] = ring[p, c]
    r = k & MASK
    changed = row[0] != ring[p, R_VX] or row[1] != ring[p, R_VY] or row[2] != ring[p, R_VZ]
    ring[r, R_VX], ring[r, R_VY], ring[r, R_VZ] = row[0], row[1], row[2]
    if rotating:
        changed = changed or row[3] != ring[p, R_WX] or row[4] != ring[p, R_WY] or row[5] != ring[p, R_WZ]
        ring[r, R_WX], ring[r, R_WY], ring[r, R_WZ] = row[3], row[4], row[5]
    if changed:
        state[S_CHANGE] = k
    state[S_LAST] = k


@njit(cache=True, inline="always")
def travel_at(ring, t: int, t0: int, dt: int, inverse_dt: float, g0: float, g1: float, g2: float, h0: float,
              h1: float, h2: float) -> tuple[float, float]:
    """``g·P(t)`` (px·m) and ``h·Θ(t)`` (px) for a time ``t`` µs of the ring's span: one row read and
    multiply-adds."""
    since = t - t0
    k = np.int64(math.floor(since * inverse_dt))  # a rounding off by one lands on the next row: P is continuous
    r = np.uint64(k & MASK)
    elapsed = (since - k * dt) * 1e-6
    travel = (g0 * (ring[r, R_PX] + ring[r, R_VX] * elapsed) + g1 * (ring[r, R_PY] + ring[r, R_VY] * elapsed)
              + g2 * (ring[r, R_PZ] + ring[r, R_VZ] * elapsed))
    turned = (h0 * (ring[r, R_AX] + ring[r, R_WX] * elapsed) + h1 * (ring[r, R_AY] + ring[r, R_WY] * elapsed)
              + h2 * (ring[r, R_AZ] + ring[r, R_WZ] * elapsed))
    return travel, turned


@njit(cache=True)
def since_reversal(ring, k: int, t: int, t0: int, dt: int, first_step: int, g0: float, g1: float, g2: float,
                   z0: float, z1: float, z2: float, reach: float, c0: float = 0.0, c1: float = 0.0, c2: float = 0.0,
                   cos_turn: float = 0.0) -> int:
    """The age (µs) of the oldest first event the fit may use: back from time ``t`` (step ``k``) while the
    image motion along the event's ``f`` keeps its sign (``g·v + z·ω > 0``, ``z`` the rotation's gains
    times the depth the pixels behind suggest: a pixel behind still holds this pass's edge) and the
    translation's image motion stays within the turn whose cosine is ``cos_turn`` of ``f`` (``c·v`` across
    ``f``, ``c = Aᵀf⊥``; net of the rotation a point moves with the translation alone: that is the track its
    line follows; ``cos_turn`` 0: back to where it reversed), and the travel (with ``z·Θ``: the depth times
    the image motion) stays within ``reach`` px·m; never past the ring or its first step."""
    start = t0 + k * dt
    r = k & MASK
    travelled = (g0 * ring[r, R_VX] + g1 * ring[r, R_VY] + g2 * ring[r, R_VZ] + z0 * ring[r, R_WX]
                 + z1 * ring[r, R_WY] + z2 * ring[r, R_WZ]) * (t - start) * 1e-6
    oldest = max(first_step, k - RING + 2)
    m = k - 1
    dt_s = dt * 1e-6
    while travelled < reach and m >= oldest:
        r = m & MASK
        moved = g0 * ring[r, R_VX] + g1 * ring[r, R_VY] + g2 * ring[r, R_VZ]  # the translation's, along f
        along = moved + z0 * ring[r, R_WX] + z1 * ring[r, R_WY] + z2 * ring[r, R_WZ]
        across = c0 * ring[r, R_VX] + c1 * ring[r, R_VY] + c2 * ring[r, R_VZ]
        if along <= 0.0 or moved <= cos_turn * math.sqrt(moved * moved + across * across):
            break
        travelled += along * dt_s
        start -= dt
        m -= 1
    return t - start


@njit(cache=True)
def to_travel(ring, ps_, pw, pt, pg, n: int, t: int, t0: int, dt: int, g0: float, g1: float, g2: float, h0: float,
              h1: float, h2: float, z: float, reach: float, q0: float, q1: float, q2: float, k0: float, k1: float,
              k2: float, middle: int) -> int:
    """Turn the gathered points' times (``pt``, µs before ``t``) into travel before the event's
    (px·m, negative behind) and their positions into where they are now net of the motion since
    (compacted in place; the event itself always stays; returns the points kept):

    - along the motion (``ps_``), net of the rotation's image motion (``h = Bᵀf`` per rad:
      ``s + h·(Θ(t) − Θ(t_q))``); kept within ``reach`` px·m of the event (the travel plus ``z`` m
      times the rotation's image motion: a depth times the image motion);
    - across it (``pw``), net of the rotation's (``k = Bᵀf⊥``) and of the translation's (``q = Aᵀf⊥``,
      over ``z``, the depth the pixels behind suggest): ``w + k·ΔΘ + q·ΔP / z``; each point goes to the
      line (``pg``) that position rounds to (the event's is ``middle``; past the lines ``1 .. 2 middle``
      it is dropped). Net of the motion since, a point has moved along ``f`` only: its line is its track
      where the velocity turned or the camera rotated (docs/time_surface.md, 7h).

    Each point's travel and shift across are taken with its own pixel's gains (``Aᵀf`` there is
    ``g + (0, 0, s)``, ``Aᵀf⊥`` is ``q + (0, 0, w)``): for a pinhole camera the travel is then exactly ``Z s``
    under any translation (docs/time_surface.md, 7g)."""
    inverse_dt = 1.0 / dt
    here, turned = travel_at(ring, t, t0, dt, inverse_dt, g0, g1, g2, h0, h1, h2)
    across, turned_across = travel_at(ring, t, t0, dt, inverse_dt, q0, q1, q2, k0, k1, k2)
    inverse_z = 1.0 / z if z > 0.0 else 0.0  # no depth suggested (the pixels behind fired with no travel): no shift
    forward = travel_at(ring, t, t0, dt, inverse_dt, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)[0]  # P_z (m)
    m = 0
    for i in range(n):
        t_q = t + np.int64(pt[i])
        travel, turned_q = travel_at(ring, t_q, t0, dt, inverse_dt, g0, g1, g2, h0, h1, h2)
        across_q, turned_across_q = travel_at(ring, t_q, t0, dt, inverse_dt, q0, q1, q2, k0, k1, k2)
        forward_q = travel_at(ring, t_q, t0, dt, inverse_dt, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)[0]
        travel += ps_[i] * (forward_q - forward) - here
        shift = turned - turned_q
        w = (pw[i] + turned_across - turned_across_q
             + (across - across_q + pw[i] * (forward - forward_q)) * inverse_z)
        line = middle + np.int64(math.floor(w + 0.5))
        ps_[m], pw[m], pt[m], pg[m] = ps_[i] + shift, w, travel, line
        m += np.int64((travel - z * shift >= -reach) & (1 <= line) & (line <= 2 * middle))
    return m


@njit(cache=True, inline="always")
def pace(travel: float, distance: float) -> float:
    """Travel per pixel (px·m, the depth it suggests) of a pixel ``distance`` px behind (net of rotation)
    that the edge reached ``travel`` px·m ago; infinite when it says nothing (``distance <= 0``)."""
    return travel / distance if distance > 0.0 else math.inf
