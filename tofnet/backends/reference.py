"""The float reference backend: the network executed step by step, literally.

Every process runs its ``reference`` model (``tofnet.models``): dense per-pixel state,
called every step, reading the records its inputs were sent in the previous step (the
one-step delay of every connection). Slow on purpose: it is the readable statement of
the semantics the fast backends are checked against.
"""

from __future__ import annotations

from tofnet.backends.local import LocalBackend


class ReferenceBackend(LocalBackend):
    """Step-by-step float execution of any process graph (the trusted reference)."""

    name = "reference"
    arithmetic = "float"
    family = "reference"
