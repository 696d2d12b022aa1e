"""Processes declare their counts; results and the run summary add them up per process, and every
event is accounted for once per process that reads the events."""

from pathlib import Path

import pytest

from tofnet.api import run
from tofnet.cli.run_summary import format_summary
from tofnet.core.counters import KINDS, Count
from tofnet.core.network import Network
from tofnet.core.process import Process
from tofnet.networks import denoised_network, depth_network, improved_network, multi_distance_network
from tofnet.processes import TimeSurfaceProcess, VelocityProcess
from tofnet.testing import TEST_INTRINSICS, ParityGateProcess, merge_events, moving_pattern, noise_events
from tofnet.io.recording import Recording

SENSOR = (24, 18)
FLOW = (250.0, -120.0)  # px/s
VELOCITY = [-FLOW[0] / TEST_INTRINSICS.fx, -FLOW[1] / TEST_INTRINSICS.fy, 0.0]  # a texture at 1 m
CONSTANT = {"source": "constant", "velocity": VELOCITY}
EVENTS = merge_events(moving_pattern(SENSOR, FLOW, 120_000, seed=3, sample_us=50, start_us=1_000),
                      noise_events(SENSOR, 10, 120_000, seed=4))
OUTSIDE = EVENTS[-3:].copy()
OUTSIDE["x"] = SENSOR[0] + 2  # three events beyond the sensor: dropped out of bounds by every reader
OUTSIDE["t"] = EVENTS["t"][-1]
RECORDING = Recording(merge_events(EVENTS, OUTSIDE), intrinsics=TEST_INTRINSICS, sensor_size=SENSOR)


def two_readers() -> Network:
    """The paper's network with the time-surface estimator beside it (both read the events) and a
    user's process on the input's spikes."""
    paper = depth_network(SENSOR, velocity=CONSTANT)
    surface = TimeSurfaceProcess(name="surface", sensor_size=SENSOR)
    velocity = VelocityProcess(name="surface_velocity", per="pixel", **CONSTANT)
    velocity.a_t.connect(surface.a_t)
    gate = ParityGateProcess(name="gate")
    paper.process("input").events.connect(gate.events)
    return Network([*paper.processes, surface, velocity, gate], name="two_readers")


ROTATION = {"source": "constant", "omega": [0.0, 0.0, 0.2]}  # rad/s: what tofnet run adds for a turning recording
LENS = {"model": "radtan", "coefficients": [-0.05, 0.01, 0.0, 0.0], "intrinsics": [200.0, 200.0, 12.0, 9.0]}

#: Every built-in network (tofnet.networks, and the variants tofnet run builds from them), and a
#: user's network with two readers.
NETWORKS = {
    "paper": lambda: depth_network(SENSOR, velocity=CONSTANT),
    "paper, rotation": lambda: depth_network(SENSOR, velocity=CONSTANT, rotation=ROTATION),
    "paper, undistorted": lambda: depth_network(SENSOR, velocity=CONSTANT, undistort=LENS),
    "improved": lambda: improved_network(SENSOR, velocity=CONSTANT),
    "improved, rotation": lambda: improved_network(SENSOR, velocity=CONSTANT, rotation=ROTATION),
    "distances": lambda: multi_distance_network(SENSOR, velocity=CONSTANT),
    "denoised": lambda: denoised_network(SENSOR, velocity=CONSTANT),
    "two readers": two_readers,
}


def test_every_built_in_process_declares_the_counts_its_models_keep():
    for process_type in Process._registry.values():
        for count in process_type.counters:
            assert count.kind in KINDS and count.name
    with pytest.raises(TypeError, match="kind"):
        Count("x", "lost")


def test_networks_covers_every_built_in_network():
    import tofnet.networks
    from tofnet.api import ESTIMATORS

    built_in = {name for name, value in vars(tofnet.networks).items() if name.endswith("_network") and callable(value)}
    assert built_in == {"depth_network", "improved_network", "multi_distance_network", "denoised_network"}, \
        "a new built-in network: add it (and its variants) to NETWORKS"
    assert set(ESTIMATORS.values()) == {depth_network, improved_network}  # what tofnet run --estimator builds


