"""What a user reads off a result, compared between two runs: which output is the depth (its
payload, and so the files' names), what each process declares it counts, and the run summary.

A backend can agree on every record and count and still report ``events in 0`` (a result without
``declared``) or write the depth under another name (without ``payloads``); ``compare`` and the
workers check fail such a run with a line naming the field.
"""

from __future__ import annotations

from tofnet.backends.base import RUN_SPECIFIC

#: Summary keys that follow from the depth estimates and the counts, which ``quantised`` compares
#: within its tolerance (the summary compares them exactly in the other modes).
ESTIMATE_KEYS = ("depth_out", "rejected", "outputs", "counts")


def visible_differences(result, baseline, skip: tuple[str, ...] = ()) -> list[str]:
    """How what a user reads of two results differs, one line per field: ``payloads`` (which output
    is the depth, and so the files' names), ``declared`` counts, and ``RunResult.summary()`` (events
    in, accepted, drops, totals, latency...; ``RUN_SPECIFIC`` keys and ``skip`` apart)."""
    out = []
    if result.payloads != baseline.payloads:
        out.append(f"payloads: {result.payloads} vs {baseline.payloads}")
    if set(result.declared) != set(baseline.declared):
        out.append(f"declared counts of processes {sorted(result.declared)} vs {sorted(baseline.declared)}")
    for process in baseline.declared.keys() & result.declared.keys():
        a, b = result.declared[process], baseline.declared[process]
        for name in dict.fromkeys([*b, *a]):
            if a.get(name) != b.get(name):
                out.append(f"declared count {process}.{name}: {a.get(name)} vs {b.get(name)}")
                break
    ours, theirs = result.summary(), baseline.summary()
    for key in dict.fromkeys([*theirs, *ours]):
        if key not in RUN_SPECIFIC and key not in skip and ours.get(key) != theirs.get(key):
            out.append(f"summary {key}: {ours.get(key)!r} vs {theirs.get(key)!r}")
    return out
