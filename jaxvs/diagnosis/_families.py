"""The diagnosis families by name (`jaxvs diagnose --family NAME`)."""

from __future__ import annotations

from ._base import AbstractFamily
from ._drive import DriveFamily
from ._thermal import ThermalFamily
from ._tmf import TMFFamily

__all__ = ["FAMILIES"]

FAMILIES: dict[str, type[AbstractFamily]] = {
    "drive": DriveFamily,
    "thermal": ThermalFamily,
    "tmf": TMFFamily,
}
