"""tofnet: low-latency monocular depth from event timing, as a neuromorphic process graph."""

from tofnet.core import InPort, Network, OutPort, Param, Payload, PortSpec, Process
from tofnet.networks import depth_network
from tofnet.processes import (BackgroundActivityFilterProcess, DepthProcess, InputProcess, TimeOfTravelProcess,
                              VelocityProcess)

__version__ = "0.1.0"


def __getattr__(name: str):
    # Session and Monitor run backends: imported on first use, so that `import tofnet` (the
    # declarations) stays free of numba and the backends.
    if name in ("Session", "Monitor"):
        import importlib
        module = importlib.import_module("tofnet.session" if name == "Session" else "tofnet.monitor")
        return getattr(module, name)
    raise AttributeError(f"module 'tofnet' has no attribute {name!r}")

__all__ = ["InPort", "OutPort", "Param", "Payload", "PortSpec", "Process", "Network", "InputProcess",
           "TimeOfTravelProcess", "DepthProcess", "VelocityProcess", "BackgroundActivityFilterProcess",
           "depth_network", "Session", "Monitor", "__version__"]
