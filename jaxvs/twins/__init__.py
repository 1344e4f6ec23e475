"""Richer "real" plants that generate data with known, hidden effects (docs/guides/architecture.md).

Only tests, benchmarks, notebooks and the CLI demo import this package.
"""

from ._drive import (
    DRIVE_EFFECT_LABELS as DRIVE_EFFECT_LABELS,
    DRIVE_TWIN_EFFECTS as DRIVE_TWIN_EFFECTS,
    DriveLoop as DriveLoop,
    DriveTwin as DriveTwin,
    draw_drive_effect as draw_drive_effect,
    drive_reference as drive_reference,
)
from ._structure import (
    TMF_TWIN_EFFECTS as TMF_TWIN_EFFECTS,
    ImpactData as ImpactData,
    ImpactSensors as ImpactSensors,
    MachineStructureTwin as MachineStructureTwin,
    StructureData as StructureData,
    TMFSensors as TMFSensors,
    draw_tmf_effect as draw_tmf_effect,
)
from ._thermal import (
    STUDY_PARTS as STUDY_PARTS,
    THERMAL_TWIN_EFFECTS as THERMAL_TWIN_EFFECTS,
    TYPICAL_THERMAL_EFFECTS as TYPICAL_THERMAL_EFFECTS,
    SparseTarget as SparseTarget,
    SpindleThermalTwin as SpindleThermalTwin,
    draw_thermal_effect as draw_thermal_effect,
    thermal_speed_profile as thermal_speed_profile,
)
