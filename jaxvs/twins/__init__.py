"""Richer "real" plants that generate data with known, hidden effects (DESIGN.md §2).

Only tests, benchmarks, notebooks and the CLI demo import this package.
"""

from ._structure import MachineStructureTwin as MachineStructureTwin, StructureData as StructureData
