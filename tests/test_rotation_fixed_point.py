"""Eq. 7 on integers: the rounding division, the share and the depth (docs/rotation.md).

``tests/golden/rotation_fixed_point.json`` holds hand-checkable vectors; an exact
rational oracle (``fractions.Fraction``) checks them and many random ones.
"""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from tofnet.kernels.depth import (EMITTED, ROTATION_DOMINATED, classify_rotation, float_depth_rotation,
                                  translational_share)
from tofnet.kernels.fixed_point import (divide_round_half_away, fixed_depth_rotation, fixed_share, quantize,
                                        rotation_depth_tolerance)

GOLDEN = json.loads((Path(__file__).parent / "golden" / "rotation_fixed_point.json").read_text())
F, P = 16, 24


def oracle(n: int, d: int, shift: int, bits: int) -> int:
    """``n * 2**shift / d`` rounded half away from zero, saturated: with exact rationals."""
    top = 2 ** (bits - 1) - 1
    if d <= 0:
        return -top - 1
    q = Fraction(n * 2**shift, d)
    whole = abs(q).numerator // abs(q).denominator
    if abs(q) - whole >= Fraction(1, 2):
        whole += 1
    return max(-top - 1, min(top, whole if q >= 0 else -whole))


@pytest.mark.parametrize("case", GOLDEN["divide"], ids=lambda c: c["comment"])
def test_divide_golden(case):
    args = case["n"], case["d"], case["shift"], case["bits"]
    assert divide_round_half_away(*args) == case["result"] == oracle(*args)


def test_divide_matches_the_exact_oracle_on_random_operands():
    rng = np.random.default_rng(12)
    for _ in range(3000):
        bits = int(rng.integers(2, 63))
        shift = int(rng.integers(0, 40))
        n = int(rng.integers(-(2**62), 2**62)) >> int(rng.integers(0, 62))
        d = max(1, int(rng.integers(1, 2**62)) >> int(rng.integers(0, 62)))
        assert divide_round_half_away(n, d, shift, bits) == oracle(n, d, shift, bits), (n, d, shift, bits)


def test_divide_rounds_exact_halves_away_from_zero():
    for n in range(-40, 41):
        for d in (1, 2, 4, 6, 10):
            assert divide_round_half_away(n, d, 0, 24) == oracle(n, d, 0, 24)


@pytest.mark.parametrize("case", GOLDEN["depth"], ids=lambda c: c["comment"][:40])
def test_depth_golden(case):
    w = quantize(-200.0 * case["tx"] * 1e-3, F, P)
    v = quantize(-200.0 * case["wy"] * 1e-3, F, P)
    assert (w, v) == (case["w_x"], case["v_x"])
    share = fixed_share(case["s_x"], 0, v, 0, F)
    assert share == case["share_raw"] == 2**F - case["s_x"] * v
    min_raw = quantize(case["min_share"], F, P)
    assert min_raw == case["min_share_raw"]
    verdict = classify_rotation(True, share, 0, min_raw, -(2**23), 2**23 - 1)
    assert (verdict == ROTATION_DOMINATED) == case["rejected"]
    if case["rejected"]:
        return
    z_raw = fixed_depth_rotation(case["s_x"], 0, w, 0, share, F, P)
    assert z_raw == case["z_raw"] == oracle(case["s_x"] * w, share, F, P)
    assert verdict == EMITTED and case["z"] == z_raw / 2**F
    if case["z_float"] is not None:
        at, bw = -200.0 * case["tx"], -200.0 * case["wy"]
        assert translational_share(case["s_x"], 0, bw, 0.0, 1e-3) == case["share_float"]
        assert float_depth_rotation(case["s_x"], 0, at, 0.0, bw, 0.0, 1e-3) == pytest.approx(case["z_float"], rel=1e-12)
        tolerance = rotation_depth_tolerance(case["s_x"], 0, max(case["z"], case["z_float"]), share / 2**F, F)
        assert abs(case["z"] - case["z_float"]) <= tolerance


def test_without_rotation_eq7_is_eq8_bit_for_bit():
    rng = np.random.default_rng(3)
    for _ in range(500):
        s_x, s_y = (int(v) for v in rng.integers(-255, 256, size=2))
        w_x, w_y = (int(v) for v in rng.integers(-(2**20), 2**20, size=2))
        share = fixed_share(s_x, s_y, 0, 0, F)
        assert share == 2**F
        z = s_x * w_x + s_y * w_y
        assert fixed_depth_rotation(s_x, s_y, w_x, w_y, share, F, P) == max(-(2**23), min(2**23 - 1, z))


def test_fixed_and_float_agree_within_the_documented_tolerance():
    rng = np.random.default_rng(7)
    spc = 1e-3
    checked = 0
    for _ in range(3000):
        at_x, at_y = rng.uniform(-300, 300, size=2)
        bw_x, bw_y = rng.uniform(-80, 80, size=2)
        s_x, s_y = (int(v) for v in rng.integers(-255, 256, size=2))
        share_float = translational_share(s_x, s_y, bw_x, bw_y, spc)
        w_x, w_y = quantize(at_x * spc, F, P), quantize(at_y * spc, F, P)
        v_x, v_y = quantize(bw_x * spc, F, P), quantize(bw_y * spc, F, P)
        share = fixed_share(s_x, s_y, v_x, v_y, F)
        if share_float <= 0.05 or share <= 0.05 * 2**F:
            continue
        z_float = float_depth_rotation(s_x, s_y, at_x, at_y, bw_x, bw_y, spc)
        z_fixed = fixed_depth_rotation(s_x, s_y, w_x, w_y, share, F, P) / 2**F
        if abs(z_float) >= 127 or abs(z_fixed) >= 127:
            continue  # saturated: rejected too_far / too_near by both
        tolerance = rotation_depth_tolerance(s_x, s_y, max(abs(z_float), abs(z_fixed)), share / 2**F, F)
        assert abs(z_fixed - z_float) <= tolerance + 1e-12 * abs(z_float), (s_x, s_y, at_x, at_y, bw_x, bw_y)
        checked += 1
    assert checked > 1000
