"""Typed errors raised by porefsi.

Every error names the offending value and the fix. Library code raises these and never
exits; :func:`porefsi.cli.main` alone turns them into exit codes and one-line messages.
"""

from __future__ import annotations

__all__ = [
    "PorefsiError",
    "InputError",
    "ConfigError",
    "MeshError",
    "NetworkError",
    "ConvergenceError",
]


class PorefsiError(Exception):
    """Base class of every error porefsi raises on purpose."""


class InputError(PorefsiError, ValueError):
    """A file, image or parameter given by the user is unusable (missing, malformed, out of range)."""


class ConfigError(InputError):
    """A case file has an unknown key or a bad value; the message names the key."""


class MeshError(PorefsiError):
    """The solid mesh cannot be built or has become invalid (no supported solid, inverted elements)."""


class NetworkError(PorefsiError):
    """The pore network is unusable for the requested job (no inlet/outlet, no percolating path)."""


class ConvergenceError(PorefsiError):
    """An iterative solve did not converge.

    Parameters
    ----------
    message : str
        What did not converge and what to try.
    history : sequence of float, optional
        Residual (or error) history of the failed iteration, first to last.
    """

    def __init__(self, message: str, history=None):
        super().__init__(message)
        self.history = [] if history is None else list(history)
