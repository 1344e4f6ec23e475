"""Study workflows on top of the engine (the source studies and the public benchmarks)."""

from . import benchmarks as benchmarks
