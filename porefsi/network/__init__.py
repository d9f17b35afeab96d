"""Pore networks: the :class:`Network` type, extraction from images, geometry, conversions."""

from porefsi.network.geometry import conduit_conductance, resistance_factors
from porefsi.network.network import FACES, Network

__all__ = ["Network", "FACES", "conduit_conductance", "resistance_factors"]
