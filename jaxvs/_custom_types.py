"""Type aliases shared across jaxvs (one place, as STYLE.md asks)."""

from typing import TypeAlias

from jaxtyping import Array, ArrayLike, Complex, Float, Int

RealScalarLike: TypeAlias = float | int | Float[ArrayLike, ""]
FloatArrayLike: TypeAlias = Float[ArrayLike, "..."]
FrequencyGrid: TypeAlias = Float[ArrayLike, " freq"]

__all__ = [
    "Array",
    "ArrayLike",
    "Complex",
    "Float",
    "FloatArrayLike",
    "FrequencyGrid",
    "Int",
    "RealScalarLike",
]
