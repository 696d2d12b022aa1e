"""The four processes of the paper's network, as declarations (ports, parameters, docs)."""

from tofnet.processes.depth import DepthProcess
from tofnet.processes.input import InputProcess
from tofnet.processes.time_of_travel import TimeOfTravelProcess
from tofnet.processes.velocity import VelocityProcess

__all__ = ["InputProcess", "TimeOfTravelProcess", "DepthProcess", "VelocityProcess"]
