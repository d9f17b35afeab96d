"""Unit constants shared by every layer of porefsi (it imports nothing, so any module may use it)."""

from __future__ import annotations

__all__ = ["MILLIDARCY", "DARCY"]

#: One darcy in m² (API RP 40: 1 D = 9.869233e-13 m²).
DARCY = 9.869233e-13

#: One millidarcy in m².
MILLIDARCY = 9.869233e-16
