r"""Mechanical transmission of a feed drive: rigid axis, flexible chain, ball screw.

All mechanical models work in **linear load-side coordinates**: a rotary part of
inertia `J` [kg·m²] behind a ball screw of lead `p` [m/rev] appears as the equivalent
mass `J·(2π/p)²` [kg], a torsional stiffness `k_t` [N·m/rad] as `k_t·(2π/p)²` [N/m], a
motor torque `T` [N·m] as the force `T·2π/p` [N] (Pislaru 2001, §3.5 and §4.2: load
inertia reflected to the motor; Altintas, *Manufacturing Automation*, 2012, ch. 6).
Degree of freedom 0 is the motor side (where the drive force acts and the rotary
encoder / tachometer measure), the last one the table (where guideway friction and
external forces act, and the linear encoder measures).

- [`RigidAxis`][]: one mass, the EMPS / IDIM model `M q̈ = f − F(q̇)`.
- [`FlexibleAxis`][]: a chain of masses and spring–dampers (two-mass lumped model,
  hybrid model with a distributed ball screw), friction on the table and optionally on
  the motor, backlash (dead zone) in one spring.
- [`BallScrew`][]: geometry and material of a screw, with builders of the rigid, lumped
  and distributed (`n_segments` torsional elements) axis models.
"""

import abc

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..._misc import as_real
from .._base import check_parameters
from ..lti import NormalModes, normal_modes
from ._friction import AbstractFriction, NoFriction, dead_zone

__all__ = ["AbstractMechanics", "BallScrew", "FlexibleAxis", "RigidAxis"]


def _friction(f, where: str) -> AbstractFriction:
    if f is None:
        return NoFriction()
    if not isinstance(f, AbstractFriction):
        raise TypeError(
            f"{where}: friction must be a jaxvs friction law (ViscousFriction, "
            "CoulombViscousFriction, StribeckFriction, AsymmetricFriction, ...) or None; got "
            f"{type(f).__name__}."
        )
    return f


class AbstractMechanics(eqx.Module):
    """Mechanical part of a drive: masses, springs, friction, in linear coordinates [m]."""

    def __check_init__(self):
        check_parameters(self)


    @property
    @abc.abstractmethod
    def n_dof(self) -> int:
        """Number of degrees of freedom (static); 0 = motor side, `n_dof − 1` = table."""

    @abc.abstractmethod
    def acceleration(
        self,
        q: Float[Array, " dof"],
        v: Float[Array, " dof"],
        force: Float[Array, ""],
        external: Float[Array, ""],
    ) -> Float[Array, " dof"]:
        """`q̈` [m/s²] under the drive force `force` [N] on the motor side and the
        external (process) force `external` [N] on the table."""

    @abc.abstractmethod
    def matrices(self) -> tuple[Array, Array, Array]:
        """`(M, C, K)` of the linear part [kg, N·s/m, N/m] (friction and backlash left out)."""

    def normal_modes(self) -> NormalModes:
        """Natural frequencies [rad/s] and mass-normalised mode shapes of the linear part
        (generalised eigenproblem `K φ = ω² M φ`; a free chain has a rigid-body mode at 0)."""
        M, C, K = self.matrices()
        return normal_modes(K, M, C)


class RigidAxis(AbstractMechanics):
    """Rigid axis: all moving parts as one mass, `M q̈ = f + f_ext − F(q̇)` (the IDM of the
    EMPS benchmark, Janot et al. 2019, eq. (1) and (3); Pislaru 2001, §4.2).

    **Arguments:**

    - `mass`: total moving mass reflected to the table [kg], > 0.
    - `friction`: a friction law (default none).
    """

    mass: Float[Array, ""]
    friction: AbstractFriction

    def __init__(self, mass: ArrayLike, friction: AbstractFriction | None = None):
        m = as_real(mass, "RigidAxis: mass")
        self.mass = eqx.error_if(m, ~(m > 0), "RigidAxis: mass must be > 0 kg.")
        self.friction = _friction(friction, "RigidAxis")

    @property
    def n_dof(self) -> int:
        return 1

    def acceleration(self, q, v, force, external):
        return ((force + external - self.friction(v[0])) / self.mass)[None]

    def matrices(self):
        z = jnp.zeros((1, 1), self.mass.dtype)
        return self.mass.reshape(1, 1), z, z


