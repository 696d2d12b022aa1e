"""Issue 27 item 7: the storage recipes with every option drawn at random (hypothesis), on top of
the mutated seeds of tests/test_fuzz.py: HDF5 external/virtual storage, links and declared
sizes; ROS message definitions and stamps. Each case is a one-line error or a valid result,
and a case that must be refused (``tofnet.fuzzing_storage``) never is accepted."""

import tempfile
from pathlib import Path

import pytest

from optional import optional

hypothesis = optional("hypothesis")
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402

from tofnet.fuzzing import TARGETS, outcome  # noqa: E402
from tofnet.fuzzing_storage import STORAGE_TARGETS, random_recipe, storage_seeds  # noqa: E402


@pytest.mark.parametrize("name", list(STORAGE_TARGETS))
@settings(max_examples=60, deadline=None, derandomize=True, database=None, suppress_health_check=list(HealthCheck))
@given(rng=st.randoms(use_true_random=False))
def test_random_recipes_are_refused_or_valid(name, rng):
    if not storage_seeds(name):
        pytest.skip(f"{name}: its library (an optional extra) is not installed")
    case = random_recipe(rng, name)
    with tempfile.TemporaryDirectory() as folder:
        kind, detail = outcome(TARGETS[name], case, Path(folder))
    assert kind in ("error", "accepted"), f"{name}: {kind}: {detail}\ncase: {case!r}"


@pytest.mark.parametrize("recipe, refused", [
    (b"allow 1\nt 1 0 0\nstore 1\n", "FIFO"),                        # external storage is a FIFO
    (b"allow 1\nt 7 0 0\n", "outside this file's folder"),          # /dev/zero as storage
    (b"allow 0\nt 1 0 0\n", "refused unless --allow-external"),
    (b"allow 1\nt 2 0 1\n", "file not found"),                       # virtual source missing
    (b"allow 0\nt 3 1000000000000 0\n", "chunks are written"),       # 10^12 declared, none written
    (b"allow 0\nx 4 0 0\n", "expected a dataset, found a group"),
])
def test_the_hdf5_reproducers_as_recipes(recipe, refused):
    with tempfile.TemporaryDirectory() as folder:
        kind, detail = outcome(TARGETS["hdf5 storage"], recipe, Path(folder))
    assert kind == "error" and refused in detail, detail


@pytest.mark.parametrize("recipe, refused", [(b"ts 1\n", "non-standard message definition"),  # int64 stamps
                                             (b"ts 1\nmd5 1\n", "definition text"),
                                             (b"nsec 1000000000\n", "below 10^9")])
def test_the_ros_reproducers_as_recipes(recipe, refused):
    with tempfile.TemporaryDirectory() as folder:
        kind, detail = outcome(TARGETS["ros definitions"], recipe, Path(folder))
    assert kind == "error" and refused in detail, detail
