"""tofnet: low-latency monocular depth from event timing, as a neuromorphic process graph."""

from tofnet.core import InPort, Network, OutPort, Process
from tofnet.networks import depth_network
from tofnet.processes import DepthProcess, InputProcess, TimeOfTravelProcess, VelocityProcess

__version__ = "0.1.0"

__all__ = ["InPort", "OutPort", "Process", "Network", "InputProcess", "TimeOfTravelProcess", "DepthProcess",
           "VelocityProcess", "depth_network", "__version__"]
