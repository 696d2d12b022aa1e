"""Backends that execute a compiled network; chosen by name through the registry."""

from tofnet.backends.base import Backend, RunResult
from tofnet.backends.registry import available_backends, get_backend, register_backend

__all__ = ["Backend", "RunResult", "available_backends", "get_backend", "register_backend"]
