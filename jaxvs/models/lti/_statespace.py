"""Continuous-time state-space models `x' = A x + B u`, `y = C x + D u`."""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Complex, Float

from ..._misc import as_real
from .._base import AbstractLinearModel, check_batch
from .._realisation import ModalRealisation, from_dense


class StateSpace(AbstractLinearModel):
    """Continuous-time state-space model, the python-control/scipy `StateSpace` analogue.

    **Arguments:**

    - `A`: `(*batch, n, n)` state matrix [1/s].
    - `B`: `(*batch, n, in)` input matrix.
    - `C`: `(*batch, out, n)` output matrix.
    - `D`: `(*batch, out, in)` feedthrough.

    Leading `batch` axes make a family (one system per member).
    """

    A: Float[Array, "*batch n n"]
    B: Float[Array, "*batch n input"]
    C: Float[Array, "*batch output n"]
    D: Float[Array, "*batch output input"]

    def __init__(self, A: ArrayLike, B: ArrayLike, C: ArrayLike, D: ArrayLike):
        A, B, C, D = (as_real(x, k) for x, k in zip((A, B, C, D), "ABCD"))
        for x, k in zip((A, B, C, D), "ABCD"):
            if x.ndim < 2:
                raise ValueError(
                    f"StateSpace: {k} must be at least 2-D (rows, columns); got shape "
                    f"{x.shape}. Use e.g. B.reshape(-1, 1) for a single input."
                )
        n, m, p = A.shape[-1], B.shape[-1], C.shape[-2]
        if A.shape[-2] != n or B.shape[-2] != n or C.shape[-1] != n or D.shape[-2:] != (p, m):
            raise ValueError(
                "StateSpace: inconsistent shapes "
                f"A{A.shape}, B{B.shape}, C{C.shape}, D{D.shape}; expected A (n, n), "
                "B (n, in), C (out, n), D (out, in) after any leading family axes."
            )
        check_batch([A.shape[:-2], B.shape[:-2], C.shape[:-2], D.shape[:-2]], "StateSpace")
        dtype = jnp.result_type(A, B, C, D)
        self.A, self.B, self.C, self.D = (x.astype(dtype) for x in (A, B, C, D))

    @property
    def n_inputs(self) -> int:
        return self.B.shape[-1]

    @property
    def n_outputs(self) -> int:
        return self.C.shape[-2]

    @property
    def order(self) -> int:
        return self.A.shape[-1]

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return self.A.shape[:-2]

    def response(self, s: Complex[Array, " freq"]) -> Complex[Array, "freq out in"]:
        n = self.order
        eye = jnp.eye(n, dtype=s.dtype)
        M = s[:, None, None] * eye - self.A.astype(s.dtype)
        X = jnp.linalg.solve(
            M, jnp.broadcast_to(self.B.astype(s.dtype), (s.shape[0],) + self.B.shape)
        )
        return jnp.einsum("on,fni->foi", self.C.astype(s.dtype), X) + self.D

    def modal_realisation(self) -> ModalRealisation:
        return from_dense(self.A, self.B, self.C, self.D)

    def to_state_space(self) -> "StateSpace":
        return self
