"""Sim-to-real gap diagnosis: where a calibrated model disagrees with the machine, which
unmodelled effect causes it, and how far the gap shrinks once it is added
(docs/guides/contracts.md).
"""

from ._base import (
    AbstractAdditiveEffect as AbstractAdditiveEffect,
    AbstractEffect as AbstractEffect,
    AbstractFamily as AbstractFamily,
    AdmissibilityContext as AdmissibilityContext,
    EffectSpec as EffectSpec,
    Experiment as Experiment,
    GapModel as GapModel,
    NotIdentifiable as NotIdentifiable,
)
from ._check import CheckReport as CheckReport, check as check
from ._diagnose import FAMILIES as FAMILIES, diagnose as diagnose
from ._discover import (
    Discovered as Discovered,
    DiscoveryOptions as DiscoveryOptions,
    discover as discover,
)
from ._gapmap import GapCell as GapCell, gap_map as gap_map
from ._next_experiment import NextExperiment as NextExperiment
from ._report import DiagnosisReport as DiagnosisReport

EFFECTS: dict[str, tuple[str, ...]] = {
    name: tuple(s.name for s in fam().library()) for name, fam in FAMILIES.items()
}
"""The effect names of each family, in library order (docs/guides/contracts.md)."""
