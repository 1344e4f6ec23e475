"""Models: one abstract interface (`AbstractModel`: a pure prediction for one experiment;
`AbstractLinearModel` adds frequency response and state space), the time-stepping engines
(exact discretisation + scan, Euler, Heun, diffrax), and one sub-package per family:
`lti`, `drive`, `thermal`, `tmf`. Every public name of the sub-packages is available here."""

from . import drive as drive, lti as lti, thermal as thermal, tmf as tmf
from ._base import (
    AbstractFamilyLaw as AbstractFamilyLaw,
    AbstractLinearModel as AbstractLinearModel,
    AbstractModel as AbstractModel,
    map_batch as map_batch,
)
from ._discretise import (
    DiscreteModalRealisation as DiscreteModalRealisation,
    discretise as discretise,
)
from ._nonlinear_simulate import (
    amplification as amplification,
    check_step as check_step,
    solve_ode as solve_ode,
    solve_sampled as solve_sampled,
    zoh_interval as zoh_interval,
)
from ._realisation import ModalRealisation as ModalRealisation
from ._simulate import (
    SimulationMetrics as SimulationMetrics,
    simulate as simulate,
    simulate_metrics as simulate_metrics,
)
from .drive import (
    AbstractActuator as AbstractActuator,
    AbstractDynamicFriction as AbstractDynamicFriction,
    AbstractFriction as AbstractFriction,
    AbstractMechanics as AbstractMechanics,
    ActuatorSaturation as ActuatorSaturation,
    AsymmetricFriction as AsymmetricFriction,
    BallbarResult as BallbarResult,
    BallScrew as BallScrew,
    CoulombFriction as CoulombFriction,
    CoulombViscousFriction as CoulombViscousFriction,
    CurrentLoop as CurrentLoop,
    DahlFriction as DahlFriction,
    DCMotor as DCMotor,
    DriftingFriction as DriftingFriction,
    DriveAxis as DriveAxis,
    DriveResponse as DriveResponse,
    FlexibleAxis as FlexibleAxis,
    ForceGain as ForceGain,
    FrictionSum as FrictionSum,
    GeometricErrors as GeometricErrors,
    LuGreFriction as LuGreFriction,
    NoFriction as NoFriction,
    PositionLoop as PositionLoop,
    RigidAxis as RigidAxis,
    StribeckFriction as StribeckFriction,
    UnstableLoopError as UnstableLoopError,
    VelocityLoop as VelocityLoop,
    ViscousFriction as ViscousFriction,
    XYTable as XYTable,
    ballbar_test as ballbar_test,
    circle_path as circle_path,
    dead_zone as dead_zone,
    quantise as quantise,
    saturation as saturation,
    smooth_sign as smooth_sign,
)
from .lti import (
    DampedModes as DampedModes,
    GridFamily as GridFamily,
    ModalModel as ModalModel,
    NormalModes as NormalModes,
    OscillatorChain as OscillatorChain,
    RationalTF as RationalTF,
    SmoothFamily as SmoothFamily,
    StateSpace as StateSpace,
    acceleration_to_position as acceleration_to_position,
    acceleration_to_position_frf as acceleration_to_position_frf,
    damped_modes as damped_modes,
    damping as damping,
    frequency_response as frequency_response,
    from_control as from_control,
    from_scipy as from_scipy,
    is_stable as is_stable,
    normal_modes as normal_modes,
    poles as poles,
    position_to_acceleration as position_to_acceleration,
    position_to_acceleration_frf as position_to_acceleration_frf,
    static_gain as static_gain,
    to_control as to_control,
    to_modal as to_modal,
    to_rational as to_rational,
    to_scipy as to_scipy,
    zeros as zeros,
)
from .thermal import (
    AbstractNetwork as AbstractNetwork,
    BiasFreeRegression as BiasFreeRegression,
    DrivenFirstOrder as DrivenFirstOrder,
    FirstOrder as FirstOrder,
    Perceptron as Perceptron,
    PiecewiseFirstOrder as PiecewiseFirstOrder,
    StaticNetwork as StaticNetwork,
    TimeDelayNetwork as TimeDelayNetwork,
)
from .tmf import (
    StableTMF as StableTMF,
    VirtualSensor as VirtualSensor,
    partial_fractions as partial_fractions,
    pole_sections as pole_sections,
    section_poles as section_poles,
    simulate_modal as simulate_modal,
)
