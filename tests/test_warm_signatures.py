"""One compiled signature per kernel whatever the input's kind, so ``tofnet warmup`` covers real runs.

numba compiles a kernel again for every new combination of argument types, and an array's type
includes its layout ('C' for a contiguous array, 'A' for a strided view: the field of a record
array is 'A' with two records or more and 'C' with 0 or 1) and whether it is read-only. A kernel
whose argument types depend on the reader, the packet's size or how the bytes were read compiled
after ``tofnet warmup`` on real-sensor files (an EVT3 file's words are read-only, faery's packets
carry uint64 times and bool polarities, a live packet may hold one event). These tests call each
such kernel the ways the real paths and the warmer do and check that its dispatcher holds one
overload (cheap: no fresh cache, no warmup).
"""

from __future__ import annotations

import numpy as np

from tofnet.events import EVENT_DTYPE

FAERY_DTYPE = np.dtype([("t", "<u8"), ("x", "<u2"), ("y", "<u2"), ("on", "?")])


def test_the_evt3_decoder_has_one_signature_for_writable_read_only_and_empty_words(tmp_path):
    from tofnet.io import evt3

    words = np.array([0x8001, 0x0002, 0x6003, 0x2804, 0x3005, 0x4003], "<u2")
    kinds = [words,                                   # the warmer's (and a ROS message's): writable
             np.frombuffer(words.tobytes(), "<u2"),  # a file's block: read-only
             words[:0], words[:1]]
    decoded = [evt3.decode_words(w, 24, 18, 0, evt3.new_state()) for w in kinds]
    assert np.array_equal(decoded[0], decoded[1]) and len(decoded[0]) == 3 and len(decoded[2]) == 0
    path = tmp_path / "a.raw"
    path.write_bytes(b"% evt 3.0\n% geometry 24x18\n" + words.tobytes())
    assert np.array_equal(np.concatenate(list(evt3.decode_file(path, 24, 18))), decoded[0])
    assert len(evt3._decode.signatures) == 1, evt3._decode.signatures


def test_rechunking_has_one_signature_for_every_readers_packets():
    """tofnet's own packets (``EVENT_DTYPE``), faery's (uint64 t, bool polarity), a packet of one event
    and a read-only (memory-mapped) one: one ``_copy_checked``, the same events out."""
    from tofnet.io import event_source

    ours = np.zeros(5, EVENT_DTYPE)
    ours["t"], ours["x"], ours["y"], ours["p"] = [1, 2, 3, 4, 5], [0, 1, 2, 3, 4], [4, 3, 2, 1, 0], [1, 0, 1, 0, 1]
    faery = np.zeros(5, FAERY_DTYPE)
    faery["t"], faery["x"], faery["y"], faery["on"] = ours["t"], ours["x"], ours["y"], ours["p"].astype(bool)
    read_only = ours.copy()
    read_only.flags.writeable = False
    for packets in ([ours[:2], ours[2:3], ours[3:]], [faery[:1], faery[1:]], [read_only], [faery]):
        chunks = list(event_source._rechunk(iter(packets), 4))
        assert np.array_equal(np.concatenate([c for c, _ in chunks]), ours)
        assert all(back == -1 for _, back in chunks)
    assert len(event_source._copy_checked.signatures) == 1, event_source._copy_checked.signatures


def test_the_input_filter_and_depth_layer_have_one_signature_for_packets_of_any_size():
    """The paper's network model by model (as ``tofnet live`` feeds 1 ms packets: some hold 0 or 1
    events, or yield 0 or 1 counter spikes or velocity updates): one ``filter_events``, one
    ``depth_from_counts``."""
    from tofnet.backends.registry import get_backend
    from tofnet.kernels.depth_counts import depth_from_counts
    from tofnet.kernels.input_filter import filter_events
    from tofnet.networks import depth_network
    from tofnet.testing import TEST_INTRINSICS, moving_edge
    from tofnet.io.recording import Recording

    recording = Recording(moving_edge((16, 12), -50.0, "u"), intrinsics=TEST_INTRINSICS)
    network = depth_network((16, 12), velocity={"source": "constant", "velocity": [-0.1, 0.0, 0.0]})
    stream = get_backend("fixed", fuse=False).open_stream(network, recording=recording)
    events = recording.events
    cuts = [0, 1, 1, 2, len(events) // 2, len(events)]
    for a, b in zip(cuts[:-1], cuts[1:]):
        stream.feed(events[a:b])
    assert len(filter_events.signatures) == 1, filter_events.signatures
    assert len(depth_from_counts.signatures) == 1, depth_from_counts.signatures


def test_the_workers_warmer_touches_fresh_output_with_the_types_the_bands_do(monkeypatch):
    """``touch`` runs only for packets of ``SERIAL_BELOW`` events or more, in threads: the warmer calls it
    directly, with the argument types ``BandedKernel.run_events`` passes (one overload after both)."""
    from tofnet.backends import bands as bands_module
    from tofnet.backends.registry import get_backend
    from tofnet.kernels.bands import touch
    from tofnet.networks import depth_network
    from tofnet.testing import TEST_INTRINSICS, moving_edge
    from tofnet.io.recording import Recording
    from tofnet.warmup import touch_as_bands_do

    touch_as_bands_do()
    monkeypatch.setattr(bands_module, "SERIAL_BELOW", 0)
    recording = Recording(moving_edge((24, 16), -50.0, "u"), intrinsics=TEST_INTRINSICS)
    network = depth_network((24, 16), velocity={"source": "constant", "velocity": [-0.1, 0.0, 0.0]})
    stream = get_backend("fixed", workers=2).open_stream(network, recording=recording)
    stream.kernel.one_band_below = 0
    stream.feed_all(recording.events[:50])  # builds the bands
    into = np.empty(1 << 18, stream.kernel.buffers()[0].dtype)  # fresh: 7 MB
    stream.kernel.run_events(recording.events[50:], stream._updates.rows, into, 0)
    assert stream.kernel._touched[2] > 0  # the real path touched
    assert len(touch.signatures) == 1, touch.signatures


def test_the_event_stream_end_check_has_the_warmers_signature(tmp_path):
    """The warmer walks a writable array; the reader's chunks (``np.fromfile``) are writable too."""
    from tofnet.io import event_stream_tail

    event_stream_tail.walk_bytes(np.zeros(5, np.uint8), 0, 0xFE)
    path = tmp_path / "a.es"
    path.write_bytes(b"Event Stream\x02\x00\x00\x01\x10\x00\x08\x00" + bytes([0xFF, 2, 3, 0, 4, 0, 6, 1]))
    assert event_stream_tail.partial_event_bytes(path, "dvs") == 2  # an overflow, an event, 2 bytes of one
    assert len(event_stream_tail.walk_bytes.signatures) == 1, event_stream_tail.walk_bytes.signatures
