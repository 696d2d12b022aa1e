"""--intrinsics and --calib FILE: calib.txt, Kalibr/DSEC YAML, TUM-VIE JSON, ROS camera_info, in the published layouts."""

import json

import numpy as np
import pytest

from tofnet.cli import main
from tofnet.errors import DataError, TofnetError
from tofnet.io.calibration import parse_intrinsics, read_camera_file
from tofnet.io.recording import Intrinsics

from formats_helpers import pattern_recording
from optional import optional

DSEC = """\
intrinsics:
  camRect0:
    camera_matrix: [569.78, 569.78, 335.86, 221.75]
    resolution: [640, 480]
  cam0:
    camera_matrix: [553.47, 553.26, 346.65, 216.52]
    distortion_coeffs: [-0.0948, 0.1976, 7.6e-05, 0.000436]
    distortion_model: radtan
    resolution: [640, 480]
  cam1:
    camera_matrix: [1164.6, 1164.6, 713.6, 570.6]
    distortion_coeffs: [-0.107, 0.0998, 0.0001, 0.0002]
    distortion_model: radtan
    resolution: [1440, 1080]
  cam3:
    camera_matrix: [552.18, 552.09, 336.88, 225.68]
    distortion_coeffs: [-0.0934, 0.1959, 1.2e-04, -0.0002]
    distortion_model: radtan
    resolution: [640, 480]
extrinsics:
  T_10: [[1, 0, 0, -0.06], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
"""

KALIBR = """\
cam0:
  T_cam_imu:
  - [1.0, 0.0, 0.0, 0.0]
  - [0.0, 1.0, 0.0, 0.0]
  - [0.0, 0.0, 1.0, 0.0]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  distortion_coeffs: [-0.048, 0.0113, -0.0493, 0.0194]
  distortion_model: equidistant
  intrinsics: [226.38, 226.15, 173.65, 133.73]
  resolution: [346, 260]
  rostopic: /davis/left/image_raw
cam1:
  camera_model: pinhole
  distortion_coeffs: [-0.0476, 0.0116, -0.0493, 0.0190]
  distortion_model: equidistant
  intrinsics: [226.04, 225.76, 174.58, 124.69]
  resolution: [346, 260]
  rostopic: /davis/right/image_raw
"""

ROS = """\
image_width: 346
image_height: 260
camera_name: davis
camera_matrix:
  rows: 3
  cols: 3
  data: [226.38, 0, 173.65, 0, 226.15, 133.73, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.33, 0.12, 0.0007, 0.0001, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [226.38, 0, 173.65, 0, 0, 226.15, 133.73, 0, 0, 0, 1, 0]
"""


def _tumvie():
    def kb4(fx, cx):
        return {"camera_type": "kb4", "intrinsics": {"fx": fx, "fy": fx + 0.5, "cx": cx, "cy": 360.2,
                                                      "k1": 0.01, "k2": -0.02, "k3": 0.003, "k4": -0.0004}}
    return {"value0": {"T_imu_cam": [{"px": 0, "py": 0, "pz": 0, "qx": 0, "qy": 0, "qz": 0, "qw": 1}] * 4,
                       "intrinsics": [kb4(740.0, 512.0), kb4(741.0, 511.0), kb4(1049.0, 635.0), kb4(1048.0, 636.0)],
                       "resolution": [[1024, 1024], [1024, 1024], [1280, 720], [1280, 720]],
                       "vignette": [], "mocap_time_offset_ns": 0}}


def test_intrinsics_text():
    assert parse_intrinsics("200,201,120,90") == Intrinsics(200, 201, 120, 90)
    assert parse_intrinsics("200,201,120,90,-0.3,0.1,0.001,0.002").distortion == (-0.3, 0.1, 0.001, 0.002, 0.0)
    assert parse_intrinsics("200,201,120,90,-0.3,0.1,0,0,0.05").distortion == (-0.3, 0.1, 0.0, 0.0, 0.05)
    for bad, what in (("1,2,3", "got 3 numbers"), ("0,1,2,3", "focal lengths must be positive"),
                      ("1,1,nan,2", "'cx' is not a finite number"), ("1,1,a,2", "'cx' is not a finite number")):
        with pytest.raises(TofnetError, match=f"^--intrinsics: .*{what}"):
            parse_intrinsics(bad)


