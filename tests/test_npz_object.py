"""A pickled metadata dictionary in a .npz (EVIMO's ``meta``) is read without running anything from the file:
hostile names are refused before they are looked up, and corrupt pickles end in one-line errors."""

import io
import pickle
import zipfile

import numpy as np
import pytest

from tofnet.errors import DataError
from tofnet.fuzzing import OPS, mutate
from tofnet.io.npz_object import read_npz_object

META = {"frames": [{"id": 0, "ts": 0.03, "gt_frame": "depth_mask_0.png",
                    "cam": {"pos": {"t": {"x": 0.1, "y": 0.0, "z": 0.0}, "q": {"w": 1.0, "x": 0.0, "y": 0.0, "z": 0.0}}}}],
        "meta": {"fx": np.float64(200.0), "res_x": 640, "dist_model": "radtan"}}


def _npz_with_pickle(path, body: bytes) -> None:
    """An .npz whose member meta.npy is a 0-d object array's header followed by ``body`` (stored: no CRC in the
    way of an edited pickle)."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "|O", "fortran_order": False, "shape": ()})
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as archive:
        archive.writestr("meta.npy", header.getvalue() + body)


def _pickle_of(value) -> bytes:
    array = np.empty((), dtype=object)
    array[()] = value
    return pickle.dumps(array, protocol=3)


class _Call:
    """Pickles as a call of ``function`` (module, name) with ``args``: what a hostile file would hold."""

    def __init__(self, function, args):
        self.function, self.args = function, args

    def __reduce__(self):
        return self.function, self.args


def test_the_dictionary_is_read(tmp_path):
    _npz_with_pickle(tmp_path / "info.npz", _pickle_of(META))
    assert read_npz_object(tmp_path / "info.npz", "meta") == META


@pytest.mark.parametrize("function, args", [
    (__import__("os").system, ("touch {marker}",)),
    (eval, ("open({marker!r}, 'w')",)),
    (exec, ("open({marker!r}, 'w')",)),
    (__import__("subprocess").Popen, (["touch", "{marker}"],)),
    (open, ("{marker}", "w")),
    (getattr, (np.ndarray, "tofile")),  # an allowed name as the object: getattr itself is refused
    (np.save, ("{marker}", np.zeros(1))),
])
def test_a_pickle_naming_anything_else_is_refused_and_nothing_runs(tmp_path, function, args):
    marker = tmp_path / "ran"
    filled = tuple(a.format(marker=marker) if isinstance(a, str) else
                   [w.format(marker=marker) for w in a] if isinstance(a, list) else a for a in args)
    _npz_with_pickle(tmp_path / "info.npz", _pickle_of({"meta": _Call(function, filled)}))
    with pytest.raises(DataError, match=r"info.npz\[meta\]: not a readable object array: refers to .*: not read"):
        read_npz_object(tmp_path / "info.npz", "meta")
    assert not marker.exists() and not (tmp_path / "ran.npy").exists()


def test_edited_pickles_end_in_plain_data_or_a_one_line_error(tmp_path):
    body = _pickle_of(META)
    rng = np.random.default_rng(0)
    outcomes = {"read": 0, "refused": 0}
    for case in range(400):
        edits = [(OPS[int(rng.integers(len(OPS)))], int(rng.integers(2**20)), int(rng.integers(200)))
                 for _ in range(int(rng.integers(1, 4)))]
        _npz_with_pickle(tmp_path / "info.npz", mutate(body, edits))
        try:
            read_npz_object(tmp_path / "info.npz", "meta")
            outcomes["read"] += 1
        except DataError as err:
            assert "\n" not in str(err)
            outcomes["refused"] += 1
    assert outcomes["refused"] > 100  # the edits reached the unpickler, which refused what was not plain data


class _Reduce:
    """Pickles as ``function(*args)`` with an optional BUILD ``state``: forged numpy objects."""

    def __init__(self, function, args, state=None):
        self.function, self.args, self.state = function, args, state

    def __reduce__(self):
        return (self.function, self.args) if self.state is None else (self.function, self.args, self.state)


def _wrapped(obj) -> bytes:
    """The 0-d object array numpy pickles, holding ``obj`` (which may be forged)."""
    from numpy._core.multiarray import _reconstruct
    return pickle.dumps(_Reduce(_reconstruct, (np.ndarray, (0,), b"b"), (1, (), np.dtype("O"), False, [obj])),
                        protocol=3)


def _forged_dtype(flags):  # a structured dtype with an object field whose flags say it holds none
    return _Reduce(np.dtype, ("V8", False, True), (3, "|", None, ("a",), {"a": (np.dtype("O"), 0)}, 8, 1, flags))


@pytest.mark.parametrize("forged, what", [
    (_Reduce(np.ndarray, ((1,), _forged_dtype(0), b"A" * 8)), "dtype 'V8'"),  # raw bytes read as a pointer
    (_Reduce(np.ndarray, ((2**28,), np.dtype("O"))), "not callable"),  # 362 bytes allocating 2 GB
    (_Reduce(np.dtype, ("O8", False, True), (3, "|", None, None, None, -1, -1, 0)), "a dtype state other than"),
    (_Reduce(__import__("numpy._core.multiarray", fromlist=["x"])._reconstruct, (np.ndarray, (0,), b"b"),
             (1, (1,), np.dtype("O"), False, [1])), "an array other than one object"),
])
def test_numpy_objects_forged_from_allowed_names_are_refused(tmp_path, forged, what):
    """The names an object array needs, used to build other numpy objects: a forged dtype or array could point
    numpy at memory the file chooses or allocate what it declares (found in review: a segmentation fault)."""
    _npz_with_pickle(tmp_path / "info.npz", _wrapped({"meta": {"fx": forged}}))
    with pytest.raises(DataError, match=f"info.npz\\[meta\\]: not a readable object array: .*{what}"):
        read_npz_object(tmp_path / "info.npz", "meta")


def test_numpy_scalars_in_the_dictionary_are_read_as_numbers(tmp_path):
    _npz_with_pickle(tmp_path / "info.npz", _wrapped({"fx": np.float64(200.5), "n": np.int32(7), "ok": np.bool_(True)}))
    value = read_npz_object(tmp_path / "info.npz", "meta")
    assert value == {"fx": 200.5, "n": 7, "ok": True} and type(value["fx"]) is float
