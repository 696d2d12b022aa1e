"""The processes tofnet ships, as declarations (ports, parameters, docs): no execution code."""

from tofnet.processes.angular_velocity import AngularVelocityProcess
from tofnet.processes.background_filter import BackgroundActivityFilterProcess
from tofnet.processes.depth import DepthProcess
from tofnet.processes.input import InputProcess
from tofnet.processes.time_of_travel import TimeOfTravelProcess
from tofnet.processes.time_surface import TimeSurfaceProcess
from tofnet.processes.undistort import UndistortProcess
from tofnet.processes.velocity import VelocityProcess

__all__ = ["InputProcess", "TimeOfTravelProcess", "DepthProcess", "VelocityProcess",
           "BackgroundActivityFilterProcess", "AngularVelocityProcess", "TimeSurfaceProcess", "UndistortProcess"]