def test_each_layout(tmp_path):
    (tmp_path / "cam_to_cam.yaml").write_text(DSEC)
    (tmp_path / "camchain-imucam.yaml").write_text(KALIBR)
    (tmp_path / "camera_info.yaml").write_text(ROS)
    (tmp_path / "calibration.json").write_text(json.dumps(_tumvie()))
    (tmp_path / "calib.txt").write_text("199.0 198.5 132.2 110.1 -0.37 0.15 0 0 0\n")

    dsec, size, what = read_camera_file(tmp_path / "cam_to_cam.yaml")
    assert what == "intrinsics.cam0" and size == (640, 480)  # camRect0 (rectified) only when asked for
    assert read_camera_file(tmp_path / "cam_to_cam.yaml", "camRect0")[0].distortion == ()
    assert (dsec.fx, dsec.cy, dsec.distortion, dsec.distortion_model) == \
        (553.47, 216.52, (-0.0948, 0.1976, 7.6e-05, 0.000436, 0.0), "radtan")
    assert read_camera_file(tmp_path / "cam_to_cam.yaml", "cam3")[0].fx == 552.18
    assert read_camera_file(tmp_path / "cam_to_cam.yaml", None, (1440, 1080))[2] == "intrinsics.cam1"

    kalibr, size, what = read_camera_file(tmp_path / "camchain-imucam.yaml", "cam1")
    assert (kalibr.fx, kalibr.cx, kalibr.distortion_model, size, what) == \
        (226.04, 174.58, "equidistant", (346, 260), "cam1")
    assert kalibr.distortion == (-0.0476, 0.0116, -0.0493, 0.0190)

    ros, size, _ = read_camera_file(tmp_path / "camera_info.yaml")
    assert (ros.fx, ros.fy, ros.cx, ros.cy, size) == (226.38, 226.15, 173.65, 133.73, (346, 260))
    assert ros.distortion == (-0.33, 0.12, 0.0007, 0.0001, 0.0)

    tum, size, what = read_camera_file(tmp_path / "calibration.json", None, (1280, 720))
    assert (tum.fx, tum.fy, tum.cx, size, what) == (1049.0, 1049.5, 635.0, (1280, 720), "camera 2 (kb4)")
    assert tum.distortion == (0.01, -0.02, 0.003, -0.0004) and tum.distortion_model == "equidistant"
    assert read_camera_file(tmp_path / "calibration.json", "3")[0].fx == 1048.0

    ecd, size, what = read_camera_file(tmp_path / "calib.txt")
    assert (ecd.fx, ecd.distortion[0], size, what) == (199.0, -0.37, None, "calib.txt")


def test_errors_name_the_file_and_the_key(tmp_path):
    bad = tmp_path / "cam.yaml"
    bad.write_text(KALIBR.replace("camera_model: pinhole", "camera_model: omni", 1))
    with pytest.raises(DataError, match=r"cam.yaml: cam0.camera_model 'omni': only pinhole is supported"):
        read_camera_file(bad)
    with pytest.raises(DataError, match=r"cam_to_cam.yaml: no camera 'cam9'; the file has cam0, cam1, cam3, camRect0"):
        (tmp_path / "cam_to_cam.yaml").write_text(DSEC)
        read_camera_file(tmp_path / "cam_to_cam.yaml", "cam9")
    (tmp_path / "info.yaml").write_text(ROS.replace("data: [226.38, 0, 173.65, 0, 226.15, 133.73, 0, 0, 1]",
                                                    "data: [226.38, 0, 173.65]"))
    with pytest.raises(DataError, match=r"info.yaml: camera_matrix.data: expected 9 numbers"):
        read_camera_file(tmp_path / "info.yaml")
    (tmp_path / "other.yaml").write_text("name: something\n")
    with pytest.raises(DataError, match=r"other.yaml: no camera found .*expected a calib.txt"):
        read_camera_file(tmp_path / "other.yaml")
    (tmp_path / "broken.json").write_text('{"value0": ')
    with pytest.raises(DataError, match=r"broken.json: not valid JSON"):
        read_camera_file(tmp_path / "broken.json")
    for text, why in (('{"a": ' + "[" * 100_000, "the JSON is nested too deeply"),  # were RecursionError, ValueError
                      ('{"value0": ' + "1" * 5000 + "}", r"not readable JSON \(Exceeds the limit \(4300 digits\)")):
        (tmp_path / "broken.json").write_text(text)
        with pytest.raises(DataError, match=rf"broken.json: {why}"):
            read_camera_file(tmp_path / "broken.json")


