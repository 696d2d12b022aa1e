"""Make small sequence folders in the layouts of DSEC, MVSEC, TUM-VIE, M3ED and EVIMO2 (docs/formats.md, "Datasets").

    python examples/dataset_folders.py OUT

writes OUT/zurich_city_00_a (DSEC), OUT/indoor_flying1 (MVSEC), OUT/mocap-desk2 (TUM-VIE),
OUT/car_urban_day_1 (M3ED) and OUT/scene13_dyn_test_00_000000 (EVIMO2 v2, NPZ): 2.2 s of a textured
plane 2 m away, the camera moving at 0.5 m/s to the left, with each dataset's calibration and ground truth (``tofnet.testing_datasets``).
"""

from __future__ import annotations

import sys
from pathlib import Path

from tofnet.testing_datasets import MAKERS

NAMES = {"dsec": "zurich_city_00_a", "mvsec": "indoor_flying1", "tumvie": "mocap-desk2", "m3ed": "car_urban_day_1",
         "evimo2": "scene13_dyn_test_00_000000"}


def main(out: str) -> None:
    for kind, make in MAKERS.items():
        folder = make(Path(out) / NAMES[kind])
        print(f"{kind:7} {folder}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
