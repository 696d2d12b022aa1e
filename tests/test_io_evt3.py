"""EVT3 timing: tofnet's decoder keeps the time base of Prophesee's specification (tofnet.io.evt3).

The stream below is built by hand from the format's words. Its middle part has the layout of
the expelliarmus project's public ``evt3_sample.raw``: a TIME_LOW of 811 followed directly by
a TIME_LOW of 800, with no event between, so the events after it are at 800 µs, not 811.
"""

import numpy as np
import pytest

from optional import optional
from tofnet.io.evt3 import clamped_of, decode_words, new_state

HIGH, LOW, Y, X, BASE, VECT12, VECT8 = 0x8000, 0x6000, 0x0000, 0x2000, 0x3000, 0x4000, 0x5000
ON = 0x800
BASE_US = 5 << 12  # TIME_HIGH 5

WORDS = [
    HIGH | 5, Y | 10,
    LOW | 790, X | ON | 3,            # one event at 790
    LOW | 811, LOW | 800,             # 811 then 800, nothing between
    X | ON | 4,                       # 800 (faery 0.7: 811)
    BASE | 8, VECT12 | 0b101,         # x 8 and 10, OFF, at 800
    LOW | 805, X | 5,                 # 805 (faery 0.7: 811)
    LOW | 812, X | 6,                 # 812
    LOW | 700, X | 7,                 # the stream really goes back: given 812 and counted
    HIGH | 4095, LOW | 0, X | 1,      # end of the 24-bit range ...
    HIGH | 0, VECT8 | 0b1,            # ... wraps: 2**24 µs later; the vectors' base moved on to x 20
]
EXPECTED_T = [790, 800, 800, 800, 805, 812, 812]
EXPECTED_X = [3, 4, 8, 10, 5, 6, 7, 1, 20]


def _decode(words, width=64, height=48):
    state = new_state()
    events = decode_words(np.array(words, dtype="<u2"), width, height, 0, state)
    return events, state


def test_time_low_going_back_without_an_event_is_the_specifications_time():
    events, state = _decode(WORDS)
    assert list(events["x"]) == EXPECTED_X
    assert list(events["t"][:7] - BASE_US) == EXPECTED_T
    assert list(events["p"]) == [1, 1, 0, 0, 0, 0, 0, 0, 0]
    assert list(events["t"][7:]) == [(4095 << 12), 1 << 24]
    assert np.all(np.diff(events["t"]) >= 0)
    assert clamped_of(state) == 1  # only the event whose own time was earlier than the one before


def test_blocks_carry_the_state():
    whole, _ = _decode(WORDS)
    state = new_state()
    parts = [decode_words(np.array(WORDS[i:i + 3], dtype="<u2"), 64, 48, 0, state) for i in range(0, len(WORDS), 3)]
    assert np.array_equal(np.concatenate(parts), whole)


def test_coordinates_outside_the_geometry_are_refused():
    with pytest.raises(ValueError, match="y 48 outside the header.s 64x48 geometry at word 1 of the block"):
        _decode([HIGH | 1, Y | 48, X | 1])
    with pytest.raises(ValueError, match="x 64 outside"):
        _decode([HIGH | 1, Y | 1, X | 64])


def _file(tmp_path, words):
    path = tmp_path / "pattern.raw"
    path.write_bytes(b"% evt 3.0\n% geometry 64x48\n% t0 1000\n" + np.array(words, dtype="<u2").tobytes())
    return path


def test_the_reader_gives_the_specifications_time_and_notes_the_clamped_event(tmp_path):
    faery = optional("faery")
    from tofnet.io.source import open_recording

    path = _file(tmp_path, WORDS)
    with open_recording(path) as source:
        assert source.detail == "EVT3" and source.sensor_size == (64, 48)
        recording = source.read()
    t = recording.events["t"]
    assert list(t[:7] - BASE_US - 1000) == EXPECTED_T  # the header's t0 added, as faery does
    assert any("1 EVT3 events" in note and "went back" in note for note in recording.notes)
    if faery.__version__.startswith("0.7"):
        # What the docs say of faery 0.7: its clock does not go back, so 800 and 805 come out as 811.
        from faery.extension import evt
        with evt.Decoder(path, None, None) as decoder:
            theirs = np.concatenate([packet["events"] for packet in decoder if "events" in packet])
        assert list(theirs["t"][:5] - BASE_US - 1000) == [790, 811, 811, 811, 811]


def test_a_file_cut_inside_a_word_is_read_to_its_last_whole_word_and_noted(tmp_path):
    optional("faery")
    from tofnet.io.source import open_recording

    whole = open_recording(_file(tmp_path, WORDS)).read()
    path = tmp_path / "cut.raw"
    path.write_bytes(_file(tmp_path, WORDS).read_bytes() + b"\x01")  # one byte of a word more
    with open_recording(path) as source:
        recording = source.read()
    assert np.array_equal(recording.events, whole.events)
    assert "the file ends with 1 byte of a partial 2-byte word (not read): truncated?" in recording.notes