def test_intrinsics_no_camera_has_are_refused_naming_the_file(tmp_path):
    cases = {  # file: (content, what the one line says)
        "info.yaml": (ROS.replace("data: [226.38, 0, 173.65, 0, 226.15", "data: [0, 0, 173.65, 0, -226.15"),
                      "focal lengths must be positive .pixels., got fx 0, fy -226.15"),
        "zeros.yaml": (ROS.replace("data: [226.38, 0, 173.65, 0, 226.15, 133.73, 0, 0, 1]", "data: [0, 0, 0, 0, 0, 0, 0, 0, 0]"),
                       "the camera matrix is all zeros .an uncalibrated camera.; give the calibration with --calib"),
        "cam_to_cam.yaml": (DSEC.replace("[553.47, 553.26, 346.65, 216.52]", "[553.47, 553.26, .nan, 216.52]"),
                            "cx is nan; expected a finite number of pixels"),
        "camchain.yaml": (KALIBR.replace("[-0.048, 0.0113, -0.0493, 0.0194]", "[-0.048, .inf, -0.0493, 0.0194]"),
                          "distortion coefficients must be finite, got -0.048, inf"),
        "calibration.json": (json.dumps(_tumvie()).replace('"fx": 740.0', '"fx": -740.0'),
                             "focal lengths must be positive .pixels., got fx -740"),
    }
    for name, (content, message) in cases.items():
        (tmp_path / name).write_text(content)
        with pytest.raises(DataError, match=f"^{tmp_path / name}: {message}"):
            read_camera_file(tmp_path / name)
    recording = tmp_path / "rec.npz"
    np.savez(recording, x=np.zeros(1, np.uint16), y=np.zeros(1, np.uint16), t=np.zeros(1, np.int64),
             p=np.ones(1, np.int8), intrinsics=np.array([200.0, 0.0, 120.0, 90.0]))
    from tofnet.io import read_recording
    with pytest.raises(DataError, match=r"rec.npz\[intrinsics\]: focal lengths must be positive .*fy 0"):
        read_recording(recording)


