"""``tofnet convert``: a recording in any readable format to an ECD folder, .npz, HDF5, AEDAT4, Prophesee
RAW (EVT3) or DAT, or Event Stream."""

from __future__ import annotations

from tofnet.cli.inputs import add_input_options, input_options


def register(subparsers) -> None:
    p = subparsers.add_parser("convert", help="convert a recording to ECD, .npz, HDF5 (DSEC layout), AEDAT4, "
                                                  "Prophesee RAW (EVT3)/DAT or Event Stream",
                              description="Read a recording in any supported format and write it as an ECD "
                                          "folder (OUT without suffix), .npz, .h5/.hdf5 (DSEC layout), "
                                          ".aedat4, .raw (Prophesee EVT3), .dat (Prophesee DAT2) or .es (Event "
                                          "Stream). Calibration, poses and IMU go along where the target can "
                                          "hold them; AEDAT4, RAW, DAT and Event Stream get "
                                          "calib.txt/groundtruth.txt beside them; anything not written is "
                                          "reported.")
    p.add_argument("input", help="ECD folder or event file (.txt .npy .npz .aedat4 .raw .dat .es .h5 .bag)")
    p.add_argument("output", help="ECD folder name, or a .npz, .h5/.hdf5, .aedat4, .raw (EVT3), .dat "
                                   "or .es file")
    add_input_options(p)
    p.add_argument("--sensor-size", metavar="WxH", help="sensor size in pixels (overrides the input's)")
    p.add_argument("--force", action="store_true", help="replace OUT (and side files) when they exist (never an input)")
    p.add_argument("--quiet", action="store_true", help="no progress")
    p.set_defaults(handler=handle)


def handle(args) -> int:
    from tofnet.cli.progress import Progress
    from tofnet.core.params import parse_size
    from tofnet.io.convert import check_convert_output, convert
    from tofnet.io.source import open_recording

    check_convert_output(args.output, args.input, force=args.force)  # before reading anything
    sensor = parse_size(args.sensor_size, "--sensor-size") if args.sensor_size else None
    progress = None if args.quiet else Progress("tofnet convert")
    with open_recording(args.input, sensor_size=sensor, **input_options(args)) as source:
        messages = convert(source, args.output, force=args.force, progress=progress)
    if progress:
        progress.done()
    print("\n".join(messages))
    return 0