class FlexibleAxis(AbstractMechanics):
    r"""Chain of masses joined by spring–dampers: motor (index 0) … table (last index).

    `m_i q̈_i = F_i − s_i + s_{i−1}` with the spring forces
    `s_i = k_i · d_i(q_i − q_{i+1}) + c_i (q̇_i − q̇_{i+1})`, where `d_i` is the identity or,
    for the spring `backlash_spring`, the dead zone of half width `backlash` (play in a nut,
    gear or coupling, Pislaru 2001, §4.3.1). `F_0` = drive force − motor friction,
    `F_last` = external force − guideway friction.

    **Arguments:**

    - `masses`: `(dof,)` equivalent masses [kg], > 0, `dof >= 2`.
    - `stiffnesses`: `(dof − 1,)` spring rates [N/m], > 0.
    - `dampings`: `(dof − 1,)` dampers parallel to the springs [N·s/m], >= 0 (explicit
      damping coefficients of the hybrid model).
    - `friction`: friction law of the table (guideway), default none.
    - `motor_friction`: friction law on the motor side (bearings, seals), default none.
    - `backlash`: half width `b` [m] of the dead zone (default 0: none; total play `2b`).
    - `backlash_spring`: index of the spring with the play (static, default the last one,
      between nut and table).
    - `backlash_smoothness`: corner rounding of the dead zone [m] (static, default 0).
    """

    masses: Float[Array, " dof"]
    stiffnesses: Float[Array, " spring"]
    dampings: Float[Array, " spring"]
    backlash: Float[Array, ""]
    friction: AbstractFriction
    motor_friction: AbstractFriction
    backlash_spring: int = eqx.field(static=True)
    backlash_smoothness: float = eqx.field(static=True)

    def __init__(
        self,
        masses: ArrayLike,
        stiffnesses: ArrayLike,
        dampings: ArrayLike,
        *,
        friction: AbstractFriction | None = None,
        motor_friction: AbstractFriction | None = None,
        backlash: ArrayLike = 0.0,
        backlash_spring: int = -1,
        backlash_smoothness: float = 0.0,
    ):
        where = "FlexibleAxis"
        m = as_real(masses, f"{where}: masses")
        k = as_real(stiffnesses, f"{where}: stiffnesses")
        c = as_real(dampings, f"{where}: dampings")
        if m.ndim != 1 or m.shape[0] < 2:
            raise ValueError(
                f"{where}: masses must be 1-D with >= 2 entries (motor ... table); got shape "
                f"{m.shape}. Use RigidAxis for one mass; vmap over families."
            )
        n = m.shape[0]
        if k.shape != (n - 1,) or c.shape != (n - 1,):
            raise ValueError(
                f"{where}: {n} masses need {n - 1} stiffnesses and dampings (one spring "
                f"between neighbours); got {k.shape} and {c.shape}."
            )
        if not -(n - 1) <= backlash_spring < n - 1:
            raise ValueError(
                f"{where}: backlash_spring={backlash_spring} is not a spring index (0..{n - 2})."
            )
        self.masses = eqx.error_if(m, ~jnp.all(m > 0), f"{where}: masses must be > 0 kg.")
        self.stiffnesses = eqx.error_if(
            k, ~jnp.all(k > 0), f"{where}: stiffnesses must be > 0 N/m."
        )
        self.dampings = eqx.error_if(c, ~jnp.all(c >= 0), f"{where}: dampings must be >= 0.")
        b = as_real(backlash, f"{where}: backlash")
        self.backlash = eqx.error_if(b, ~(b >= 0), f"{where}: backlash must be >= 0 m.")
        self.friction = _friction(friction, where)
        self.motor_friction = _friction(motor_friction, where)
        self.backlash_spring = backlash_spring % (n - 1)
        self.backlash_smoothness = float(backlash_smoothness)

    @property
    def n_dof(self) -> int:
        return self.masses.shape[-1]

    def spring_forces(self, q, v):
        """Forces `s_i` [N] in the springs (positive in compression of `q_i − q_{i+1}`)."""
        dq = q[:-1] - q[1:]
        dv = v[:-1] - v[1:]
        j = self.backlash_spring
        dz = dead_zone(dq[j], self.backlash, smoothness=self.backlash_smoothness)
        dq = dq.at[j].set(dz)
        return self.stiffnesses * dq + self.dampings * dv

    def acceleration(self, q, v, force, external):
        s = self.spring_forces(q, v)
        zero = jnp.zeros((1,), s.dtype)
        f = jnp.concatenate([zero, s]) - jnp.concatenate([s, zero])
        f = f.at[0].add(force - self.motor_friction(v[0]))
        f = f.at[-1].add(external - self.friction(v[-1]))
        return f / self.masses

    def matrices(self):
        n = self.n_dof
        M = jnp.diag(self.masses)

        def tri(x):
            d = jnp.zeros(n, x.dtype).at[:-1].add(x).at[1:].add(x)
            return jnp.diag(d) - jnp.diag(x, 1) - jnp.diag(x, -1)

        return M, tri(self.dampings), tri(self.stiffnesses)


