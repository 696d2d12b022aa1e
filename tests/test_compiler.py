"""The compiler: budgets, partitioning into cores, halos, traffic and the compiled network."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tofnet import depth_network
from tofnet.compiler import (BUDGETS, LOIHI2, Budget, ChipBudget, CoreBudget, auto_patch,
                             compile_network)
from tofnet.compiler.partition import grid_of, halo_of, max_pixels_per_core, receptive_offsets
from tofnet.errors import BudgetError, TofnetError
from tofnet.io.compiled import compiled_from_dict, compiled_to_dict
from tofnet.processes import DepthProcess, TimeOfTravelProcess


def paper(size=(240, 180), **kwargs):
    return depth_network(size, **kwargs)


# ---------------------------------------------------------------- the paper's numbers

def test_paper_30x30_is_48_plus_48_cores_on_one_chip():
    compiled = compile_network(paper(), LOIHI2, patch=(30, 30))
    assert [(l.name, l.patch, l.grid, l.cores) for l in compiled.layers] == [
        ("time_of_travel", (30, 30), (8, 6), 48), ("depth", (30, 30), (8, 6), 48)]
    assert compiled.cores_used == 96 and compiled.chips_used == 1
    tot, depth = compiled.layers
    assert tot.usage_max == {"accumulators": 7200, "neurons": 3600}
    assert depth.usage_max == {"accumulators": 5400, "neurons": 900}


def test_the_pixel_limit_comes_from_the_budget_and_the_declared_needs():
    tot = paper().process("time_of_travel")
    # 8192 accumulators / 8 per pixel = 1024 pixels: the paper's 32x32.
    assert max_pixels_per_core(tot, LOIHI2.core.limits(), 10**6) == 1024
    compile_network(paper(), patch=(32, 32))
    core = Budget(core=CoreBudget(accumulators=4096))
    assert max_pixels_per_core(tot, core.core.limits(), 10**6) == 512


def test_one_chip_numbers_the_layers_one_after_the_other():
    compiled = compile_network(paper((240, 180)), patch=(30, 30))
    assert [c.index for c in compiled.cores] == list(range(96)) and compiled.chips_used == 1
    assert {c.process for c in compiled.cores[:48]} == {"time_of_travel"}
    assert [c.process for c in compiled.cores_of("depth")] == ["depth"] * 48


def test_on_several_chips_a_regions_layers_share_a_chip():
    compiled = compile_network(paper((346, 260)), patch=(30, 30))
    assert [l.cores for l in compiled.layers] == [108, 108] and compiled.chips_used == 2
    assert [c.index for c in compiled.cores] == list(range(216))
    assert compiled.cores[127].chip == 0 and compiled.cores[128].chip == 1 and compiled.cores[128].slot == 0
    assert compiled.layer("depth").chips == (0, 1) and compiled.layer("time_of_travel").chips == (0, 1)
    for tot, depth in zip(compiled.cores_of("time_of_travel"), compiled.cores_of("depth")):
        assert tot.rect == depth.rect and tot.chip == depth.chip  # the same region, on one chip
    assert compiled.traffic[1].cross_chip == 0


@pytest.mark.parametrize("size, cores, chips", [((346, 260), 216, 2), ((640, 480), 704, 6), ((1280, 720), 2064, 17)])
def test_larger_sensors_need_more_chips(size, cores, chips):
    compiled = compile_network(paper(size), patch=(30, 30))
    assert (compiled.cores_used, compiled.chips_used) == (cores, chips)


def test_patches_tile_the_sensor_with_ragged_edges():
    compiled = compile_network(paper((346, 260)), patch=(30, 30))
    cores = compiled.cores_of("time_of_travel")
    assert (cores[11].x0, cores[11].x1) == (330, 346) and (cores[-1].y0, cores[-1].y1) == (240, 260)
    owner = compiled.core_map("time_of_travel")
    assert owner.shape == (260, 346)
    counts = np.bincount(owner.ravel())
    assert all(counts[c.index] == c.pixels for c in cores)
    assert cores[-1].usage == {"accumulators": 8 * 16 * 20, "neurons": 4 * 16 * 20}


# ---------------------------------------------------------------- automatic patches

def brute_force_min_cores(sensor, max_pixels):
    return min(grid_of(sensor, (w, h))[0] * grid_of(sensor, (w, h))[1]
               for w in range(1, sensor[0] + 1) for h in range(1, sensor[1] + 1) if w * h <= max_pixels)


@pytest.mark.parametrize("sensor", [(7, 5), (12, 9), (13, 13), (20, 3), (1, 17), (31, 11)])
@pytest.mark.parametrize("max_pixels", [1, 4, 6, 10, 17, 40])
def test_auto_patch_is_minimal(sensor, max_pixels):
    w, h = auto_patch(sensor, max_pixels)
    assert w * h <= max_pixels and w <= sensor[0] and h <= sensor[1]
    nx, ny = grid_of(sensor, (w, h))
    assert nx * ny == brute_force_min_cores(sensor, max_pixels)


def test_auto_compile_uses_the_fewest_cores_that_fit():
    compiled = compile_network(paper(), patch="auto")
    tot, depth = compiled.layers
    assert tot.cores == brute_force_min_cores((240, 180), 1024) == 44
    assert depth.cores == brute_force_min_cores((240, 180), 8192 // 6) == 32
    assert tot.automatic and depth.automatic
    assert all(v <= tot.limits[k] for k, v in tot.usage_max.items())
    assert compile_network(paper()).cores_used == compiled.cores_used  # None means auto


def test_patch_per_layer():
    compiled = compile_network(paper(), patch={"time_of_travel": (30, 30)})
    assert [l.cores for l in compiled.layers] == [48, 32]
    with pytest.raises(BudgetError, match="patch.velocity: no core-placed process"):
        compile_network(paper(), patch={"velocity": (30, 30)})


# ---------------------------------------------------------------- budgets and their errors

def test_a_pixel_that_needs_more_than_a_core_has():
    budget = Budget(core=CoreBudget(accumulators=7))
    with pytest.raises(BudgetError, match="time_of_travel needs 8 accumulators per pixel but a core has 7: 1 over"):
        compile_network(paper(), budget)


def test_a_fixed_patch_too_large_says_which_limit_and_by_how_much():
    with pytest.raises(BudgetError) as err:
        compile_network(paper(), patch=(33, 33))
    message = str(err.value)
    assert "time_of_travel: a 33x33 patch needs 8712 accumulators per core" in message
    assert "but a core has 8192: 520 over" in message and "at most 1024 pixels" in message
    neurons = Budget(core=CoreBudget(neurons=1000))
    with pytest.raises(BudgetError, match="needs 3600 neurons per core .* 1000: 2600 over"):
        compile_network(paper(), neurons, patch=(30, 30))


def test_too_many_chips_says_how_many_are_needed():
    budget = Budget(max_chips=1, name="one-chip")
    with pytest.raises(BudgetError) as err:
        compile_network(paper((346, 260)), budget, patch=(30, 30))
    message = str(err.value)
    assert "needs 216 cores (108 time_of_travel + 108 depth) on 1 chip(s) of 128 cores: 88 over" in message
    assert "allow max_chips: 2" in message and "patch: auto needs 158 cores" in message
    assert compile_network(paper((346, 260)), budget.with_max_chips(2), patch=(30, 30)).chips_used == 2


def test_unknown_resource_needs_a_limit():
    class Hungry(TimeOfTravelProcess):
        resources_per_pixel = {"accumulators": 8, "synapses": 3}

    from tofnet.core.network import Network
    from tofnet.processes import InputProcess
    inp, tot = InputProcess(name="input", sensor_size=(20, 10)), Hungry(name="tot")
    inp.events.connect(tot.events)
    net = Network([inp, tot])
    with pytest.raises(BudgetError, match="no per-core limit for 'synapses'"):
        compile_network(net)
    compiled = compile_network(net, Budget(core=CoreBudget(extra={"synapses": 30})))
    assert compiled.layers[0].usage_max["synapses"] <= 30 and compiled.layers[0].cores == 20
    # a limit spelt like one the network needs would leave that one at its default unseen (8192 accumulators)
    with pytest.raises(BudgetError, match=r"budget.core.synapse: no process of network .* needs 'synapse'; did you "
                                          r"mean 'synapses'\?"):
        compile_network(net, Budget(core=CoreBudget(extra={"synapses": 30, "synapse": 20})))
    with pytest.raises(BudgetError, match=r"budget.core.acumulators: .* did you mean 'accumulators'\? \(its limit "
                                          r"stays 8192\)"):
        compile_network(net, Budget.from_dict({"core": {"acumulators": 100, "synapses": 30}}))
    # a limit of the user's own for other networks is kept, and the report says no process here needs it
    from tofnet.compiler.report import format_report
    mine = compile_network(net, Budget(core=CoreBudget(extra={"synapses": 30, "widgets": 5})))
    assert mine.layers[0].cores == 20 and "  budget: core.widgets: no process of this network needs it" in \
        format_report(mine)
    assert "no process of this network needs" not in format_report(compiled)


def test_budget_dict_round_trip_and_named_budgets():
    budget = Budget(core=CoreBudget(accumulators=4096, neurons=2048, extra={"synapses": 10}),
                    chip=ChipBudget(cores=64), max_chips=3, name="mine")
    assert Budget.from_dict(json.loads(json.dumps(budget.to_dict()))) == budget
    assert Budget.from_dict("kapoho-point").max_chips == 8 and BUDGETS["oheo-gulch"].max_chips == 1
    assert Budget.from_dict({"core": {"accumulators": 4096}}).core.neurons == 8192  # rest from Loihi 2
    assert Budget.from_dict({"base": "kapoho-point", "chip": {"cores": 32}}).max_chips == 8
    with pytest.raises(BudgetError, match="budget.core.neurons: expected a positive whole number"):
        Budget.from_dict({"core": {"neurons": -1}})
    with pytest.raises(BudgetError, match="budget.chips: unknown key"):
        Budget.from_dict({"chips": 2})
    with pytest.raises(BudgetError, match="unknown budget 'loihi3'"):
        Budget.from_dict("loihi3")


# ---------------------------------------------------------------- halos and traffic

def test_tot_halo_is_the_patch_widened_along_u_and_v():
    compiled = compile_network(paper(), patch=(30, 30))
    core = compiled.cores_of("time_of_travel")[9]  # second row, second column: x 30..60, y 30..60
    assert core.rect == (30, 30, 60, 60)
    assert set(core.halo) == {(29, 30, 61, 60), (30, 29, 60, 61)}
    assert core.receives(29, 45) and core.receives(60, 45) and core.receives(45, 29) and core.receives(45, 60)
    assert not core.receives(29, 29) and not core.receives(61, 45) and not core.receives(45, 61)
    ys, xs = np.mgrid[0:180, 0:240]
    mask = core.receives_mask(xs, ys)
    assert mask.sum() == 30 * 30 + 4 * 30
    assert all(mask[y, x] == core.receives(x, y) for x, y in [(29, 45), (29, 29), (61, 45), (0, 0)])
    corner = compiled.cores_of("time_of_travel")[0]
    assert set(corner.halo) == {(0, 0, 31, 30), (0, 0, 30, 31)}  # clipped at the sensor
    depth_core = compiled.cores_of("depth")[9]
    assert depth_core.halo == ((30, 30, 60, 60),)


def test_halo_matches_the_units_facilitating_pixels():
    # Every unit (p, D) of a core needs p - distance*D; the halo holds exactly those
    # pixels plus the patch (for distance <= patch side).
    for distance in (1, 2, 3):
        net = paper((50, 40), time_of_travel={"distance": distance})
        compiled = compile_network(net, patch=(10, 8))
        offsets = receptive_offsets(net.process("time_of_travel"))
        for core in compiled.cores_of("time_of_travel"):
            needed = {(x + dx, y + dy) for x in range(core.x0, core.x1) for y in range(core.y0, core.y1)
                      for dx, dy in offsets if 0 <= x + dx < 50 and 0 <= y + dy < 40}
            ys, xs = np.mgrid[0:40, 0:50]
            got = set(zip(xs[core.receives_mask(xs, ys)].tolist(), ys[core.receives_mask(xs, ys)].tolist()))
            assert got == needed


def test_halo_of_a_patch_narrower_than_distance_has_holes():
    rects = halo_of((10, 0, 11, 1), [(0, 0), (2, 0), (-2, 0)], (20, 1))
    assert rects == [(8, 0, 9, 1), (10, 0, 11, 1), (12, 0, 13, 1)]


def test_input_fanout_and_cores_receiving():
    compiled = compile_network(paper(), patch=(30, 30))
    fanout = compiled.fanout_map("time_of_travel")
    assert fanout.max() == 3 and fanout.min() == 1
    # Interior patch-boundary columns and rows are each sent to one extra core.
    extra = 2 * 7 * 180 + 2 * 5 * 240
    assert fanout.sum() == 240 * 180 + extra
    first = compiled.traffic[0]
    assert (first.source, first.target, first.kind) == ("input.events", "time_of_travel.events", "event")
    assert first.mean_cores == pytest.approx(1 + extra / (240 * 180)) and first.max_cores == 3
    assert compiled.cores_receiving("time_of_travel", 15, 15) == [0]
    assert compiled.cores_receiving("time_of_travel", 29, 29) == [0, 1, 8]
    assert compiled.cores_receiving("time_of_travel", 30, 29) == [0, 1, 9]


def test_tot_to_depth_and_velocity_traffic():
    aligned = compile_network(paper(), patch=(30, 30))
    tot_depth, velocity = aligned.traffic[1], aligned.traffic[2]
    assert (tot_depth.mean_cores, tot_depth.links_mean, tot_depth.links_max, tot_depth.cross_chip) == (1, 1, 1, 0)
    assert tot_depth.channels == 4
    assert velocity.kind == "update" and velocity.messages == 48 and velocity.per_second == 48000
    # Depth patches 30x45 against 30x30 time-of-travel patches and 30 px velocity patches:
    # two of the six time-of-travel rows straddle two depth rows; each depth core holds 2 A t.
    mixed = compile_network(paper(), patch={"time_of_travel": (30, 30), "depth": (30, 45)})
    assert mixed.traffic[1].links_max == 2 and mixed.traffic[1].links_mean == pytest.approx((4 * 1 + 2 * 2) / 6)
    assert mixed.traffic[1].mean_cores == 1 and mixed.traffic[2].messages == 8 * 4 * 2
    per_pixel = compile_network(paper(velocity={"per": "pixel", "update_every": 10}), patch=(30, 30))
    assert per_pixel.traffic[2].messages == 240 * 180 and per_pixel.traffic[2].per_second == 240 * 180 * 100
    # Depth cores taller than time-of-travel cores: a few regions straddle the chip seam.
    two_chips = compile_network(paper((346, 260)), patch={"time_of_travel": (30, 30), "depth": (30, 40)})
    assert two_chips.chips_used == 2 and 0 < two_chips.traffic[1].cross_chip < 0.1


# ---------------------------------------------------------------- the compiled network

def test_compiled_network_round_trips_through_json():
    compiled = compile_network(paper((100, 70), time_of_travel={"distance": 2}),
                               Budget(core=CoreBudget(accumulators=4096), max_chips=2, name="x"),
                               patch={"time_of_travel": (20, 20), "depth": "auto"})
    data = json.loads(json.dumps(compiled_to_dict(compiled)))
    again = compiled_from_dict(data)
    assert compiled_to_dict(again) == compiled_to_dict(compiled)
    assert again.cores == compiled.cores and again.layers == compiled.layers and again.budget == compiled.budget
    assert again.network.process("time_of_travel").distance == 2
    assert again.network.process("time_of_travel").sensor_size == (100, 70)
    assert data["summary"]["cores_used"] == compiled.cores_used


def test_host_processes_take_no_cores():
    compiled = compile_network(paper())
    assert compiled.host == ("input", "velocity")
    assert {c.process for c in compiled.cores} == {"time_of_travel", "depth"}
    assert DepthProcess.placement == "core" and issubclass(BudgetError, TofnetError)
    assert math.isclose(sum(c.pixels for c in compiled.cores_of("depth")), 240 * 180)