def test_aedat4_without_calib_runs_with_intrinsics_and_velocity(tmp_path, capsys):
    optional("faery")
    from tofnet.io.aedat import write_aedat4

    recording = pattern_recording()
    folder = tmp_path / "alone"
    folder.mkdir()
    write_aedat4(folder / "rec.aedat4", [recording.events], recording)
    out = str(tmp_path / "d.npz")
    assert main(["run", str(folder / "rec.aedat4"), "--quiet", "--out", out]) != 0
    assert "calib" in capsys.readouterr().err
    assert main(["run", str(folder / "rec.aedat4"), "--quiet", "--out", out, "--intrinsics", "60,61,31.5,23.25",
                 "--velocity", "0.5,0,0", "--duration", "100ms"]) == 0
    printed = capsys.readouterr().out
    assert "intrinsics from --intrinsics" in printed and "time window 0 s .. 0.1 s" in printed
    (tmp_path / "cam.yaml").write_text(KALIBR.replace("[346, 260]", "[64, 48]", 1))
    assert main(["run", str(folder / "rec.aedat4"), "--quiet", "--out", out, "--force", "--calib",
                 str(tmp_path / "cam.yaml"), "--velocity", "0.5,0,0"]) == 0
    assert f"intrinsics from {tmp_path / 'cam.yaml'} (cam0)" in capsys.readouterr().out
    assert main(["info", str(folder / "rec.aedat4"), "--intrinsics", "1,2,3"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--intrinsics: expected fx,fy,cx,cy" in err
    assert main(["info", str(folder / "rec.aedat4"), "--calib", str(tmp_path / "nothing.yaml")]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "nothing.yaml" in err
    assert np.isfinite(recording.intrinsics.fx)


def test_camera_of_a_one_camera_file_is_refused_not_ignored(tmp_path):
    from types import SimpleNamespace

    from tofnet.io.calibration import set_camera

    (tmp_path / "calib.txt").write_text("199.1 198.8 132.2 110.7\n")
    source = SimpleNamespace(intrinsics=None, sensor_size=(240, 180), notes=[])
    with pytest.raises(DataError, match=r"^--camera cam9: .*calib.txt holds one camera \(calib.txt\)"):
        set_camera(source, None, tmp_path / "calib.txt", "cam9")
    set_camera(source, None, tmp_path / "calib.txt", None)
    assert source.intrinsics.fx == pytest.approx(199.1)


SECRET = "API_KEY=sk-live-" + "A" * 200


@pytest.mark.parametrize("name, camera, hostile", [
    ("calibration.json", "2", lambda: _with(lambda d: d["value0"]["intrinsics"][2].update(camera_type=SECRET))),
    ("calibration.json", "2", lambda: _with(lambda d: d["value0"]["intrinsics"][2]["intrinsics"].update(fx=SECRET))),
    ("calibration.json", "2", lambda: _with(lambda d: d["value0"]["resolution"][2].__setitem__(0, SECRET))),
    ("cam.yaml", None, lambda: KALIBR.replace("camera_model: pinhole", f"camera_model: {SECRET}", 1)),
    ("cam.yaml", None, lambda: KALIBR.replace("distortion_model: equidistant", f"distortion_model: {SECRET}", 1)),
    ("info.yaml", None, lambda: ROS.replace("data: [226.38,", f"data: [{SECRET},", 1)),
    ("cam_to_cam.yaml", None, lambda: DSEC.replace("camera_matrix: [553.47,", f"camera_matrix: ['{SECRET}',", 1)),
    ("cam_to_cam.yaml", "camX", lambda: DSEC.replace("  cam1:", f"  cam{SECRET}:", 1)),  # the error lists the names
    ("cam.yaml", None, lambda: KALIBR.replace("camera_model: pinhole", f"camera_model: !{SECRET}", 1)),  # a YAML tag
])
def test_a_calibration_file_quotes_40_characters_of_a_field_and_none_when_it_links_out(tmp_path, name, camera,
                                                                                        hostile):
    """The audit's case: a TUM-VIE JSON linked out of its folder was quoted up to ~160 characters
    (camera_type, float()'s and int()'s own messages); the text readers' rule holds for every layout."""
    text = hostile()
    (tmp_path / "rec").mkdir()
    (tmp_path / "away").mkdir()
    (tmp_path / "rec" / name).write_text(text)
    with pytest.raises(TofnetError) as err:
        read_camera_file(tmp_path / "rec" / name, camera)
    message = str(err.value)
    assert "API_KEY=sk-live-A" in message and "A" * 30 not in message and "\n" not in message, message
    (tmp_path / "away" / name).write_text(text)
    (tmp_path / "rec" / name).unlink()
    (tmp_path / "rec" / name).symlink_to(tmp_path / "away" / name)
    with pytest.raises(TofnetError) as err:
        read_camera_file(tmp_path / "rec" / name, camera)
    message = str(err.value)
    assert "sk-live" not in message and "links out of its folder, to " in message and "\n" not in message, message


def _with(change):
    data = _tumvie()
    change(data)
    return json.dumps(data)


def test_info_of_a_tumvie_folder_whose_calibration_links_out(tmp_path, capsys):
    """The audit's reproduction end to end: ``tofnet info`` on a made TUM-VIE sequence folder."""
    from tofnet.testing_datasets import MAKERS

    folder = tmp_path / "tumvie"
    MAKERS["tumvie"](folder)
    calibration = next(folder.glob("camera-calibration*.json"))
    data = json.loads(calibration.read_text())
    for entry in data["value0"]["intrinsics"]:
        entry["camera_type"] = SECRET
    away = tmp_path / calibration.name
    away.write_text(json.dumps(data))
    calibration.unlink()
    calibration.symlink_to(away)
    assert main(["info", str(folder)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sk-live" not in err and "links out of its folder" in err, err
