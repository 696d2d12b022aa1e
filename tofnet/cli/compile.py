"""``tofnet compile``: place a network spec on neuromorphic cores and print the mapping."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from tofnet.errors import TofnetError


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "compile", help="partition a network into cores under a budget and report the mapping",
        description="Partition every core-placed process of a YAML network spec into patches, one per "
                    "neuromorphic core, check the budget (Loihi 2 by default) and print the mapping: "
                    "cores per layer, resource use per core, chips, and the spike traffic between cores.")
    p.add_argument("spec", nargs="?", help="YAML network spec (default: the --estimator's network, 240x180)")
    p.add_argument("--estimator", choices=("paper", "improved"), default=None,
                   help="built-in network without a spec: paper (the default: the built-in paper spec) or improved "
                        "(the time-surface estimator: host processes only, no cores)")
    p.add_argument("--budget", metavar="FILE|NAME",
                   help="budget YAML file, or a built-in name (loihi2, oheo-gulch, kapoho-point); "
                        "default: the spec's, else loihi2")
    p.add_argument("--max-chips", metavar="N", help="allow at most N chips")
    p.add_argument("--patch", action="append", metavar="WxH|auto|LAYER=WxH",
                   help="patch size for every layer, or for one layer (repeatable); default: the spec's, else auto")
    p.add_argument("--sensor-size", metavar="WxH", help="override the spec's sensor size, e.g. 1280x720")
    p.add_argument("--json", metavar="OUT", help="write the compiled network (mapping, cores, halos) as JSON; - for stdout")
    p.add_argument("--force", action="store_true", help="overwrite an existing --json file")
    from tofnet.cli.trust import add_allow_import
    add_allow_import(p)
    p.set_defaults(handler=handle)


def parse_patch_args(values: list[str] | None, current, layers: list[str]):
    """``["30x30"]`` -> (30, 30); ``["30x30", "depth=auto"]`` -> ``{layer: size}`` for every layer.

    Layers a ``LAYER=`` option does not name keep the common size given, else the spec's.
    """
    from tofnet.compiler.partition import parse_patch_size, patch_per_layer
    if not values:
        return current
    named, whole = {}, None
    for value in values:
        if "=" in value:
            name, size = (part.strip() for part in value.split("=", 1))
            if name not in layers:
                raise TofnetError(f"--patch {value}: no core-placed process {name!r}; expected {', '.join(layers)}")
            named[name] = parse_patch_size(size, f"--patch {name}")
        else:
            whole = parse_patch_size(value, "--patch")
    if not named:
        return whole
    base = patch_per_layer(current if whole is None else whole, layers)
    return {**base, **named}


def handle(args) -> int:
    from tofnet.compiler import compile_network
    from tofnet.compiler.report import format_report
    from tofnet.core.params import parse_size
    from tofnet.io.spec import Spec, default_spec_path, load_budget, load_spec

    if args.json and args.json != "-":
        from tofnet.io.files import check_output
        check_output(args.json, force=args.force, inputs=[args.spec] if args.spec else [], what="--json")
    if args.spec and args.estimator:
        raise TofnetError(f"{args.spec}: --estimator picks a built-in network, and a spec names its own processes; "
                          "give one or the other")
    if args.estimator == "improved":
        from tofnet.api import default_network
        spec = Spec(default_network(estimator="improved"), source="--estimator improved")
    else:
        spec = load_spec(Path(args.spec) if args.spec else default_spec_path(), allow_import=args.allow_import)
    network = spec.network
    if args.sensor_size:
        size = parse_size(args.sensor_size, "--sensor-size")
        for process in network.processes:
            process.set_param("sensor_size", list(size))
        network.validate()
    budget = load_budget(args.budget) if args.budget else spec.budget
    if args.max_chips is not None:
        chips = args.max_chips.strip()
        if not (chips.isdigit() and int(chips) >= 1):  # one message for 0, 1.5 and two
            raise TofnetError(f"--max-chips: expected a whole number of chips >= 1, got {args.max_chips!r}")
        budget = budget.with_max_chips(int(chips))
    layers = [p.name for p in network.processes if p.placement == "core"]
    patch = parse_patch_args(args.patch, spec.compile.get("patch"), layers)
    compiled = compile_network(network, budget=budget, patch=patch)
    print(format_report(compiled))
    if args.json:
        from tofnet.io.compiled import compiled_to_dict
        text = json.dumps(compiled_to_dict(compiled), indent=1) + "\n"
        if args.json == "-":
            sys.stdout.write(text)
        else:
            from tofnet.io.files import write_text_atomic
            write_text_atomic(args.json, text)
            print(f"\nwrote {args.json}")
    return 0
