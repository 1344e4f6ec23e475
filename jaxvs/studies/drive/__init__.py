"""The CNC axis-drive study (Pislaru 2001; EMPS, Janot et al. 2019): inverse-dynamics
identification (IDIM-LS) and closed-loop calibration of drive models."""

from ._drive_calibration import (
    DriveSignals as DriveSignals,
    calibrate_drive as calibrate_drive,
    drive_residual as drive_residual,
)
from ._idim import (
    ForcePrediction as ForcePrediction,
    IDIMResult as IDIMResult,
    idim_ls as idim_ls,
    idim_regressor as idim_regressor,
    predict_force as predict_force,
)
