r"""N-mass oscillator chains: FRFs, transmissibility functions (TMFs) and their conversions.

A chain of lumped masses joined by spring–damper pairs is the textbook stand-in for a
machine-tool feed drive (motor, ball screw, slide, tool side). The study behind the TMF
virtual sensor (Doerrer et al. 2022, §2.4 and Figure 3) uses a three-mass chain to show that
a transmissibility `T_ab^c = x_a^c / x_b^c = H_ac / H_bc` (eq. 6) depends on where the force
acts: `T_32^1 = T_32^2 ≠ T_32^3`. [`OscillatorChain`][] reproduces that finding, and gives
every chain as a `jaxvs.StateSpace`, a `jaxvs.ModalModel` and, for its TMFs, a
`jaxvs.RationalTF`, so chains can be simulated, fitted and differentiated like any model.

Mass indices are **0-based** (the paper's mass 1 is index 0).
"""

import operator
from collections.abc import Sequence
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float

from ..._misc import as_real
from .._base import AbstractLinearModel, check_batch, map_batch
from .._realisation import ModalRealisation
from ._modal import ModalModel
from ._rational import RationalTF
from ._response import as_omega
from ._statespace import StateSpace

_QUANTITY_POWER = {"displacement": 0, "velocity": 1, "acceleration": 2}

# heuristic: ΦᵀCΦ counts as diagonal (classical normal modes) when its largest off-diagonal
# entry is below this fraction of its largest diagonal entry. Rounding leaves ~1e-15 · N
# relative for Rayleigh damping built exactly; genuinely non-proportional damping is
# orders of magnitude above.
_PROPORTIONAL_RTOL = 1e-6


class NormalModes(eqx.Module):
    """Undamped normal modes of an [`OscillatorChain`][] (one system or a family).

    **Fields:**

    - `omega_n`: `(*batch, mode)` natural frequencies [rad/s], ascending.
    - `mode_shapes`: `(*batch, dof, mode)` mass-normalised mode shapes `Φ`
      (`Φᵀ M Φ = I`, `Φᵀ K Φ = diag(ω_n²)`) [1/sqrt(kg)]; sign fixed so that the entry
      of the first mass (index 0) is positive.
    - `zeta`: `(*batch, mode)` modal damping ratios `ζ_k = φ_kᵀ C φ_k / (2 ω_k)` [-].
      Exact for proportional damping; for non-proportional damping this is the diagonal
      (classical normal-mode) approximation, which ignores the coupling of the modes
      through `C`.
    """

    omega_n: Float[Array, "*batch mode"]
    mode_shapes: Float[Array, "*batch dof mode"]
    zeta: Float[Array, "*batch mode"]


def _index(i, n: int, name: str, where: str) -> int:
    """A static mass index in `0..n-1` (negative values count from the right end)."""
    try:
        j = operator.index(i)
    except TypeError:
        raise TypeError(
            f"{where}: {name} must be a Python int (a mass index 0..{n - 1}); got "
            f"{type(i).__name__}. Indices set output shapes and model orders, so they must be "
            "concrete: close over them instead of passing them through jit/vmap."
        ) from None
    if not -n <= j < n:
        raise ValueError(
            f"{where}: {name}={j} is out of range; valid mass indices are 0..{n - 1} "
            f"(0-based: the paper's mass 1 is index 0), or -{n}..-1 counted from the right end."
        )
    return j % n


def _indices(x, n: int, name: str, where: str) -> tuple[tuple[int, ...], bool]:
    """Mass indices from an int (scalar: its axis is dropped), a sequence, or `None` (all)."""
    if x is None:
        return tuple(range(n)), False
    if (isinstance(x, Sequence) and not isinstance(x, str)) or getattr(x, "ndim", 0) == 1:
        idx = tuple(_index(i, n, name, where) for i in x)
        if not idx:
            raise ValueError(f"{where}: {name} is an empty sequence; give at least one index.")
        return idx, False
    return (_index(x, n, name, where),), True


def _quantity_power(quantity: str, where: str) -> int:
    if quantity not in _QUANTITY_POWER:
        raise ValueError(f"{where}: quantity={quantity!r} is not one of {tuple(_QUANTITY_POWER)}.")
    return _QUANTITY_POWER[quantity]


