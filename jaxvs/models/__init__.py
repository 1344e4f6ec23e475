"""Linear models: rational transfer functions, modal models, state space."""

from ._base import AbstractLinearModel as AbstractLinearModel, map_batch as map_batch
from ._modal import ModalModel as ModalModel
from ._rational import RationalTF as RationalTF
from ._realisation import ModalRealisation as ModalRealisation
from ._response import frequency_response as frequency_response
from ._statespace import StateSpace as StateSpace
