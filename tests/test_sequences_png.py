"""DSEC disparity maps are read safely: only regular files, and a map's size is checked from its
PNG header before any pixel is decoded (docs/reliability.md, "Reading files")."""

from __future__ import annotations

import os
import shutil
import struct
import zlib

import numpy as np
import pytest

from tests.fifos import fifo_in_place, needs_fifo, watched
from tests.optional import optional

h5py = optional("h5py")

from PIL import Image  # noqa: E402 - matplotlib's dependency
from tofnet.cli import main  # noqa: E402
from tofnet.errors import DataError  # noqa: E402
from tofnet.events import MAX_SENSOR_PIXELS  # noqa: E402
from tofnet.io import read_recording  # noqa: E402
from tofnet.testing_datasets import make_dsec  # noqa: E402


@pytest.fixture(scope="module")
def dsec(tmp_path_factory):
    return make_dsec(tmp_path_factory.mktemp("dsec") / "zurich_city_00_a", duration_s=0.5)


@pytest.fixture
def folder(dsec, tmp_path):
    shutil.copytree(dsec, tmp_path / "seq")
    return tmp_path / "seq"


def write_blank_png(path, width: int, height: int) -> None:
    """A valid 16-bit grey PNG of zeros, written row by row: ~70 KB at 6000x6000, whose decoding
    would take over 1 GB (the ``int64`` array of its pixels)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    packer, row = zlib.compressobj(9), bytes(1 + 2 * width)  # filter byte 0, then the row's zeros
    data = b"".join(packer.compress(row) for _ in range(height)) + packer.flush()
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0))
                     + chunk(b"IDAT", data) + chunk(b"IEND", b""))


@pytest.fixture
def decoded(monkeypatch):
    """The sizes of the PNGs whose pixels were decoded."""
    from PIL import ImageFile

    sizes, load = [], ImageFile.ImageFile.load

    def counting(image):
        sizes.append(image.size)
        return load(image)

    monkeypatch.setattr(ImageFile.ImageFile, "load", counting)
    return sizes


def test_the_blank_png_helper_writes_what_pil_reads(tmp_path):
    write_blank_png(tmp_path / "a.png", 5, 3)
    with Image.open(tmp_path / "a.png") as image:
        assert image.size == (5, 3) and image.mode.startswith("I;16")
        assert not np.asarray(image).any()


@needs_fifo
@pytest.mark.parametrize("name", ["000000.png", "000004.png"])  # checked at open / when the frame is read
def test_a_fifo_among_the_disparity_maps_is_refused_without_blocking(folder, name):
    fifo = fifo_in_place(folder / "disparity" / "event" / name)
    outcome = watched(lambda: read_recording(folder), fifo)
    err = outcome.get("error")
    assert isinstance(err, DataError), outcome
    assert f"{name}: is a FIFO (named pipe), expected a regular disparity map" in str(err)


@needs_fifo
def test_info_on_a_dsec_folder_with_a_fifo_map_is_one_line_exit_2(folder, capsys):
    fifo = fifo_in_place(folder / "disparity" / "event" / "000000.png")
    outcome = watched(lambda: main(["info", str(folder)]), fifo)
    assert outcome.get("value") == 2, outcome
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert err.endswith("000000.png: is a FIFO (named pipe), expected a regular disparity map")


@needs_fifo
@pytest.mark.parametrize("name, what", [
    ("events/left/events.h5", "the left events of the DSEC sequence"),
    ("events/left/rectify_map.h5", "the rectification map (HDF5)"),
    ("calibration/cam_to_cam.yaml", "the DSEC sequence's calibration"),
    ("disparity/timestamps.txt", "the times of the disparity maps"),
])
def test_a_fifo_as_a_side_file_of_the_sequence_is_named_as_such_not_missing(folder, name, what):
    fifo = fifo_in_place(folder / name)
    outcome = watched(lambda: read_recording(folder), fifo)
    err = outcome.get("error")
    assert isinstance(err, DataError), outcome
    assert f"{fifo.name}: is a FIFO (named pipe), expected {what}" in str(err)


def test_a_folder_named_like_a_disparity_map_is_refused(folder):
    (folder / "disparity" / "event" / "000000.png").unlink()
    (folder / "disparity" / "event" / "000000.png").mkdir()
    with pytest.raises(DataError, match=r"000000\.png: is a folder, expected a (regular )?disparity map"):
        read_recording(folder)


def test_disparity_maps_larger_than_the_sensor_are_refused_before_decoding(folder, decoded):
    # The audit's folder: every map a hard link of one 6000x6000 PNG (agreeing with each other).
    maps = sorted((folder / "disparity" / "event").glob("*.png"))
    big = folder / "big.png"
    write_blank_png(big, 6000, 6000)
    for path in maps:
        path.unlink()
        os.link(big, path)
    with pytest.raises(DataError) as err:
        read_recording(folder)
    assert str(err.value).endswith("000000.png: disparity map is 6000x6000 px, expected 48x32 px "
                                   "(the events' sensor size)")
    assert decoded == []


def test_one_map_of_another_size_is_refused_before_it_is_decoded(folder, decoded):
    write_blank_png(folder / "disparity" / "event" / "000006.png", 6000, 6000)
    with pytest.raises(DataError) as err:
        read_recording(folder)
    assert str(err.value).endswith("000006.png: disparity map is 6000x6000 px, expected 48x32 px "
                                   "(the events' sensor size)")
    assert (48, 32) in decoded and (6000, 6000) not in decoded


def test_without_a_sensor_size_the_first_map_sets_it_within_the_sensor_limit(folder, decoded):
    from tofnet.io.sequences import _q_matrix, dsec_disparity

    q = _q_matrix(folder / "calibration" / "cam_to_cam.yaml")
    frames = dsec_disparity(folder / "disparity", q, None)  # the sensor size unknown: the first map's
    assert (frames.width, frames.height) == (48, 32)
    write_blank_png(folder / "disparity" / "event" / "000002.png", 49, 32)
    with pytest.raises(DataError, match=r"000002\.png: disparity map is 49x32 px, expected 48x32 px "
                                        r"\(the first map's size\)"):
        frames.frame(1)
    side = 4097  # one pixel row and column beyond 4096x4096
    assert side * side > MAX_SENSOR_PIXELS
    write_blank_png(folder / "disparity" / "event" / "000000.png", side, side)
    with pytest.raises(DataError, match=rf"000000\.png: disparity map: at most {MAX_SENSOR_PIXELS:,} pixels"):
        dsec_disparity(folder / "disparity", q, None)
    assert (side, side) not in decoded and (49, 32) not in decoded


def test_a_file_that_is_not_a_png_is_one_line_naming_it(folder):
    (folder / "disparity" / "event" / "000000.png").write_bytes(b"GIF89a" + bytes(100))
    with pytest.raises(DataError) as err:
        read_recording(folder)
    assert str(err.value).endswith("000000.png: not a PNG file")
