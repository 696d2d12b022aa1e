"""``Spec``: what a loaded spec holds (the network, compile options, backend, where it came from).

``tofnet.io.spec`` reads one and ``tofnet.io.spec_writer`` writes one back; both import it
from here so neither imports the other for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from tofnet.compiler.budget import LOIHI2, Budget
from tofnet.core.network import Network


@dataclass
class Spec:
    """A loaded spec: the network, compile options, backend and where it came from.

    ``compile`` holds the keys the spec gave, as ``compile_network`` takes them:
    ``budget`` (a ``Budget``) and ``patch`` (``"auto"``, ``(w, h)`` px or per process).
    """

    network: Network
    compile: dict[str, Any] = field(default_factory=dict)
    backend: str | None = None
    backend_options: dict[str, Any] = field(default_factory=dict)
    description: str | None = None
    source: str = "<string>"
    #: The line of ``backend`` (key ``""``) and of each of its options in the spec's file, for errors found later.
    backend_lines: dict[str, int | None] = field(default_factory=dict, compare=False, repr=False)

    @property
    def budget(self) -> Budget:
        return self.compile.get("budget", LOIHI2)

    def compile_network(self, **overrides: Any):
        """``compile_network(network, **compile)``, with ``overrides`` (budget, patch) applied."""
        from tofnet.compiler import compile_network
        return compile_network(self.network, **{**self.compile, **overrides})
