"""The conformance suite on every registered backend, and proof that it catches differences."""

import dataclasses

import numpy as np
import pytest

from tofnet.backends.base import Backend
from tofnet.backends.reference import ReferenceBackend
from tofnet.backends.registry import available_backends, get_backend
from tofnet.conformance import CASES, format_table, run_suite
from tofnet.conformance.compare import compare
from tofnet.conformance.runner import select_cases

BACKENDS = available_backends()
#: Reference results shared by every backend's run (keyed by baseline and case).
CACHE: dict = {}


def _assert_all_pass(results):
    assert results and all(r.ok for r in results), "\n" + format_table(results)


@pytest.mark.parametrize("name", BACKENDS)
def test_every_backend_conforms_to_the_reference(name):
    results = run_suite(name, "reference", cache=CACHE)
    assert len(results) == len(CASES)
    _assert_all_pass(results)


@pytest.mark.parametrize("name", [n for n in BACKENDS if n != "fixed" and get_backend(n).arithmetic == "fixed"
                                  and "fixed" in BACKENDS])
def test_integer_backends_equal_the_fixed_backend_exactly(name):
    results = run_suite(name, "fixed", cache=CACHE)
    assert {r.mode for r in results} == {"exact"}
    _assert_all_pass(results)


def test_multiproc_per_core_still_equals_the_fixed_backend_exactly():
    """The chip-core-by-chip-core mode (spikes routed by the compiled mapping) stays checked."""
    from tofnet.backends.multiproc import MultiprocBackend
    results = run_suite(MultiprocBackend(workers=2, per_core=True), "fixed", cache=CACHE)
    assert {r.mode for r in results} == {"exact"}
    _assert_all_pass(results)


class ShiftedBackend(Backend):
    """A wrapper around the reference whose depths are off by ``shift`` metres (a broken backend)."""

    name = "shifted"
    arithmetic = "float"

    def __init__(self, shift=0.0, drop_first=False):
        self.shift, self.drop_first = shift, drop_first

    def run(self, compiled, recording, *, record_tot=False, probes=(), progress=None):
        result = ReferenceBackend().run(compiled, recording, record_tot=record_tot, probes=probes, progress=progress)
        depth = result.depth.copy()
        depth["z"] += self.shift
        if self.drop_first and len(depth):
            depth = depth[1:]
        return dataclasses.replace(result, outputs={**result.outputs, result.depth_output: depth},
                                   backend=self.name)


def test_a_backend_registered_at_runtime_runs_the_suite_by_name(registered):
    registered("wrapped-reference", lambda: ShiftedBackend())
    assert "wrapped-reference" in available_backends()
    _assert_all_pass(run_suite("wrapped-reference", cases=["edge", "texture-blobs", "patch-d2"], cache=CACHE))


def test_the_suite_reports_the_first_difference(registered):
    registered("off-by-a-micron", lambda: ShiftedBackend(shift=1e-6))
    registered("drops-one", lambda: ShiftedBackend(drop_first=True))
    (shifted,) = run_suite("off-by-a-micron", cases=["edge+u"], cache=CACHE)
    assert not shifted.ok and shifted.first.startswith("depth z at (step")
    (dropped,) = run_suite("drops-one", cases=["edge+u"], cache=CACHE)
    assert not dropped.ok and "only in the baseline" in dropped.first
    assert "FAIL" in format_table([shifted, dropped]) and "2 failed" in format_table([shifted, dropped])


class CrashingBackend(ShiftedBackend):
    def run(self, compiled, recording, **options):
        raise IndexError("a bug in the backend")


def test_a_crashing_backend_fails_its_cases_and_the_suite_goes_on(registered):
    registered("crashing", CrashingBackend)
    results = run_suite("crashing", cases=["edge+u", "edge-u"], cache=CACHE)
    assert [r.ok for r in results] == [False, False]
    assert results[0].first == "error: IndexError: a bug in the backend"


class ForgetfulBackend(ShiftedBackend):
    """The reference's records and counts, with its result's ``payloads`` or ``declared`` emptied after
    it was built (a backend of the audit's: every case passed, its summary said 0 events in, and
    ``tofnet run -o np.npz`` wrote np.depth.depth.npz)."""

    name = "forgetful"

    def __init__(self, forget):
        super().__init__()
        self.forget = forget

    def run(self, compiled, recording, **options):
        result = super().run(compiled, recording, **options)
        setattr(result, self.forget, {})
        return result


def test_a_backend_whose_result_loses_payloads_or_declared_counts_fails_naming_the_field(registered):
    registered("no-payloads", lambda: ForgetfulBackend("payloads"))
    registered("no-declared", lambda: ForgetfulBackend("declared"))
    (payloads,) = run_suite("no-payloads", cases=["edge+u"], cache=CACHE)
    assert not payloads.ok and payloads.first.startswith("payloads: {} vs {'depth.depth': 'depth'")
    (declared,) = run_suite("no-declared", cases=["edge+u"], cache=CACHE)
    assert not declared.ok
    assert declared.first == "declared counts of processes [] vs ['depth', 'input', 'time_of_travel', 'velocity']"


