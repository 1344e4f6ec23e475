"""The three-axis machine study: calibration of the 21 geometric errors of a
`jaxvs.models.CartesianMachine` from laser, straightness, angular, ball-bar and diagonal
tests; identifiability of a test plan; test-plan suggestion; the compensated volumetric
error."""

from ._calibration import (
    MachineCalibration as MachineCalibration,
    calibrate_machine as calibrate_machine,
    machine_residual as machine_residual,
)
from ._compensation import compensated_error as compensated_error
from ._identifiability import (
    IdentifiabilityReport as IdentifiabilityReport,
    identifiability as identifiability,
)
from ._parameters import (
    component_curves as component_curves,
    geometry as geometry,
    parameter_names as parameter_names,
    parameters as parameters,
    plan_jacobian as plan_jacobian,
    with_parameters as with_parameters,
)
from ._plans import (
    ballbar_diagonal_plan as ballbar_diagonal_plan,
    ballbar_plan as ballbar_plan,
    candidate_tests as candidate_tests,
    complete_plan as complete_plan,
    diagonal_plan as diagonal_plan,
)
from ._suggest import suggest_test as suggest_test
