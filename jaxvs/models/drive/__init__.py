"""CNC axis-drive components: friction laws, axis mechanics (rigid, two-mass, ball screw),
the rigid axis's inverse dynamics (force from motion, IDIM),
cascaded P/PI loops, actuators, the `DriveAxis` cascade, two-axis contouring, and the
three-axis Cartesian machine with its 21 geometric errors."""

from ._ballscrew import (
    AbstractMechanics as AbstractMechanics,
    BallScrew as BallScrew,
    FlexibleAxis as FlexibleAxis,
    RigidAxis as RigidAxis,
)
from ._cartesian import (
    STRUCTURES as STRUCTURES,
    CartesianMachine as CartesianMachine,
    MachineResponse as MachineResponse,
)
from ._contouring import (
    BallbarResult as BallbarResult,
    GeometricErrors as GeometricErrors,
    XYTable as XYTable,
    ballbar_test as ballbar_test,
    circle_path as circle_path,
)
from ._drive import (
    AbstractActuator as AbstractActuator,
    CurrentLoop as CurrentLoop,
    DCMotor as DCMotor,
    DriveAxis as DriveAxis,
    DriveResponse as DriveResponse,
    ForceGain as ForceGain,
    PositionLoop as PositionLoop,
    UnstableLoopError as UnstableLoopError,
    VelocityLoop as VelocityLoop,
)
from ._dynamic_friction import (
    AbstractDynamicFriction as AbstractDynamicFriction,
    DahlFriction as DahlFriction,
    DriftingFriction as DriftingFriction,
    LuGreFriction as LuGreFriction,
)
from ._friction import (
    AbstractFriction as AbstractFriction,
    ActuatorSaturation as ActuatorSaturation,
    AsymmetricFriction as AsymmetricFriction,
    CoulombFriction as CoulombFriction,
    CoulombViscousFriction as CoulombViscousFriction,
    FrictionSum as FrictionSum,
    NoFriction as NoFriction,
    StribeckFriction as StribeckFriction,
    ViscousFriction as ViscousFriction,
    dead_zone as dead_zone,
    quantise as quantise,
    saturation as saturation,
    smooth_sign as smooth_sign,
)
from ._geometric_errors import (
    COMPONENTS as COMPONENTS,
    MachineErrors as MachineErrors,
    legendre as legendre,
)
from ._inverse_dynamics import RigidInverseDynamics as RigidInverseDynamics
from ._volumetric_tests import (
    AbstractMachineTest as AbstractMachineTest,
    AngularLine as AngularLine,
    BallbarCircle as BallbarCircle,
    DiagonalLine as DiagonalLine,
    LaserLine as LaserLine,
    StraightnessLine as StraightnessLine,
    plan_predict as plan_predict,
)