def test_the_comparison_names_each_summary_field_a_user_would_read_differently():
    scene = next(c for c in CASES if c.name == "borders").build()
    base = ReferenceBackend().run(scene.network, scene.recording, record_tot=True)
    unread = dataclasses.replace(base, declared={**base.declared, "input": {
        name: {**what, "kind": "other"} for name, what in base.declared["input"].items()}})
    differences = compare(unread, base, "quantised", scene.network).differences
    assert differences[0] == ("declared count input.events_in: {'kind': 'other', 'total': ''} vs "
                              "{'kind': 'read', 'total': ''}")
    assert f"summary events_in: 0 vs {base.events_in}" in differences and base.events_in > 0
    assert f"summary accepted: 0 vs {base.accepted}" in differences
    assert any(line.startswith("summary dropped: {} vs {'out_of_bounds': 4") for line in differences)


def test_the_workers_check_compares_what_a_user_reads_too():
    from tofnet.conformance.workers import first_difference
    scene = next(c for c in CASES if c.name == "edge+u").build()
    base = ReferenceBackend().run(scene.network, scene.recording)
    unnamed = dataclasses.replace(base)
    unnamed.payloads = {}
    assert first_difference(base, dataclasses.replace(base)) == ""
    assert first_difference(unnamed, base) == "payloads: {} vs {'depth.depth': 'depth'}"


def test_quantised_comparison_uses_the_count_weighted_bound():
    case = next(c for c in CASES if c.name == "edge+u")
    scene = case.build()
    base = ReferenceBackend().run(scene.network, scene.recording, record_tot=True)
    fixed = dataclasses.replace(base, extra={"frac_bits": 16})
    count = 4  # 250 px/s at 1 ms steps: 4 steps per pixel, one axis measured
    bound = count * 2.0 ** -17
    near = dataclasses.replace(fixed, outputs=dict(base.outputs))
    near.depth = base.depth.copy()
    near.depth["z"] += 0.9 * bound
    assert compare(near, base, "quantised", scene.network).ok
    far = dataclasses.replace(fixed, outputs=dict(base.outputs))
    far.depth = base.depth.copy()
    far.depth["z"][3] += 1.1 * bound
    assert "tolerance" in compare(far, base, "quantised", scene.network).first


def test_case_selection_by_prefix():
    assert [c.name for c in select_cases(["speed-8bit"])] == ["speed-8bit-254", "speed-8bit-255", "speed-8bit-256"]
    assert len({c.name for c in CASES}) == len(CASES)
    with pytest.raises(Exception, match="unknown conformance case"):
        select_cases(["no-such-case"])


