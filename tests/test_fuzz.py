"""Property-based fuzzing of every reader (issue 10's formats too, through ``read_recording``),
the spec loader and the CLI options (hypothesis).

Every case must end in a one-line ``TofnetError`` or in a result satisfying the
documented rules (``tofnet.fuzzing``). Derandomised and bounded (about 1,500 cases,
well under a minute); ``python benchmarks/fuzz.py`` runs 20,000.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from optional import optional

hypothesis = optional("hypothesis")
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

from tofnet.fuzzing import OPS, TARGETS, TOKENS, _npy, _npz, mutate, mutate_words, outcome, seeds  # noqa: E402

FUZZ = settings(max_examples=80, deadline=None, derandomize=True, database=None,
                suppress_health_check=list(HealthCheck))
#: A case slower than this counts as a hang.
HANG_S = 10.0

ops = st.lists(st.tuples(st.sampled_from(OPS), st.integers(0, 2**20), st.integers(0, 8 * len(TOKENS))),
               min_size=1, max_size=4)


def assert_clean(name: str, case) -> None:
    with tempfile.TemporaryDirectory() as folder:
        started = time.perf_counter()
        kind, detail = outcome(TARGETS[name], case, Path(folder))
        elapsed = time.perf_counter() - started
    assert kind in ("error", "accepted"), f"{name}: {kind}: {detail}\ncase: {case!r:.500}"
    assert elapsed < HANG_S, f"{name}: {elapsed:.1f} s"


@pytest.mark.parametrize("name", [name for name, target in TARGETS.items() if target.kind == "bytes"])
def test_seeds_are_accepted(name):
    if not seeds(name):
        pytest.skip(f"{name}: its library (an optional extra) is not installed")
    for case in seeds(name):
        with tempfile.TemporaryDirectory() as folder:
            assert outcome(TARGETS[name], case, Path(folder)) == ("accepted", "")


@pytest.mark.parametrize("name", list(TARGETS))
@FUZZ
@given(data=st.data())
def test_mutated_files_and_options(name, data):
    target = TARGETS[name]
    if not seeds(name):
        pytest.skip(f"{name}: its library (an optional extra) is not installed")
    seed = data.draw(st.sampled_from(seeds(name)))
    edits = data.draw(ops)
    case = mutate_words(seed, edits) if target.kind == "words" else mutate(seed, edits)
    assert_clean(name, case)


# ---------------------------------------------------------------- structured cases

_dtypes = st.sampled_from(["<i1", "<u1", "<i2", "<u2", "<i4", "<u8", "<i8", ">i8", "<f2", "<f4", "<f8", "?",
                           "<c8", "<U2", "<M8[us]"])
_columns = st.integers(0, 6).flatmap(
    lambda n: st.fixed_dictionaries({k: hnp.arrays(_dtypes, st.sampled_from([n, n, n, n + 1])) for k in "txyp"}))


@FUZZ
@given(columns=_columns, compressed=st.booleans(),
       table=hnp.arrays(_dtypes, st.tuples(st.integers(0, 5), st.sampled_from([3, 4, 4, 5]))))
def test_numpy_event_files_of_any_dtype_and_value(columns, compressed, table):
    assert_clean("events.npz", _npz(compressed, **columns))
    n = min(len(a) for a in columns.values())
    structured = np.zeros(n, dtype=[(k, a.dtype) for k, a in columns.items()])
    for k, a in columns.items():
        structured[k] = a[:n]
    assert_clean("events.npy", _npy(structured))
    assert_clean("events.npy", _npy(table))


@FUZZ
@given(depth=hnp.arrays(_dtypes, st.sampled_from([3, 3, 2, 0])))
def test_true_depth_files_of_any_dtype_and_value(depth):
    assert_clean("events_depth.npy", _npy(depth))


@FUZZ
@given(arrays=st.integers(0, 4).flatmap(lambda n: st.fixed_dictionaries(
    {k: hnp.arrays(_dtypes, st.sampled_from([n, n, n + 1])) for k in ("t", "t_us", "x", "y", "z", "step")})),
    summary=st.text(max_size=20))
def test_depth_npz_of_any_dtype_and_value(arrays, summary):
    assert_clean("depth.npz", _npz(False, **arrays, t0_us=np.int64(0), timestep_us=np.int64(1000),
                                   latency_steps=np.int64(2), summary_json=np.str_(summary)))


_number = (st.floats(allow_nan=True, allow_infinity=True).map(repr) | st.integers().map(str)
           | st.sampled_from([t.decode("latin1") for t in TOKENS]))
_row = st.lists(_number, min_size=0, max_size=9).map(" ".join)


@pytest.mark.parametrize("name", ["events.txt", "calib.txt", "groundtruth.txt", "imu.txt", "sensor_size.txt",
                                  "velocity samples", "depth.csv"])
@FUZZ
@given(rows=st.lists(_row, max_size=6), ending=st.sampled_from(["\n", "", "\r\n"]))
def test_text_tables_of_any_numbers(name, rows, ending):
    text = "\n".join(rows) + ending
    if name == "depth.csv":
        text = "t,x,y,z,step\n" + "\n".join(r.replace(" ", ",") for r in rows) + f"\n# end: {len(rows)} rows\n"
    assert_clean(name, text.encode("utf-8", "surrogatepass"))


_plain = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8)
_tree = st.recursive(_plain, lambda children: st.lists(children, max_size=4)
                     | st.dictionaries(st.text(max_size=6) | st.integers(), children, max_size=4), max_leaves=20)


@FUZZ
@given(tree=_tree, value=_plain | _tree, field=st.sampled_from(["processes", "connections", "compile", "backend",
                                                                 "name", "description"]))
def test_specs_of_any_yaml_value(tree, value, field):
    base = yaml.safe_load(seeds("spec")[0])
    assert_clean("spec", yaml.safe_dump(tree).encode())
    assert_clean("spec", yaml.safe_dump({**base, field: value}).encode())
    process = "input"
    body = dict(base["processes"][process])
    body["timestep" if isinstance(value, (int, float)) else "sensor_size"] = value
    assert_clean("spec", yaml.safe_dump({**base, "processes": {**base["processes"], process: body}}).encode())


_decimal_time = st.builds(
    lambda sign, whole, fraction, exponent: f"{sign}{whole}{'.' + fraction if fraction is not None else ''}"
                                            f"{'e' + str(exponent) if exponent is not None else ''}",
    st.sampled_from(["", "-", "+"]), st.text("0123456789", min_size=1, max_size=22),
    st.none() | st.text("0123456789", max_size=30), st.none() | st.integers(-30, 14))


@FUZZ
@given(times=st.lists(_decimal_time, min_size=1, max_size=6))
def test_events_txt_times_equal_the_exact_decimal_value(times):
    from decimal import Decimal
    times = sorted(times, key=Decimal)
    assert_clean("events.txt", "".join(f"{t} 1 2 1\n" for t in times).encode())