def _mul_quadratic(p: Array, q: Array) -> Array:
    """`p(s) · (q0 + q1 s + q2 s²)`, coefficients lowest power first, truncated to len(p)."""
    z1 = jnp.zeros(1, p.dtype)
    z2 = jnp.zeros(2, p.dtype)
    return q[0] * p + q[1] * jnp.concatenate([z1, p[:-1]]) + q[2] * jnp.concatenate([z2, p[:-2]])


@eqx.filter_jit
def _apply(chain: "OscillatorChain", method: str, *args):
    """`chain.<method>(*args)` for every member of a family, compiled once per structure.

    Mass indices travel as (traced) integer arrays and only shapes and Python ints (the
    quantity, the model order) are static, so one XLA program serves every index choice
    of the same shape instead of dozens of small eager ops per call.
    """
    return map_batch(lambda ch: getattr(ch, method)(*args), chain)


class OscillatorChain(AbstractLinearModel):
    r"""Chain of `N` point masses joined by parallel spring–damper pairs.

    Topology (indices 0-based, `N = len(masses)`):

    ```
    ground ─k0/c0─ m0 ─k1/c1─ m1 ─ ... ─k(N-1)/c(N-1)─ m(N-1) [─kN/cN─ ground]
    ```

    - `grounded="left"` (default): mass 0 is tied to ground through `k_0, c_0`, the right
      end is free; `N` springs. The typical drive model: the motor side is held by the
      position control, the tool side is free.
    - `grounded="both"`: additionally mass `N-1` is tied to ground through `k_N, c_N`;
      `N + 1` springs.

    Optional `ground_dampings` add a viscous damper from every mass to ground (e.g.
    guideway friction); with them a Rayleigh damping `C = α M + β K` is representable
    (see [`OscillatorChain.rayleigh`][]). The equations of motion are
    `M x'' + C x' + K x = f` with diagonal `M` and tridiagonal `K`, `C`.

    **Arguments:**

    - `masses`: `(*batch, N)` masses `m_i` [kg], > 0.
    - `stiffnesses`: `(*batch, N)` (left) or `(*batch, N + 1)` (both) spring rates `k_i`
      [N/m], > 0, ordered from left to right as in the sketch.
    - `dampings`: same shape as `stiffnesses`, viscous dampers `c_i` parallel to the
      springs [N·s/m], >= 0.
    - `grounded`: `"left"` or `"both"` (static).
    - `ground_dampings`: optional `(*batch, N)` dampers from each mass to ground
      [N·s/m], >= 0 (default 0).

    As a linear model (`jaxvs.frequency_response`, `jaxvs.simulate`, `predict`) the chain
    maps the forces on all `N` masses [N] to the displacements of all `N` masses [m]: its
    transfer matrix is the receptance `(M s² + C s + K)⁻¹`, `(N, N)`, of order `2N`;
    [`OscillatorChain.state_space`][] selects forces, outputs and the measured quantity.

    Leading `batch` axes make a family of chains (one per member); every method maps over
    them. Non-positive masses or stiffnesses and negative dampings raise at run time
    (`eqx.error_if`), also under `jit`.
    """

    masses: Float[Array, "*batch n"]
    stiffnesses: Float[Array, "*batch spring"]
    dampings: Float[Array, "*batch spring"]
    ground_dampings: Float[Array, "*batch n"]
    grounded: Literal["left", "both"] = eqx.field(static=True)

    def __init__(
        self,
        masses: ArrayLike,
        stiffnesses: ArrayLike,
        dampings: ArrayLike,
        *,
        grounded: Literal["left", "both"] = "left",
        ground_dampings: ArrayLike | None = None,
    ):
        if grounded not in ("left", "both"):
            raise ValueError(
                f"OscillatorChain: grounded={grounded!r}; use 'left' (mass 0 tied to ground, "
                "right end free) or 'both' (both ends tied to ground)."
            )
        m = as_real(masses, "masses")
        k = as_real(stiffnesses, "stiffnesses")
        c = as_real(dampings, "dampings")
        if m.ndim < 1 or m.shape[-1] < 1:
            raise ValueError(
                f"OscillatorChain: masses must have shape (*batch, N) with N >= 1; got {m.shape}."
            )
        n = m.shape[-1]
        n_springs = n if grounded == "left" else n + 1
        if k.ndim < 1 or k.shape[-1] != n_springs:
            ends = "m(N-1)-ground" if grounded == "both" else "m(N-2)-m(N-1)"
            raise ValueError(
                f"OscillatorChain: a chain of {n} masses grounded {grounded!r} has "
                f"{n_springs} springs (ground-m0 ... {ends}), so stiffnesses must have "
                f"shape (*batch, {n_springs}); got {k.shape}."
            )
        if c.shape != k.shape:
            raise ValueError(
                "OscillatorChain: dampings must have the same shape as stiffnesses (one "
                f"damper parallel to every spring); got {c.shape} and {k.shape}. Use zeros "
                "for undamped springs."
            )
        if ground_dampings is None:
            g = jnp.zeros_like(m)
        else:
            g = as_real(ground_dampings, "ground_dampings")
            if g.shape != m.shape:
                raise ValueError(
                    "OscillatorChain: ground_dampings must have the shape of masses "
                    f"(*batch, N) = {m.shape}; got {g.shape}."
                )
        check_batch([m.shape[:-1], k.shape[:-1], c.shape[:-1], g.shape[:-1]], "OscillatorChain")
        dtype = jnp.result_type(m, k, c, g)
        m, k, c, g = (x.astype(dtype) for x in (m, k, c, g))
        # `~(x > 0)` also catches NaN.
        m = eqx.error_if(m, ~(m > 0), "OscillatorChain: masses must be > 0 kg.")
        k = eqx.error_if(k, ~(k > 0), "OscillatorChain: stiffnesses must be > 0 N/m.")
        c = eqx.error_if(c, ~(c >= 0), "OscillatorChain: dampings must be >= 0 N·s/m.")
        g = eqx.error_if(g, ~(g >= 0), "OscillatorChain: ground_dampings must be >= 0 N·s/m.")
        self.masses, self.stiffnesses, self.dampings, self.ground_dampings = m, k, c, g
        self.grounded = grounded

    @classmethod
    def rayleigh(
        cls,
        masses: ArrayLike,
        stiffnesses: ArrayLike,
        alpha: ArrayLike,
        beta: ArrayLike,
        *,
        grounded: Literal["left", "both"] = "left",
    ) -> "OscillatorChain":
        """Chain with Rayleigh (proportional) damping `C = α M + β K`.

        Realised as dampers `c_i = β k_i` parallel to the springs and ground dampers
        `α m_i` (Rayleigh, *The Theory of Sound*, 1877; Ewins, *Modal Testing*, 2000,
        ch. 2). Its modes are the undamped ones with `ζ_k = α / (2 ω_k) + β ω_k / 2`.

        **Arguments:**

        - `masses`, `stiffnesses`, `grounded`: as for [`OscillatorChain`][].
        - `alpha`: mass-proportional coefficient [1/s], >= 0, scalar or `(*batch,)`.
        - `beta`: stiffness-proportional coefficient [s], >= 0, scalar or `(*batch,)`.

        **Returns:**

        An [`OscillatorChain`][].
        """
        m = as_real(masses, "masses")
        k = as_real(stiffnesses, "stiffnesses")
        alpha = as_real(alpha, "alpha")
        beta = as_real(beta, "beta")
        return cls(
            m,
            k,
            beta[..., None] * k,
            grounded=grounded,
            ground_dampings=alpha[..., None] * m,
        )

    # -- structure -------------------------------------------------------------------

    @property
    def n_masses(self) -> int:
        """Number of masses (degrees of freedom) `N` (static)."""
        return self.masses.shape[-1]

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading axes of the parameters: `()` for one chain, `(n,)` for a family."""
        return self.masses.shape[:-1]

    @property
    def n_inputs(self) -> int:
        """One force per mass (static)."""
        return self.n_masses

    @property
    def n_outputs(self) -> int:
        """One displacement per mass (static)."""
        return self.n_masses

    @property
    def order(self) -> int:
        """`2N` states: displacements and velocities (static)."""
        return 2 * self.n_masses

    def response(self, s: Complex[Array, " freq"]) -> Complex[Array, "freq out in"]:
        """Receptance `(M s² + C s + K)⁻¹` of one chain, `(freq, N, N)` [m/N]."""
        return self._displacements(s, np.arange(self.n_masses))

    def modal_realisation(self) -> ModalRealisation:
        every = np.arange(self.n_masses)
        return self._state_space_one(every, every, 0).modal_realisation()

    def _elements(self, x: Array) -> tuple[Array, Array, Array]:
        """Split per-spring values into (ground at left, couplings (N-1,), ground at right)."""
        n = self.n_masses
        right = x[n] if self.grounded == "both" else jnp.zeros((), x.dtype)
        return x[0], x[1:n], right

    def _tridiagonal(self, x: Array, extra: Array) -> tuple[Array, Array]:
        """Diagonal `(N,)` and off-diagonal `(N-1,)` of the assembled K (or C) of one chain.

        Each element between masses i and j adds `x [[1, -1], [-1, 1]]` to rows/columns
        (i, j); an element to ground adds `x` to the diagonal only.
        """
        left, couple, right = self._elements(x)
        zero = jnp.zeros(1, x.dtype)
        diag = jnp.concatenate([couple, zero]) + jnp.concatenate([zero, couple]) + extra
        diag = diag.at[0].add(left).at[-1].add(right)
        return diag, -couple

    def _matrices(self) -> tuple[Array, Array, Array]:
        """Dense `(M, C, K)` of one (unbatched) chain."""

        def dense(d, off):
            return jnp.diag(d) + jnp.diag(off, 1) + jnp.diag(off, -1)

        M = jnp.diag(self.masses)
        C = dense(*self._tridiagonal(self.dampings, self.ground_dampings))
        K = dense(*self._tridiagonal(self.stiffnesses, jnp.zeros_like(self.masses)))
        return M, C, K

    def mass_matrix(self) -> Float[Array, "*batch n n"]:
        """Diagonal mass matrix `M` [kg]."""
        return map_batch(lambda ch: ch._matrices()[0], self)

    def damping_matrix(self) -> Float[Array, "*batch n n"]:
        """Tridiagonal damping matrix `C` [N·s/m] (plus ground dampers on the diagonal)."""
        return map_batch(lambda ch: ch._matrices()[1], self)

    def stiffness_matrix(self) -> Float[Array, "*batch n n"]:
        """Tridiagonal stiffness matrix `K` [N/m]."""
        return map_batch(lambda ch: ch._matrices()[2], self)

    # -- frequency domain ------------------------------------------------------------

    def _displacements(self, s: Array, force: Array) -> Array:
        """`X(s) = (M s² + C s + K)⁻¹ E_force` of one chain, shape `(freq, N, n_force)`."""
        M, C, K = self._matrices()
        ss = s[:, None, None]
        Z = K + ss * C + ss**2 * M  # dynamic stiffness, (freq, N, N)
        E = jnp.eye(self.n_masses, dtype=Z.dtype)[:, force]
        return jnp.linalg.solve(Z, jnp.broadcast_to(E, (s.shape[0],) + E.shape))

    def _s(self, omega: Array) -> Array:
        dtype = jnp.result_type(self.masses, omega)
        omega = omega.astype(dtype)
        return jax.lax.complex(jnp.zeros_like(omega), omega)

    def frf(
        self,
        omega: ArrayLike,
        *,
        response: int | Sequence[int] | None = None,
        force: int | Sequence[int] | None = None,
        quantity: Literal["displacement", "velocity", "acceleration"] = "displacement",
    ) -> Complex[Array, "..."]:
        r"""Frequency response functions `H_ab(jω)` from the force at `b` to the motion of `a`.

        Solves `(K − ω² M + jω C) X = F` for unit forces at the `force` masses (one batched
        linear solve over frequencies), i.e. the receptance `H = (K − ω² M + jω C)⁻¹`
        (Ewins, *Modal Testing*, 2000, ch. 2; Doerrer et al. 2022, eq. 1). Mobility and
        accelerance are `jω H` and `−ω² H`.

        **Arguments:**

        - `omega`: `(freq,)` angular frequencies [rad/s].
        - `response`: mass index (int), sequence of indices, or `None` for all masses.
        - `force`: mass index (int), sequence of indices, or `None` for all masses.
        - `quantity`: `"displacement"` (receptance [m/N]), `"velocity"` (mobility
          [m/(N·s)]) or `"acceleration"` (accelerance [m/(N·s²)]).

        **Returns:**

        Complex `(*batch, freq, out, in)`; the `out` / `in` axis is dropped where
        `response` / `force` is a single int.
        """
        where = "OscillatorChain.frf"
        omega = as_omega(omega, where)
        n = self.n_masses
        resp, r_scalar = _indices(response, n, "response", where)
        frc, f_scalar = _indices(force, n, "force", where)
        p = _quantity_power(quantity, where)
        h = _apply(self, "_frf_one", omega, np.asarray(resp), np.asarray(frc), p)
        if f_scalar:
            h = h[..., 0]
        if r_scalar:
            h = h[..., 0, :] if not f_scalar else h[..., 0]
        return h

    def _frf_one(self, omega: Array, resp: Array, frc: Array, p: int) -> Array:
        s = self._s(omega)
        return self._displacements(s, frc)[:, resp, :] * (s**p)[:, None, None]

    def tmf(self, omega: ArrayLike, a: int, b: int, c: int) -> Complex[Array, "*batch freq"]:
        r"""Transmissibility `T_ab^c(jω) = x_a / x_b = H_ac / H_bc` for a force at mass `c`.

        Doerrer et al. 2022, eq. 6: the ratio of the motions of masses `a` and `b` when
        only mass `c` is forced. It is the same for displacement, velocity and
        acceleration. It does not depend on `c` as long as the force acts on the same side
        of both points (`c <= min(a, b)` or `c >= max(a, b)`): the part of the chain beyond
        the point nearer to the force carries no external force and is driven only through
        that point (the study's Figure 3, `T_32^1 = T_32^2 ≠ T_32^3`).

        **Arguments:**

        - `omega`: `(freq,)` angular frequencies [rad/s].
        - `a`, `b`: mass indices of the output and reference motion.
        - `c`: mass index where the force acts.

        **Returns:**

        Complex `(*batch, freq)`.
        """
        where = "OscillatorChain.tmf"
        omega = as_omega(omega, where)
        n = self.n_masses
        a, b, c = (_index(i, n, nm, where) for i, nm in ((a, "a"), (b, "b"), (c, "c")))
        return _apply(self, "_tmf_one", omega, np.array([a, b, c]))

    def _tmf_one(self, omega: Array, abc: Array) -> Array:
        x = self._displacements(self._s(omega), abc[2:])[:, :, 0]
        return x[:, abc[0]] / x[:, abc[1]]

    # -- conversions -----------------------------------------------------------------

    def state_space(
        self,
        force: int | Sequence[int],
        outputs: int | Sequence[int] | None = None,
        *,
        quantity: Literal["displacement", "velocity", "acceleration"] = "displacement",
    ) -> StateSpace:
        r"""The chain as a `jaxvs.StateSpace` with forces as inputs and motions as outputs.

        States are `(x, x')` (displacements [m], then velocities [m/s]):
        `A = [[0, I], [−M⁻¹K, −M⁻¹C]]`, `B = [0; M⁻¹ E_force]`. Displacement and velocity
        outputs select states (`D = 0`); acceleration outputs are rows of
        `x'' = −M⁻¹K x − M⁻¹C x' + M⁻¹ f`, so `D = E_outᵀ M⁻¹ E_force` (nonzero,
        `1/m_c`, only where an output mass is forced).

        **Arguments:**

        - `force`: mass index or sequence of indices where the input forces [N] act.
        - `outputs`: mass index, sequence of indices, or `None` (all masses).
        - `quantity`: `"displacement"` [m], `"velocity"` [m/s] or `"acceleration"` [m/s²].

        **Returns:**

        A `StateSpace` of order `2N` with `(*batch)` family axes, inputs and outputs in
        the order given (a single int is one input / output).
        """
        where = "OscillatorChain.state_space"
        n = self.n_masses
        frc, _ = _indices(force, n, "force", where)
        out, _ = _indices(outputs, n, "outputs", where)
        p = _quantity_power(quantity, where)
        return _apply(self, "_state_space_one", np.asarray(frc), np.asarray(out), p)

    def _state_space_one(self, frc: Array, out: Array, p: int) -> StateSpace:
        _, C, K = self._matrices()
        minv = 1.0 / self.masses
        eye = jnp.eye(self.n_masses, dtype=minv.dtype)
        lower = jnp.concatenate([-minv[:, None] * K, -minv[:, None] * C], axis=1)
        A = jnp.concatenate([jnp.concatenate([jnp.zeros_like(eye), eye], axis=1), lower])
        Bl = minv[:, None] * eye[:, frc]
        B = jnp.concatenate([jnp.zeros_like(Bl), Bl])
        Eo = eye[out]
        D = jnp.zeros((len(out), len(frc)), minv.dtype)
        if p == 0:
            Cm = jnp.concatenate([Eo, jnp.zeros_like(Eo)], axis=1)
        elif p == 1:
            Cm = jnp.concatenate([jnp.zeros_like(Eo), Eo], axis=1)
        else:
            Cm, D = Eo @ lower, Eo @ Bl
        return StateSpace(A, B, Cm, D)

    def _normal_modes(self) -> NormalModes:
        _, C, K = self._matrices()
        # Symmetric reduction of K φ = ω² M φ with diagonal M: K̃ = M^{-1/2} K M^{-1/2},
        # φ = M^{-1/2} v (Ewins 2000, ch. 2). K̃ is an irreducible symmetric tridiagonal
        # (Jacobi) matrix since every coupling spring is > 0, so its eigenvalues are simple
        # (differentiable) and every eigenvector has a nonzero first entry (Parlett, *The
        # Symmetric Eigenvalue Problem*, 1998, ch. 7), which fixes the sign convention.
        r = 1.0 / jnp.sqrt(self.masses)
        lam, V = jnp.linalg.eigh(r[:, None] * K * r[None, :])
        V = V * jnp.where(V[0] < 0, -1.0, 1.0)
        phi = r[:, None] * V
        # K is positive definite for a grounded chain: the clip only removes rounding.
        omega = jnp.sqrt(jnp.maximum(lam, jnp.finfo(lam.dtype).tiny))
        zeta = jnp.einsum("ik,ij,jk->k", phi, C, phi) / (2 * omega)
        return NormalModes(omega, phi, zeta)

    def modal_parameters(self) -> NormalModes:
        r"""Natural frequencies, mass-normalised mode shapes and modal damping ratios.

        Solves the generalised eigenproblem `K φ = ω² M φ` (Ewins 2000, ch. 2; Pislaru
        2001, natural frequencies by generalised eigenvalues) through the symmetric
        reduction `M^{-1/2} K M^{-1/2}` and `eigh`; `ζ_k = φ_kᵀ C φ_k / (2 ω_k)`.

        **Returns:**

        A [`NormalModes`][] with `(*batch)` family axes.
        """
        return _apply(self, "_normal_modes")

    def to_modal(
        self, force: int | Sequence[int], outputs: int | Sequence[int] | None = None
    ) -> ModalModel:
        r"""The receptance as a `jaxvs.ModalModel`, exact for proportional damping.

        With classical normal modes (`Φᵀ C Φ` diagonal, e.g. Rayleigh damping
        `C = α M + β K`; Caughey & O'Kelly, *J. Appl. Mech.* 32, 1965)
        `H_ac(s) = Σ_k φ_ak φ_ck / (s² + 2 ζ_k ω_k s + ω_k²)` (Ewins 2000, ch. 2): real modal
        constants `φ_ak φ_ck` [1/kg].

        **Arguments:**

        - `force`: mass index or sequence of indices of the input forces [N].
        - `outputs`: mass index, sequence of indices, or `None` (all masses) of the
          output displacements [m].

        **Returns:**

        A `ModalModel` with `N` modes; residues `(*batch, mode)` for an int `force` and
        `outputs`, `(*batch, mode, out)` for an int `force`, else `(*batch, mode, out, in)`.

        Non-proportional damping (largest off-diagonal entry of `Φᵀ C Φ` above
        1e-6 of its largest diagonal entry) raises at run time (`eqx.error_if`): its modes
        are complex; use `state_space(...)` (whose `modal_realisation()` is exact for any
        damping) or `frf(...)` instead.
        """
        where = "OscillatorChain.to_modal"
        n = self.n_masses
        frc, f_scalar = _indices(force, n, "force", where)
        out, o_scalar = _indices(outputs, n, "outputs", where)
        squeeze = 0 if not f_scalar else (2 if o_scalar else 1)
        return _apply(self, "_to_modal_one", np.asarray(frc), np.asarray(out), squeeze)

    def _to_modal_one(self, frc: Array, out: Array, squeeze: int) -> ModalModel:
        _, C, _ = self._matrices()
        modes = self._normal_modes()
        phi = modes.mode_shapes
        D = phi.T @ C @ phi
        off = jnp.max(jnp.abs(D - jnp.diag(jnp.diag(D))))
        zeta = eqx.error_if(
            modes.zeta,
            off > _PROPORTIONAL_RTOL * jnp.max(jnp.abs(jnp.diag(D))),
            "OscillatorChain.to_modal: the damping is not proportional (Φᵀ C Φ is not "
            "diagonal), so the modes are complex and a ModalModel with real modal "
            "constants would be wrong. Use chain.state_space(...) or chain.frf(...), or "
            "build the chain with OscillatorChain.rayleigh(...).",
        )
        # r_k[o, i] = φ_{out_o, k} φ_{force_i, k}; trailing io axes dropped for int indices
        res = phi[out].T[:, :, None] * phi[frc].T[:, None, :]
        res = res.reshape(res.shape[: res.ndim - squeeze])
        return ModalModel(modes.omega_n, zeta, res)

    def _minors(self) -> tuple[Array, Array, Array]:
        """Leading and trailing principal minors of `Z(s) = M s² + C s + K`, and couplings.

        Returns `theta (N+1, L)`, `phi (N+1, L)` and `kappa (N-1, 2)`, polynomial
        coefficients lowest power first with `L = 2N + 1`: `theta[i]` is the determinant of
        the leading `i x i` block (masses `0..i-1`), `phi[j]` that of the trailing block
        (masses `j..N-1`), `kappa[l] = k_l + c_l s` the coupling between masses `l`, `l+1`.
        Three-term recurrences of a tridiagonal determinant (Usmani, *Linear Algebra
        Appl.* 212/213, 1994): `θ_{i+1} = z_i θ_i − κ_{i-1}² θ_{i-1}`, and mirrored for φ.
        """
        n = self.n_masses
        L = 2 * n + 1
        kd, koff = self._tridiagonal(self.stiffnesses, jnp.zeros_like(self.masses))
        cd, coff = self._tridiagonal(self.dampings, self.ground_dampings)
        z = jnp.stack([kd, cd, self.masses], axis=-1)  # z_i(s) = K_ii + C_ii s + m_i s²
        kappa = jnp.stack([-koff, -coff], axis=-1)  # (N-1, 2)
        kappa2 = jnp.stack(
            [kappa[:, 0] ** 2, 2 * kappa[:, 0] * kappa[:, 1], kappa[:, 1] ** 2], axis=-1
        )  # κ_l², (N-1, 3)
        one = jnp.zeros(L, z.dtype).at[0].set(1.0)
        zero = jnp.zeros(L, z.dtype)

        def step(carry, x):
            prev, prevprev = carry
            zi, k2 = x
            new = _mul_quadratic(prev, zi) - _mul_quadratic(prevprev, k2)
            return (new, prev), new

        k2_fwd = jnp.concatenate([jnp.zeros((1, 3), z.dtype), kappa2])  # κ_{i-1}², i = 0..N-1
        _, th = jax.lax.scan(step, (one, zero), (z, k2_fwd))
        theta = jnp.concatenate([one[None], th])
        k2_bwd = jnp.concatenate([kappa2, jnp.zeros((1, 3), z.dtype)])[::-1]  # κ_j², j=N-1..0
        _, ph = jax.lax.scan(step, (one, zero), (z[::-1], k2_bwd))
        phi = jnp.concatenate([ph[::-1], one[None]])
        return theta, phi, kappa

    def transmissibility_model(self, a: int, b: int, c: int) -> RationalTF:
        r"""The TMF `T_ab^c(s) = H_ac(s) / H_bc(s)` as an exact `jaxvs.RationalTF`.

        `H_ac = N_ac / Δ` and `H_bc = N_bc / Δ` share the characteristic polynomial
        `Δ = det(M s² + C s + K)`, so `T_ab^c = N_ac / N_bc` (Doerrer et al. 2022, eq. 6 and
        8). For a tridiagonal `Z(s)` the cofactors are products (Usmani 1994): for
        `i <= j`, `N_ij = θ_i · Π_{l=i}^{j-1} (k_l + c_l s) · φ_{j+1}` with the leading and
        trailing minors `θ`, `φ`. Factors common to `N_ac` and `N_bc` are cancelled
        exactly, so the model has the minimal order; e.g. for `c <= b < a` it is
        `Π_{l=b}^{a-1} (k_l + c_l s) · φ_{a+1} / φ_{b+1}`, independent of `c` (the study's
        `T_32^1 = T_32^2`, Figure 3).

        **Arguments:**

        - `a`, `b`: mass indices of the output and reference motion (`a != b`).
        - `c`: mass index where the force acts.

        **Returns:**

        A `RationalTF` (with `(*batch)` family axes) whose numerator is padded with
        leading zeros to the length of the denominator (a TMF of equal orders).

        **Raises:**

        `ValueError` when `a == b` (`T = 1`) or when `b` is farther from the force than
        `a` (`|b − c| > |a − c|`): that TMF is improper (more zeros than poles), which no
        jaxvs model represents; use `tmf(...)` for its response or model `T_ba^c = 1 / T`.
        At run time, a force strictly between `a` and `b` with undamped couplings between
        `c` and `b` lowers the order below its static form and raises (`eqx.error_if`).
        """
        where = "OscillatorChain.transmissibility_model"
        n = self.n_masses
        a, b, c = (_index(i, n, nm, where) for i, nm in ((a, "a"), (b, "b"), (c, "c")))
        if a == b:
            raise ValueError(f"{where}: a and b are both {a}; T_aa^c = 1 has no dynamics.")
        lo_a, hi_a = min(a, c), max(a, c)
        lo_b, hi_b = min(b, c), max(b, c)
        # Cancel the factors N_ac and N_bc share. θ_0 = φ_N = 1 are neutral, so a cancelled
        # θ or φ becomes index 0 or N; spring factors κ_l are kept where only one of the two
        # spans [lo, hi) covers l. Indices and masks travel as arrays, so every TMF of the
        # same order shares one compiled program.
        theta_idx = np.array([lo_a, lo_b]) if lo_a != lo_b else np.zeros(2, int)
        phi_idx = np.array([hi_a + 1, hi_b + 1]) if hi_a != hi_b else np.full(2, n)
        springs = np.arange(n - 1)
        span_a = (springs >= lo_a) & (springs < hi_a)
        span_b = (springs >= lo_b) & (springs < hi_b)
        masks = np.stack([span_a & ~span_b, span_b & ~span_a])
        # degrees: θ_i → 2i, φ_j → 2(N - j), κ_l → 1
        deg_num, deg_den = (
            int(2 * theta_idx[i] + 2 * (n - phi_idx[i]) + masks[i].sum()) for i in (0, 1)
        )
        if deg_num > deg_den:
            raise ValueError(
                f"{where}: T_ab^c with a={a}, b={b}, c={c} is improper (numerator order "
                f"{deg_num} > denominator order {deg_den}) because b is farther from the force "
                "than a. Use chain.tmf(...) for its frequency response, or model the inverse "
                "T_ba^c (swap a and b)."
            )
        return _apply(self, "_tmf_model_one", theta_idx, phi_idx, masks, deg_den)

    def _tmf_model_one(
        self, theta_idx: Array, phi_idx: Array, masks: Array, order: int
    ) -> RationalTF:
        theta, phi, kappa = self._minors()
        L = 2 * self.n_masses + 1
        one = jnp.zeros(L, theta.dtype).at[0].set(1.0)

        def spring_product(mask):
            # Π_l κ_l^mask_l by multiplying with (k_l + c_l s) or 1, one spring at a time
            def step(p, x):
                kap, use = x
                q = jnp.where(use, kap, jnp.array([1.0, 0.0], kap.dtype))
                return q[0] * p + q[1] * jnp.concatenate([jnp.zeros(1, p.dtype), p[:-1]]), None

            return jax.lax.scan(step, one, (kappa, mask))[0]

        def polynomial(i):
            p = jnp.convolve(theta[theta_idx[i]], phi[phi_idx[i]])[:L]
            return jnp.convolve(p, spring_product(masks[i]))[:L]

        num = polynomial(0)[: order + 1][::-1]
        den = polynomial(1)[: order + 1][::-1]
        den = eqx.error_if(
            den,
            den[0] == 0,
            "OscillatorChain.transmissibility_model: the couplings between the force and b "
            "are undamped, so T_ab^c has a lower order than its structure; give them a small "
            "damping > 0 or use chain.tmf(...) for the response.",
        )
        return RationalTF(num, den)