def test_cli_lists_and_fails_with_exit_code_1(registered, capsys):
    from tofnet.cli import main
    assert main(["conformance", "--list"]) == 0
    assert "patch-d2-thin" in capsys.readouterr().out
    registered("off-by-a-micron", lambda: ShiftedBackend(shift=1e-6))
    assert main(["conformance", "--backend", "off-by-a-micron", "--case", "edge+u"]) == 1
    out = capsys.readouterr().out
    assert "edge+u" in out and "FAIL" in out and "depth z at" in out
    assert main(["conformance", "--backend", "reference", "--case", "speed-4bit-1"]) == 0
    capsys.readouterr()
    assert main(["conformance", "--workers", "1,2", "--against", "float", "--case", "edge+u"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--against and --workers" in err[0]


def test_the_cases_exercise_what_they_are_named_for():
    def run(name):
        scene = next(c for c in CASES if c.name == name).build()
        return ReferenceBackend().run(scene.network, scene.recording, record_tot=True)
    assert run("speed-4bit-15").tot["count"].tolist() == [15] * 10
    assert run("speed-4bit-16").tot_spikes == 0  # overflow
    borders = run("borders")
    assert borders.dropped["out_of_bounds"] == 4 and borders.dropped["before_t0"] == 3
    assert run("refractory").dropped["refractory"] > 0 and run("same-step").dropped["same_step"] > 0
    conflict = run("conflicting-directions")
    assert conflict.rejected["no_measurement"] > 0
    assert np.unique(conflict.tot["direction"]).tolist() == [0, 1, 2, 3]
    depth_range = run("depth-range")
    assert depth_range.rejected["too_near"] > 0 and depth_range.rejected["too_far"] > 0
    lens = run("graph-undistort").counts["undistort"]
    assert lens["passed"] > 1000 and lens["left_image"] > 0


def _rotation_runs(name):
    from tofnet.conformance.runner import rotation_probes
    scene = next(c for c in CASES if c.name == name).build()
    probes = rotation_probes(scene.network)
    return scene, ReferenceBackend().run(scene.network, scene.recording, record_tot=True, probes=probes), probes


def test_the_rotation_cases_compensate_and_reject_rotation_dominated_estimates():
    for name, depth_m in (("rotation-texture", 1.0), ("rotation-poses", 1.5)):
        _, result, probes = _rotation_runs(name)
        assert probes == ["angular_velocity.b_w"]
        assert np.median(result.depth["z"]) == pytest.approx(depth_m, rel=0.06)
    _, dominated, _ = _rotation_runs("rotation-dominated")
    assert dominated.rejected["rotation_dominated"] > len(dominated.depth) / 4


def test_quantised_comparison_uses_the_eq7_bound():
    from tofnet.conformance.compare import rotation_of, shares, signed_counts
    from tofnet.kernels.fixed_point import rotation_depth_tolerance
    scene, base, _ = _rotation_runs("rotation-texture")
    rotation = rotation_of(scene.network, "depth", base.outputs, scene.recording)
    sx, sy = signed_counts(base.tot, base.depth, *scene.network.sensor_size)
    _, share_q = shares(rotation, base.depth, sx, sy, 1e-3, 16, 24)
    bound = rotation_depth_tolerance(sx, sy, np.abs(base.depth["z"]), share_q, 16)
    assert np.median(bound / depth_tolerance_of(sx, sy)) > 1.5  # eq. 7's bound is wider than eq. 8's where r < 1
    fixed = dataclasses.replace(base, extra={"frac_bits": 16, "payload_bits": 24})
    near = dataclasses.replace(fixed, outputs=dict(base.outputs))
    near.depth = base.depth.copy()
    near.depth["z"] += 0.9 * bound
    assert compare(near, base, "quantised", scene.network, scene.recording).ok
    far = dataclasses.replace(fixed, outputs=dict(base.outputs))
    far.depth = base.depth.copy()
    far.depth["z"][7] += 1.1 * bound[7]  # (the bound at the larger depth grows by c / r per metre: ~1e-4)
    assert "tolerance" in compare(far, base, "quantised", scene.network, scene.recording).first
    unprobed = dataclasses.replace(fixed, outputs={k: v for k, v in base.outputs.items() if k != "angular_velocity.b_w"})
    comparison = compare(unprobed, dataclasses.replace(unprobed, extra={}), "quantised", scene.network)
    assert comparison.ok and "compensates rotation" in comparison.notes[0]


def depth_tolerance_of(sx, sy):
    from tofnet.kernels.fixed_point import depth_tolerance
    return depth_tolerance(sx, sy)


def test_a_pass_with_unequal_estimates_is_marked_and_explained():
    from tofnet.conformance.runner import CaseResult

    equal = CaseResult("edge+u", "fixed", "float", "quantised", True, (10, 10), "", 0.1)
    unequal = CaseResult("graph-denoised", "fixed", "float", "quantised", True, (3051, 3038), "", 0.1)
    table = format_table([equal, unequal]).splitlines()
    assert " pass  " in table[1] and " pass* " in table[2]
    assert table[-1].startswith("pass* (quantised): fixed vs float: an estimate may be on one side only when its "
                                "depth lies within the quantisation tolerance")
    assert "docs/fixed_point.md" in table[-1]
    assert not format_table([equal]).splitlines()[-1].startswith("pass*")  # no such row, no footnote


def test_the_table_columns_hold_the_longest_case_and_mode(capsys):
    """``bands-1-unfused`` (15 characters) and ``variables-time-surface-texture`` (30) overflowed
    columns of 10 and 24, pushing the rest of their rows out of line."""
    from tofnet.cli import main
    from tofnet.conformance.runner import CaseResult

    rows = [CaseResult("edge+u", "fixed x1", "fixed x1", "bands-1", True, (110, 110), "", 0.1),
            CaseResult("variables-time-surface-texture", "fixed x7", "fixed x1", "bands-7-unfused", False, (5, 6),
                       "counts differ", 0.1)]
    table = format_table(rows).splitlines()
    ends = [line.index(word) + len(word) for line, word in zip(table, ("estimates", "110/110", "5/6"))]
    assert ends == [30 + 1 + 15 + 1 + 5 + 1 + 11] * 3  # case, mode, verdict, estimates (right-aligned)
    assert table[2].split() == ["variables-time-surface-texture", "bands-7-unfused", "FAIL", "5/6", "counts", "differ"]
    assert main(["conformance", "--backend", "fixed", "--workers", "1", "--case", "edge+u"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert [line.split()[:3] for line in out[2:4]] == [["edge+u", "bands-1", "pass"],
                                                       ["edge+u", "bands-1-unfused", "pass"]]
    assert out[1].index("estimates") + 9 == out[2].index("110/110") + 7 == out[3].index("110/110") + 7


def test_the_docs_count_the_cases_there_are():
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    readme = re.search(r"`tofnet conformance` runs (\d+) named cases", (root / "README.md").read_text())
    backends = re.search(r"All (\d+) cases pass for", (root / "docs" / "backends.md").read_text())
    assert int(readme.group(1)) == int(backends.group(1)) == len(CASES)
