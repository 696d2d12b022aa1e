"""The process-graph core: processes, ports, parameters and networks."""

from tofnet.core.network import Network
from tofnet.core.params import Param
from tofnet.core.ports import InPort, OutPort, Payload, PortSpec
from tofnet.core.process import Process
from tofnet.core.vars import Var

__all__ = ["Network", "Param", "InPort", "OutPort", "Payload", "PortSpec", "Process", "Var"]
