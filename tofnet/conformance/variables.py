"""Comparing every process's state variables of two backends at chosen steps (through sessions)."""

from __future__ import annotations

import contextlib

import numpy as np

from tofnet.conformance.compare import FLOAT_RTOL


def compare_variables(compiled, recording, runner_a, runner_b, steps) -> list[str]:
    """Differences between the variables of two backends at each of ``steps`` (empty: none).

    Integer variables must be equal; float ones equal within ``FLOAT_RTOL`` (both arithmetics
    hold ``A t`` and velocities as floats, so this is exact in practice).
    """
    from tofnet.session import Session

    names = [f"{p.name}.{v.name}" for p in compiled.network.processes for v in type(p).vars]
    out = []
    with contextlib.ExitStack() as stack:
        a = stack.enter_context(Session(compiled, recording, backend=runner_a.session_or_backend()))
        b = stack.enter_context(Session(compiled, recording, backend=runner_b.session_or_backend()))
        for step in sorted(steps):
            a.run(steps=max(step - a.step, 0))
            b.run(steps=max(step - b.step, 0))
            for name in names:
                va, vb = np.asarray(a.get(name)), np.asarray(b.get(name))
                if va.dtype.kind == "f":
                    same = va.shape == vb.shape and np.allclose(va, vb, rtol=FLOAT_RTOL, atol=0.0, equal_nan=True)
                else:
                    same = np.array_equal(va, vb)
                if not same:
                    at = np.argwhere(~np.isclose(va, vb, equal_nan=True)) if va.shape == vb.shape else []
                    where = f" first at index {tuple(int(i) for i in at[0])}" if len(at) else ""
                    out.append(f"variable {name} at step {step} differs{where}")
    return out
