"""Outputs other tools load: dense depth maps (.npy, 16-bit PNG) and .ply point clouds; `tofnet export`."""

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError
from tofnet.events import DEPTH_DTYPE
from tofnet.io.groundtruth import Trajectory
from tofnet.io.maps import depth_maps, depth_to_png16, write_depth_maps
from tofnet.io.ply import depth_points, write_ply
from tofnet.io.recording import Intrinsics
from optional import optional

INTRINSICS = Intrinsics(100.0, 110.0, 4.0, 3.0)


def _depth(rows):
    depth = np.zeros(len(rows), dtype=DEPTH_DTYPE)
    for i, (t, x, y, z) in enumerate(rows):
        depth[i] = (t, x, y, z, t // 1000)
    return depth


def test_maps_keep_the_latest_estimate_and_its_age():
    depth = _depth([(1000, 1, 1, 2.0), (4000, 1, 1, 3.0), (6000, 2, 1, 5.0), (25_000, 0, 0, 1.0)])
    maps = list(depth_maps(depth, (8, 6), 10_000, t0_us=0))
    # window 1: nothing new and max_age = window, so no depth: not made
    assert [m.index for m in maps] == [0, 2] and [m.estimates for m in maps] == [3, 1]
    first = maps[0]
    assert first.depth[1, 1] == 3.0 and first.age_ms[1, 1] == pytest.approx(6.0)
    assert first.depth[1, 2] == 5.0 and np.isnan(first.depth[0, 0]) and np.isnan(first.age_ms[0, 0])
    held = list(depth_maps(depth, (8, 6), 10_000, t0_us=0, max_age_us=20_000))
    assert [m.index for m in held] == [0, 1, 2] and [m.estimates for m in held] == [3, 0, 1]
    assert held[1].depth[1, 1] == 3.0 and held[1].age_ms[1, 1] == pytest.approx(16.0)
    with pytest.raises(DataError, match="outside the 2x2 map"):
        list(depth_maps(depth, (2, 2), 10_000))


def test_maps_of_estimates_far_apart_are_few_and_bounded():
    """Two estimates 2**61 µs apart made a window per millisecond between them (16 PiB asked for before any was
    written); only windows with depth are made, and more maps than MAX_MAPS is one line before the first."""
    from tofnet.units import MAX_MAPS
    far = _depth([(0, 1, 1, 1.0), (2**61 - 2, 2, 1, 2.0)])
    assert [m.index for m in depth_maps(far, (4, 4), 1000, t0_us=0)] == [0, (2**61 - 2) // 1000]
    with pytest.raises(DataError, match=f"far.npz: the estimates .* make 1,000,001 maps of 1 ms, more than the "
                                        f"{MAX_MAPS:,} allowed; give a longer --window"):
        depth_maps(far, (4, 4), 1000, t0_us=0, max_age_us=10**9, source="far.npz")  # each held for 1,000,000 windows
    with pytest.raises(DataError, match="depth: estimates before t0_us = 5000, where the maps start: 1 "):
        depth_maps(far, (4, 4), 1000, t0_us=5000)


def test_png16_holds_millimetres(tmp_path):
    from PIL import Image

    depth = np.array([[np.nan, 0.0015, 1.2345], [65.535, 70.0, -1.0]], dtype=np.float32)
    image, saturated = depth_to_png16(depth)
    assert image.tolist() == [[0, 2, 1234 if np.float32(1.2345) * 1000 < 1234.5 else 1235], [65535, 65535, 0]]
    assert saturated == 1
    done = write_depth_maps(depth_maps(_depth([(500, 1, 0, 1.5), (1500, 0, 1, 2.25)]), (2, 2), 1000, t0_us=0),
                            tmp_path)
    assert done == {"windows": 2, "empty_windows": 0, "saturated_png_pixels": 0}
    with Image.open(tmp_path / "depth_000001.png") as png:
        assert png.mode in ("I;16", "I") and png.size == (2, 2)
        assert np.array(png).tolist() == [[0, 0], [2250, 0]]
    assert np.load(tmp_path / "depth_000000.npy")[0, 1] == 1.5
    assert (tmp_path / "index.csv").read_text().splitlines()[1] == "0,0.000000,0.001000,1,1"


def _read_ply(path):
    """A minimal PLY reader for the files tofnet writes (header, then binary or ASCII vertices)."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    count = int(next(line.split()[2] for line in header if line.startswith("element vertex")))
    names = [line.split()[2] for line in header if line.startswith("property")]
    types = {"float": "<f4", "uchar": "u1"}
    dtype = [(line.split()[2], types[line.split()[1]]) for line in header if line.startswith("property")]
    if "binary_little_endian" in header[1]:
        return np.frombuffer(data[end:], dtype=dtype, count=count), names
    rows = np.loadtxt(data[end:].decode().splitlines(), ndmin=2)
    out = np.zeros(count, dtype=dtype)
    for k, name in enumerate(names):
        out[name] = rows[:, k]
    return out, names


@pytest.mark.parametrize("binary", [True, False])
def test_ply_camera_frame(tmp_path, binary):
    depth = _depth([(0, 4, 3, 2.0), (0, 14, 3, 2.0), (0, 4, 14, 4.0)])
    points = depth_points(depth, INTRINSICS)
    assert np.allclose(points, [[0, 0, 2.0], [0.2, 0, 2.0], [0, 0.4, 4.0]])
    colors = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255]], dtype=np.uint8)
    assert write_ply(tmp_path / "c.ply", points, colors=colors, binary=binary) == 3
    vertices, names = _read_ply(tmp_path / "c.ply")
    assert names == ["x", "y", "z", "red", "green", "blue"]
    assert np.allclose(np.column_stack([vertices["x"], vertices["y"], vertices["z"]]), points)
    assert vertices["blue"].tolist() == [0, 0, 255]
    plyfile = optional("plyfile")
    read = plyfile.PlyData.read(str(tmp_path / "c.ply"))
    assert np.allclose(read["vertex"]["z"], points[:, 2])


def test_ply_world_frame_and_distortion():
    # camera at x = 1 m, turned 90 degrees about y: its optical axis is the world's +x
    trajectory = Trajectory([0.0, 1.0], [[1, 0, 0], [1, 0, 0]], [[0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)]] * 2)
    depth = _depth([(500_000, 4, 3, 2.0)])
    assert np.allclose(depth_points(depth, INTRINSICS, trajectory, frame="world"), [[3.0, 0, 0]])
    with pytest.raises(DataError, match="world frame needs the recording's poses"):
        depth_points(depth, INTRINSICS, None, frame="world")
    distorted = Intrinsics(100.0, 110.0, 4.0, 3.0, (-0.3, 0.0, 0.0, 0.0, 0.0))
    raw = depth_points(_depth([(0, 24, 3, 1.0)]), distorted)
    assert raw[0, 0] > 0.2  # barrel distortion pulled the pixel in: the true ray lies further out
    assert np.allclose(depth_points(_depth([(0, 24, 3, 1.0)]), distorted, raw_pixels=False), [[0.2, 0, 1.0]])


def test_cli_export_maps_and_cloud(tmp_path, capsys):
    from tofnet.io.depth import write_depth
    from tofnet.io.ecd import write_ecd
    from tofnet.testing import moving_edge

    events = moving_edge((8, 6), -50.0, "u")
    write_ecd(tmp_path / "rec", events, intrinsics=INTRINSICS, sensor_size=(8, 6))
    depth = _depth([(1000, 1, 1, 2.0), (12_000, 2, 2, 3.0)])
    write_depth(tmp_path / "depth.npz", depth, t0_us=0, timestep_us=1000, latency_steps=2,
                summary={"recording": str(tmp_path / "rec")})
    assert main(["export", str(tmp_path / "depth.npz"), "--maps", str(tmp_path / "maps"), "--window", "10ms",
                 "--ply", str(tmp_path / "cloud.ply")]) == 0
    out = capsys.readouterr().out
    assert "2 windows of 10ms" in out and "2 points (camera frame)" in out and "without any" not in out
    assert sorted(p.name for p in (tmp_path / "maps").iterdir())[:4] == [".tofnet-manifest.json", "age_000000.npy",
                                                                        "age_000001.npy", "depth_000000.npy"]
    assert main(["export", str(tmp_path / "depth.npz")]) == 2
    assert "nothing to do" in capsys.readouterr().err
    # A 5 s span wrote 501 windows (1504 files of the sensor's size); only the two with depth are written.
    write_depth(tmp_path / "span.npz", _depth([(0, 1, 1, 1.0), (5_000_000, 2, 2, 2.0)]), t0_us=0, timestep_us=1000,
                latency_steps=2, summary={})
    assert main(["export", str(tmp_path / "span.npz"), "--maps", str(tmp_path / "span"), "--sensor-size", "8x6",
                 "--no-png"]) == 0
    assert "2 windows of 10ms with depth -> " in (out := capsys.readouterr().out)
    assert "(index.csv; 499 windows between them without any, not written)" in out  # nothing lost without a count
    assert (tmp_path / "span" / "index.csv").read_text().splitlines()[1:] == ["0,0.000000,0.010000,1,1",
                                                                              "500,5.000000,5.010000,1,1"]
    assert len(list((tmp_path / "span").glob("*.npy"))) == 4
    assert main(["export", str(tmp_path / "span.npz"), "--maps", str(tmp_path / "span2"), "--sensor-size", "8x6",
                 "--window", "1us", "--max-age", "5s"]) == 2
    err = capsys.readouterr().err
    assert "span.npz: the estimates (5 s after t0, each shown up to 5 s) make 5,000,001 maps of 1 µs" in err
    assert len(err.splitlines()) == 1 and not (tmp_path / "span2").exists()


def test_export_uses_the_runs_camera_and_checks_the_cloud_before_any_map(tmp_path, capsys):
    """A recording without a calibration run with --intrinsics: the depth file records the camera, so the
    point cloud needs no second --intrinsics; without any camera nothing is written (maps were, before)."""
    from tofnet.io.depth import read_depth, write_depth
    from tofnet.testing import moving_edge

    np.save(tmp_path / "ev.npy", moving_edge((8, 6), -50.0, "u"))
    out = tmp_path / "d.npz"
    assert main(["run", str(tmp_path / "ev.npy"), "--intrinsics", "100,110,4,3", "--velocity", "0.5,0,0",
                 "--out", str(out), "--quiet"]) == 0
    assert read_depth(out)[1]["summary"]["camera"] == {"intrinsics": [100.0, 110.0, 4.0, 3.0],
                                                         "distortion_model": "radtan", "distortion": []}
    capsys.readouterr()
    assert main(["export", str(out), "--ply", str(tmp_path / "cloud.ply"), "--maps", str(tmp_path / "maps")]) == 0
    assert "camera         the run's, from" in capsys.readouterr().out and (tmp_path / "cloud.ply").is_file()
    depth, meta = read_depth(out)
    write_depth(tmp_path / "bare.npz", depth, t0_us=meta["t0_us"], timestep_us=1000, latency_steps=2,
                summary={"recording": str(tmp_path / "ev.npy")})  # a depth file that names no camera
    assert main(["export", str(tmp_path / "bare.npz"), "--maps", str(tmp_path / "maps2"), "--ply",
                 str(tmp_path / "cloud2.ply")]) == 2
    assert "pass --intrinsics FX,FY,CX,CY" in capsys.readouterr().err
    assert not (tmp_path / "maps2").exists() and not (tmp_path / "cloud2.ply").exists()


@pytest.mark.parametrize("camera", [{"intrinsics": [100, 110, 4]}, {"intrinsics": [100, 110, 4, 3], "distortion": [0.1] * 3},
                                    {"intrinsics": [-1, 110, 4, 3]}, {"intrinsics": [100, float("nan"), 4, 3]},
                                    {"intrinsics": [100, 110, 4, 3], "distortion_model": "bogus"}, "camera"])
def test_a_depth_files_camera_is_checked_as_intrinsics_are(tmp_path, capsys, camera):
    """The depth file may come from someone else: a camera tofnet run would not write is one line, not a
    traceback from the lens code or an empty cloud."""
    from tofnet.io.depth import write_depth
    from tofnet.testing import moving_edge

    np.save(tmp_path / "ev.npy", moving_edge((8, 6), -50.0, "u"))
    write_depth(tmp_path / "d.npz", _depth([(1000, 1, 1, 2.0)]), t0_us=0, timestep_us=1000, latency_steps=2,
                summary={"recording": str(tmp_path / "ev.npy"), "camera": camera})
    assert main(["export", str(tmp_path / "d.npz"), "--ply", str(tmp_path / "c.ply")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "its summary's camera is not one tofnet run writes" in err
    assert not (tmp_path / "c.ply").exists()


def test_export_maps_beyond_the_free_space_are_refused_before_any_is_written(tmp_path, monkeypatch, capsys):
    """1,078 windows of a 1280x720 run became 7.5 GB of dense maps (for 95,944 estimates), the disk unchecked."""
    import collections
    import shutil

    from tofnet.io.depth import write_depth
    write_depth(tmp_path / "d.npz", _depth([(k * 10_000 + 1, k, k, 2.0) for k in range(10)]), t0_us=0,
                timestep_us=1000, latency_steps=2, summary={})
    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**12, 0, 20_000_000))
    common = ["export", str(tmp_path / "d.npz"), "--maps", str(tmp_path / "maps"), "--sensor-size", "640x480"]
    assert main(common) == 2
    each = 2 * (128 + 4 * 640 * 480) + 96 + 480 * 1281 + 480 * 1281 // 1000 + 1024
    assert capsys.readouterr().err.strip() == (
        f"tofnet export: error: {tmp_path / 'maps'}: --maps: 10 maps of 640x480 px need up to "
        f"{(10 * each + (1 << 20)) / 1e6:.3g} MB ({each / 1e6:.3g} MB each: depth .npy + age .npy + PNG (counted "
        "uncompressed)), the file system has 20 MB free; give a longer --window, --no-age, --no-png, or --ply "
        "alone (a point cloud)")
    assert not (tmp_path / "maps").exists()
    assert main(common + ["--no-age", "--no-png"]) == 0  # 12.3 MB of depth maps fit
    written = sorted(p.name for p in (tmp_path / "maps").iterdir())
    assert written == [".tofnet-manifest.json", *(f"depth_{k:06d}.npy" for k in range(10)), "index.csv"]


def test_the_maps_size_estimate_is_exact_for_npy_and_bounds_the_pngs(tmp_path):
    rng = np.random.default_rng(2)
    n = 3000  # every pixel of a 40x30 map holds depth in each of the 3 windows: the PNGs hardly compress
    depth = _depth(sorted((int(t), int(x), int(y), float(z)) for t, x, y, z in
                          zip(rng.integers(0, 30_000, n), rng.integers(0, 40, n), rng.integers(0, 30, n),
                              rng.uniform(0.5, 60, n))))
    for age, png in ((True, True), (False, False)):
        maps = depth_maps(depth, (40, 30), 10_000, t0_us=0)
        each = maps.map_bytes(age=age, png=png)
        write_depth_maps(maps, tmp_path / f"m{age}{png}", png=png, age=age)
        files = {p.name: p.stat().st_size for p in (tmp_path / f"m{age}{png}").iterdir()}
        npy = sum(size for name, size in files.items() if name.endswith(".npy"))
        assert npy == maps.windows * (1 + age) * (128 + 4 * 40 * 30) and maps.windows == 3
        assert sum(files.values()) - files[".tofnet-manifest.json"] <= maps.windows * each
