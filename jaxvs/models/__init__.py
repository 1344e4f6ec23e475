"""Linear models: rational transfer functions, modal models, state space."""

from ._analysis import (
    damping as damping,
    is_stable as is_stable,
    poles as poles,
    static_gain as static_gain,
    zeros as zeros,
)
from ._ballscrew import (
    AbstractMechanics as AbstractMechanics,
    BallScrew as BallScrew,
    FlexibleAxis as FlexibleAxis,
    RigidAxis as RigidAxis,
)
from ._base import AbstractLinearModel as AbstractLinearModel, map_batch as map_batch
from ._chain import NormalModes as NormalModes, OscillatorChain as OscillatorChain
from ._contouring import (
    BallbarResult as BallbarResult,
    GeometricErrors as GeometricErrors,
    XYTable as XYTable,
    ballbar_test as ballbar_test,
    circle_path as circle_path,
)
from ._convert import (
    acceleration_to_position as acceleration_to_position,
    acceleration_to_position_frf as acceleration_to_position_frf,
    position_to_acceleration as position_to_acceleration,
    position_to_acceleration_frf as position_to_acceleration_frf,
    to_modal as to_modal,
    to_rational as to_rational,
)
from ._discretise import (
    DiscreteModalRealisation as DiscreteModalRealisation,
    discretise as discretise,
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
from ._family import GridFamily as GridFamily, SmoothFamily as SmoothFamily
from ._friction import (
    AbstractFriction as AbstractFriction,
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
from ._interop import (
    from_control as from_control,
    from_scipy as from_scipy,
    to_control as to_control,
    to_scipy as to_scipy,
)
from ._modal import ModalModel as ModalModel
from ._modes import (
    DampedModes as DampedModes,
    damped_modes as damped_modes,
    normal_modes as normal_modes,
)
from ._networks import (
    Perceptron as Perceptron,
    StaticNetwork as StaticNetwork,
    TimeDelayNetwork as TimeDelayNetwork,
)
from ._nonlinear_simulate import (
    amplification as amplification,
    check_step as check_step,
    solve_ode as solve_ode,
    solve_sampled as solve_sampled,
    zoh_interval as zoh_interval,
)
from ._rational import RationalTF as RationalTF
from ._realisation import ModalRealisation as ModalRealisation
from ._regression import BiasFreeRegression as BiasFreeRegression
from ._response import frequency_response as frequency_response
from ._simulate import simulate as simulate
from ._statespace import StateSpace as StateSpace
from ._thermal import (
    DrivenFirstOrder as DrivenFirstOrder,
    FirstOrder as FirstOrder,
    PiecewiseFirstOrder as PiecewiseFirstOrder,
)
from ._virtual_sensor import VirtualSensor as VirtualSensor