@pytest.mark.parametrize("name", list(NETWORKS))
def test_the_summary_accounts_for_every_event_once_per_reader(name):
    network = NETWORKS[name]()
    result, _ = run(RECORDING, network, backend="reference")
    readers = [p.name for p in network.processes if any(c.kind == "read" for c in type(p).counters)]
    summary = result.summary()
    assert list(summary["readers"]) == readers and readers
    for reader, account in summary["readers"].items():
        assert account["events_in"] == len(RECORDING.events), reader
        assert account["events_in"] == account["accepted"] + sum(account["dropped"].values()), reader
        assert account["dropped"]["out_of_bounds"] == len(OUTSIDE), reader
        assert account["accepted"] == result.counts[reader]["accepted"] > 0
    first = summary["readers"][readers[0]]
    assert (summary["events_in"], summary["accepted"], summary["dropped"]) == \
        (first["events_in"], first["accepted"], first["dropped"])
    assert summary["latency"] == result.latency and set(result.latency) == set(result.outputs)
    # every count a model kept is one its process declares
    for process in network.processes:
        assert set(result.counts[process.name]) <= {c.name for c in type(process).counters}, process.name

    text = format_summary({**summary, "recording": "rec", "total_time_s": 1.0}, result,
                          {out: Path(f"{out}.npz") for out in result.outputs}, SENSOR)
    accepted = [int(line.split()[1].replace(",", "")) for line in text.splitlines() if line.startswith("  accepted")]
    assert accepted == [summary["readers"][r]["accepted"] for r in readers]
    assert text.count("events in") == len(readers)
    assert text.count(f"warning        {len(OUTSIDE)} events lay outside the 24x18 sensor") == 1
    latencies = set(result.latency.values())
    latency_lines = [line for line in text.splitlines() if line.startswith("latency")]
    assert len(latency_lines) == (1 if len(latencies) == 1 else len(result.latency))
    # every count no other line says (a denoiser's drops, a user's gate; with several outputs the spikes and
    # the estimators' rejections too) is on its process's line
    one_depth = len(result.depth_outputs) == 1  # then the totals, the depth's and the lens's counts have lines
    skipped = {(summary.get("undistortion") or {}).get("process")} | \
        ({result.depth_outputs[0].partition(".")[0]} if one_depth else set())
    for process, counts in result.counts.items():
        kinds = result.declared[process]
        own = [k for k in counts if not (one_depth and kinds[k].get("total"))
               and not (process in readers and kinds[k]["kind"] in ("read", "accepted", "dropped"))]
        if process not in skipped and own:
            line = next(line for line in text.splitlines() if line.startswith(f"{process:<14} "))
            assert all(f"{k.replace('_', ' ')} {counts[k]:,}" in line for k in own), line
    for process in result.counts:  # and none twice (the undistort process's counts are its lens line's)
        assert sum(line.startswith(f"{process:<14} ") for line in text.splitlines()) <= 1, process


def test_two_readers_are_not_summed_and_each_output_has_its_latency():
    result, _ = run(RECORDING, two_readers(), backend="reference")
    summary = result.summary()
    assert summary["accepted"] == result.counts["input"]["accepted"]  # not input's + the surface's
    assert "rejected" not in summary and result.rejected == {}  # two depth outputs: per process in counts
    assert result.latency["surface.depth"] == 1 and result.latency["depth.depth"] == 2
    assert result.counts["gate"]["passed"] == len(result.outputs["gate.passed"])
    assert result.declared["gate"] == {"passed": {"kind": "output", "total": ""}}
    assert summary["tot_spikes"] == result.counts["time_of_travel"]["spikes"] > 0
    # the depth files' facts stay as they were: the report-only keys are not in them
    assert "readers" not in result.facts() and "latency" not in result.facts()
