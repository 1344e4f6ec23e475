"""Study workflows built on the library: the virtual-sensor design assistant."""

from . import design as design
from .design import DesignReport as DesignReport
