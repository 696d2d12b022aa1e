"""tofnet: low-latency monocular depth from event timing, as a neuromorphic process graph."""

from tofnet.core import InPort, Network, OutPort, Param, Payload, PortSpec, Process
from tofnet.networks import depth_network
from tofnet.processes import (BackgroundActivityFilterProcess, DepthProcess, InputProcess, TimeOfTravelProcess,
                              VelocityProcess)

__version__ = "0.1.0"

__all__ = ["InPort", "OutPort", "Param", "Payload", "PortSpec", "Process", "Network", "InputProcess",
           "TimeOfTravelProcess", "DepthProcess", "VelocityProcess", "BackgroundActivityFilterProcess",
           "depth_network", "__version__"]