class BallScrew(eqx.Module):
    r"""A ball screw: solid steel shaft, nut and support bearing (Pislaru 2001, §3.5.3 and
    Appendix C4; Altintas 2012, ch. 6).

    Derived quantities (linear equivalent with the transmission ratio `n = 2π/p`):

    - torsional stiffness `k_t = G·π d⁴/32 / L` [N·m/rad] → `k_t n²` [N/m];
    - axial stiffness `k_a = E·π d²/4 / L` [N/m], in series with the nut and the bearing;
    - rotary inertia `J = ρ·π d⁴/32 · L` [kg·m²] → `J n²` [kg].

    **Arguments:**

    - `length`: free length between bearing and nut [m].
    - `diameter`: root diameter [m].
    - `lead`: travel per revolution `p` [m].
    - `nut_stiffness`: axial stiffness of the nut [N/m].
    - `bearing_stiffness`: axial stiffness of the thrust bearing [N/m].
    - `density`: [kg/m³] (steel, 7850). `youngs_modulus` [Pa] (2.1e11), `shear_modulus`
      [Pa] (8.1e10).
    """

    def __check_init__(self):
        check_parameters(self)


    length: Float[Array, ""]
    diameter: Float[Array, ""]
    lead: Float[Array, ""]
    nut_stiffness: Float[Array, ""]
    bearing_stiffness: Float[Array, ""]
    density: Float[Array, ""]
    youngs_modulus: Float[Array, ""]
    shear_modulus: Float[Array, ""]

    def __init__(
        self,
        length: ArrayLike,
        diameter: ArrayLike,
        lead: ArrayLike,
        *,
        nut_stiffness: ArrayLike = 5e8,
        bearing_stiffness: ArrayLike = 1e9,
        density: ArrayLike = 7850.0,
        youngs_modulus: ArrayLike = 2.1e11,
        shear_modulus: ArrayLike = 8.1e10,
    ):
        where = "BallScrew"
        vals = {
            "length": length,
            "diameter": diameter,
            "lead": lead,
            "nut_stiffness": nut_stiffness,
            "bearing_stiffness": bearing_stiffness,
            "density": density,
            "youngs_modulus": youngs_modulus,
            "shear_modulus": shear_modulus,
        }
        for name, val in vals.items():
            x = as_real(val, f"{where}: {name}")
            x = eqx.error_if(x, ~(x > 0), f"{where}: {name} must be > 0.")
            setattr(self, name, x)

    @property
    def ratio(self) -> Array:
        """Transmission ratio `2π/p` [rad/m]."""
        return 2 * jnp.pi / self.lead

    def torsional_stiffness(self) -> Array:
        """`G π d⁴ / (32 L)` [N·m/rad]."""
        return self.shear_modulus * jnp.pi * self.diameter**4 / 32 / self.length

    def axial_stiffness(self) -> Array:
        """Shaft `E π d² / (4 L)` in series with nut and bearing [N/m]."""
        shaft = self.youngs_modulus * jnp.pi * self.diameter**2 / 4 / self.length
        return 1.0 / (1.0 / shaft + 1.0 / self.nut_stiffness + 1.0 / self.bearing_stiffness)

    def inertia(self) -> Array:
        """Rotary inertia of the shaft `ρ π d⁴ L / 32` [kg·m²]."""
        return self.density * jnp.pi * self.diameter**4 * self.length / 32

    def equivalent_stiffness(self) -> Array:
        """Torsion (reflected) and axial compliance in series [N/m]: the single spring of
        the lumped two-mass model."""
        kt = self.torsional_stiffness() * self.ratio**2
        return 1.0 / (1.0 / kt + 1.0 / self.axial_stiffness())

    def rigid_axis(
        self,
        motor_inertia: ArrayLike,
        table_mass: ArrayLike,
        friction: AbstractFriction | None = None,
    ) -> RigidAxis:
        """Everything reflected to the table as one mass (Pislaru 2001, §4.2).

        **Arguments:**

        - `motor_inertia`: motor rotor (+ coupling) inertia [kg·m²].
        - `table_mass`: table, workpiece and nut [kg].
        - `friction`: guideway friction law.
        """
        m = (jnp.asarray(motor_inertia) + self.inertia()) * self.ratio**2 + table_mass
        return RigidAxis(m, friction)

    def lumped_axis(
        self,
        motor_inertia: ArrayLike,
        table_mass: ArrayLike,
        friction: AbstractFriction | None = None,
        *,
        damping: ArrayLike = 1e-4,
        backlash: ArrayLike = 0.0,
        motor_friction: AbstractFriction | None = None,
    ) -> FlexibleAxis:
        r"""Two-mass model: motor + screw rotation | one spring | table (Pislaru 2001,
        §4.3.1, modular load). The spring is [`equivalent_stiffness`][]; its damper is
        `c = damping · k` (stiffness-proportional, `damping` in seconds).

        **Arguments:**

        - `motor_inertia`: [kg·m²]; `table_mass`: [kg]; `friction`: guideway law.
        - `damping`: stiffness-proportional damping coefficient β [s].
        - `backlash`: half width of the play between nut and table [m].
        - `motor_friction`: bearing/seal friction on the motor side.
        """
        m1 = (jnp.asarray(motor_inertia) + self.inertia()) * self.ratio**2
        k = self.equivalent_stiffness()
        return FlexibleAxis(
            jnp.stack([m1, jnp.asarray(table_mass, m1.dtype)]),
            k[None],
            (damping * k)[None],
            friction=friction,
            motor_friction=motor_friction,
            backlash=backlash,
        )

    def distributed_axis(
        self,
        motor_inertia: ArrayLike,
        table_mass: ArrayLike,
        friction: AbstractFriction | None = None,
        *,
        n_segments: int = 8,
        damping: ArrayLike = 1e-4,
        backlash: ArrayLike = 0.0,
        motor_friction: AbstractFriction | None = None,
    ) -> FlexibleAxis:
        r"""Hybrid model: the screw as `n_segments` torsional finite elements (lumped-mass
        rod), then the axial spring (shaft, nut, bearing) to the table (Pislaru 2001,
        §4.3.3: distributed load, explicit damping coefficients).

        Degrees of freedom: node 0 (motor + half an element) … node `n_segments` (nut
        end), table: `n_segments + 2`. Element stiffness `n_segments · k_t n²`, element
        inertia `J/n_segments · n²` split half/half on its nodes. As `n_segments` grows the
        torsional frequencies converge to those of the continuous shaft; with
        `n_segments = 1` and a light screw it approaches [`lumped_axis`][].

        **Arguments:**

        - as [`lumped_axis`][]; `n_segments`: number of torsional elements (static, >= 1).
        """
        if not isinstance(n_segments, int) or n_segments < 1:
            raise ValueError(
                f"BallScrew.distributed_axis: n_segments must be an int >= 1; got {n_segments!r}."
            )
        n = n_segments
        r2 = self.ratio**2
        m_el = self.inertia() * r2 / n
        node = jnp.full((n + 1,), m_el).at[0].set(m_el / 2).at[-1].set(m_el / 2)
        node = node.at[0].add(jnp.asarray(motor_inertia) * r2)
        masses = jnp.concatenate([node, jnp.asarray(table_mass, node.dtype)[None]])
        k_el = jnp.full((n,), n * self.torsional_stiffness() * r2)
        k = jnp.concatenate([k_el, self.axial_stiffness()[None]])
        return FlexibleAxis(
            masses,
            k,
            damping * k,
            friction=friction,
            motor_friction=motor_friction,
            backlash=backlash,
        )
