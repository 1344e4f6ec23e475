"""Typed dictionaries of physically motivated terms for the slots of discovery.

A slot is a physical place where a missing term enters a family's model; its dictionary
lists the term *kinds* that physics suggests there. A kind is a formula in the slot's
inputs with at most one shape parameter (a velocity scale, a pitch, a time constant, a
force limit); the shape is searched on a grid (the grid members are the dictionary's
columns), and the members kept by the selection are recalibrated with their shape free.
Each kind knows its SymPy form and the named library effect it belongs to, if any.

Drive, slot `force` (an additional force on the axis; inputs: velocity `v`, position
`q`, acceleration `a`, the recorded force `u`, time `t`):

| kind | columns | shape | named effect |
|---|---|---|---|
| `sign(v)` | `sign(v)` | – | `coulomb_friction` |
| `tanh(v/v0)` | `tanh(v/v₀)` | `v₀` | `coulomb_friction` |
| `stribeck` | `exp(−(v/v_s)²)·sign(v)` | `v_s` | `stribeck_friction` |
| `|v|` | `|v|` | – | `asymmetric_friction` |
| `v|v|`, `v^3`, `sqrt|v|·sign(v)` | speed powers | – | – |
| `ripple` | `sin(2πq/p)`, `cos(2πq/p)` | `p` | `position_dependence` |
| `v·exp(-t/tau)` | `v·exp(−t/τ)` | `τ` | – |
| `t`, `t^2` | `t`, `t²` | – | – |

Thermal, slot `heat` (an additional heat flow into the bearing node, in kelvin of its
static temperature rise: it passes through the bearing's lag when the model has one;
inputs: the speed `s = |v_m|` [rpm] over its top `s_max`, the temperatures `T_c`
(chassis), `T_a` (air), `T_w` (water) [°C], time `t` [s]):

| kind | what | shape | named effect |
|---|---|---|---|
| `(s/smax)^p`, p = 1.5, 2, 3 | friction heat (Palmgren) | – | `speed_nonlinearity` |
| `T_a-T_c` | a conductance to the air | – | `ambient_temperature` |
| `T_w-T_c` | a conductance to the water | – | `coolant_temperature` |
| `(s/smax)·exp(-t/tau)` | friction heat fading as a bearing runs in | `τ` | – |
| `exp(-t/tau)`, `t`, `t^2` | a heat flow changing with time | `τ` | – |

Thermal, slot `sensor` (an additive term of the bearing sensor, after the lag; input
time): `exp(-t/tau)` (a thermocouple settling), `t`, `t^2` (a drift).

Drive, slot `input` (an input nonlinearity `u → g(u)`; input the model's force `f_m`,
array `yhat`): `clip(f_m)` (a dead zone, width `d`), `f_m-clip(f_m)` (a gain falling
above `L`: `saturation`), `(f_m/fmax)^3`, `f_m|f_m|`.

Tmf, slot `output` (an additive term of the tool-side motion; inputs `x_e`, its velocity
`xd_e`, the motion's moving rms `amp`): `(x_e/xmax)^3`, `x_e|x_e|`, `sign(xdot_e)`,
`tanh(xdot_e/v0)`, `x_e·(A/Amax)^p`. Slot `static` (a static nonlinearity of the model's
output `x̂_t`, array `yhat`): `(xhat/xhatmax)^3`, `xhat|xhat|`, `xhat-clip(xhat)` (a
clipped sensor or a travel stop, limit `L`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence

import jax.numpy as jnp
import numpy as np

__all__ = [
    "DRIVE_NAMED",
    "THERMAL_NAMED",
    "TMF_NAMED",
    "Kind",
    "Member",
    "drive_force_dictionary",
    "drive_input_dictionary",
    "thermal_heat_dictionary",
    "thermal_sensor_dictionary",
    "tmf_output_dictionary",
    "tmf_static_dictionary",
]


@dataclasses.dataclass(frozen=True)
class Kind:
    """A kind of term: `columns(d, shape, xp) -> (n, k)` with the array module `xp`
    (`jax.numpy` by default, `numpy` for the selection; `d` maps the slot's input names
    to arrays), `sympy(coefs, shape, symbols) -> expression`, the shape's name and
    unit (or `None`), the named effect it belongs to, and a label."""

    name: str
    columns: Callable[[Mapping[str, jnp.ndarray], jnp.ndarray], jnp.ndarray]
    sympy: Callable
    k: int = 1
    shape: str | None = None
    unit: str = ""
    named: str | None = None
    inputs: tuple[str, ...] = ("v",)


@dataclasses.dataclass(frozen=True)
class Member:
    """One column group of a dictionary: a kind at one grid value of its shape."""

    kind: Kind
    shape: float | None = None

    @property
    def label(self) -> str:
        if self.kind.shape is None:
            return self.kind.name
        return f"{self.kind.name} [{self.kind.shape}={self.shape:.4g}{self.kind.unit}]"

    def evaluate(self, d: Mapping[str, np.ndarray]) -> np.ndarray:
        """The member's columns on NumPy arrays `(n, k)`."""
        shape = 1.0 if self.shape is None else float(self.shape)
        d = {k: np.asarray(v) for k, v in d.items()}
        return np.asarray(self.kind.columns(d, shape, np)).reshape(-1, self.kind.k)


def _col(x):
    return x[:, None]


def _sym():
    import sympy as sp

    return sp


def _k_sign():
    return Kind(
        "sign(v)",
        lambda d, s, xp=jnp: _col(xp.sign(d["v"])),
        lambda c, s, x: c[0] * _sym().sign(x["v"]),
        named="coulomb_friction",
    )


def _k_tanh():
    return Kind(
        "tanh(v/v0)",
        lambda d, s, xp=jnp: _col(xp.tanh(d["v"] / s)),
        lambda c, s, x: c[0] * _sym().tanh(x["v"] / _num(s)),
        shape="v0",
        unit=" m/s",
        named="coulomb_friction",
    )


def _k_stribeck():
    return Kind(
        "stribeck",
        lambda d, s, xp=jnp: _col(xp.exp(-xp.square(d["v"] / s)) * xp.sign(d["v"])),
        lambda c, s, x: c[0] * _sym().exp(-((x["v"] / _num(s)) ** 2)) * _sym().sign(x["v"]),
        shape="v_s",
        unit=" m/s",
        named="stribeck_friction",
    )


def _k_absv():
    return Kind(
        "|v|",
        lambda d, s, xp=jnp: _col(xp.abs(d["v"])),
        lambda c, s, x: c[0] * _sym().Abs(x["v"]),
        named="asymmetric_friction",
    )


def _k_vabsv():
    return Kind(
        "v|v|",
        lambda d, s, xp=jnp: _col(d["v"] * xp.abs(d["v"])),
        lambda c, s, x: c[0] * x["v"] * _sym().Abs(x["v"]),
    )


def _k_v3():
    return Kind("v^3", lambda d, s, xp=jnp: _col(d["v"] ** 3), lambda c, s, x: c[0] * x["v"] ** 3)


def _k_sqrtv():
    return Kind(
        "sqrt|v|·sign(v)",
        lambda d, s, xp=jnp: _col(xp.sqrt(xp.abs(d["v"])) * xp.sign(d["v"])),
        lambda c, s, x: c[0] * _sym().sqrt(_sym().Abs(x["v"])) * _sym().sign(x["v"]),
    )


def _k_ripple():
    def cols(d, p, xp=jnp):
        ph = 2 * np.pi * d["q"] / p
        return xp.stack([xp.sin(ph), xp.cos(ph)], -1)

    def sym(c, p, x):
        sp = _sym()
        ph = 2 * sp.pi * x["q"] / _num(p)
        return c[0] * sp.sin(ph) + c[1] * sp.cos(ph)

    return Kind("ripple", cols, sym, k=2, shape="p", unit=" m", named="position_dependence")


def _k_vexp():
    return Kind(
        "v·exp(-t/tau)",
        lambda d, s, xp=jnp: _col(d["v"] * xp.exp(-d["t"] / s)),
        lambda c, s, x: c[0] * x["v"] * _sym().exp(-x["t"] / _num(s)),
        shape="tau",
        unit=" s",
        inputs=("v", "t"),
    )


def _k_t():
    return Kind(
        "t", lambda d, s, xp=jnp: _col(d["t"]), lambda c, s, x: c[0] * x["t"], inputs=("t",)
    )


def _k_t2():
    return Kind(
        "t^2",
        lambda d, s, xp=jnp: _col(d["t"] ** 2),
        lambda c, s, x: c[0] * x["t"] ** 2,
        inputs=("t",),
    )


def _lim(s):
    return _sym().Float(f"{float(s):.4g}", 4)


def _num(s):
    """A shape parameter rounded to four significant digits."""
    return float(f"{float(s):.4g}")


DRIVE_NAMED: dict[str, frozenset[str]] = {
    "coulomb_friction": frozenset({"sign(v)", "tanh(v/v0)"}),
    "asymmetric_friction": frozenset({"sign(v)", "tanh(v/v0)", "|v|"}),
    "stribeck_friction": frozenset({"sign(v)", "tanh(v/v0)", "stribeck"}),
    "position_dependence": frozenset({"ripple"}),
    "saturation": frozenset({"f_m-clip(f_m)"}),
}
"""The kinds each named drive effect is made of (its support in the dictionary)."""


def drive_force_dictionary(d: Mapping[str, np.ndarray]) -> list[Member]:
    """The drive's force-slot dictionary with grids drawn from the calibration data `d`
    (concatenated arrays `v`, `q`, `t`, `u`): velocity scales as fractions of the top
    speed, pitches from 1/60 of the travel to twice the travel in steps of a quarter of
    a cycle over the travel, time constants as fractions of the record's length, force
    limits at high quantiles of `|u|`."""
    vmax = float(np.max(np.abs(d["v"])))
    span = float(np.ptp(d["q"]))
    tmax = float(np.max(d["t"]))
    out = [Member(_k_sign())]
    out += [Member(_k_tanh(), vmax * f) for f in (0.005, 0.01, 0.02, 0.05, 0.1)]
    out += [Member(_k_stribeck(), vmax * f) for f in (0.02, 0.05, 0.1, 0.2, 0.3)]
    out += [Member(_k_absv()), Member(_k_vabsv()), Member(_k_v3()), Member(_k_sqrtv())]
    cycles = np.arange(0.5, 60.01, 0.25)
    out += [Member(_k_ripple(), span / c) for c in cycles]
    out += [
        Member(_k_vexp(), tmax * f)
        for f in (0.05, 0.1, 0.15, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)
    ]
    out += [Member(_k_t()), Member(_k_t2())]
    return out


def drive_input_dictionary(d: Mapping[str, np.ndarray]) -> list[Member]:
    """The drive's input-nonlinearity slot: the axis receives `g(u)`, so the recorded
    force is `u = g⁻¹(f_m)`, `f_m` the force the model says the axis needs (`d["yhat"]`).
    A dead zone (the axis receives `u ∓ d` beyond `±d`) is `u = f_m + clip(f_m, ±d)`-like,
    widths `d` at low quantiles of `|f_m|`; a gain that falls above a level (a soft
    saturation of the amplifier) is `u = f_m + c·(f_m − clip(f_m, ±L))`, `L` at high
    quantiles; a gain that changes with the force (a motor constant falling with the
    current) `(f_m/f_max)³`, `f_m|f_m|/f_max²`."""
    y = np.abs(np.asarray(d["yhat"]))
    fmax = float(np.max(y))
    out = [
        Member(_k_power("yhat", "f_m", fmax, "(f_m/fmax)^3", _cube, lambda z: z**3)),
        Member(_k_power("yhat", "f_m", fmax, "f_m|f_m|", _sabs, lambda z: z * _sym().Abs(z))),
    ]
    out += [
        Member(_k_out_clip("f_m", " N", "f_m"), float(np.quantile(y, q)))
        for q in (0.6, 0.7, 0.8, 0.9, 0.95)
    ]
    return out + [
        Member(_k_deadzone("f_m", " N"), float(np.quantile(y, q)))
        for q in (0.02, 0.05, 0.1, 0.2, 0.3)
    ]


def _k_speed_power(smax: float, p: float):
    def cols(d, s, xp=jnp):
        return _col((d["s"] / smax) ** p)

    return Kind(
        f"(s/smax)^{p:g}",
        cols,
        lambda c, s, x: c[0] * (x["s"] / _num(smax)) ** _sym().nsimplify(p),
        named="speed_nonlinearity",
        inputs=("s",),
    )


def _k_tdiff(key: str, sym: str, named: str):
    return Kind(
        f"{sym}-T_c",
        lambda d, s, xp=jnp: _col(d[key] - d["T_chassis"]),
        lambda c, s, x: c[0] * (x[sym] - x["T_c"]),
        named=named,
        inputs=(key, "T_chassis"),
    )


def _k_sexp(smax: float):
    return Kind(
        "(s/smax)·exp(-t/tau)",
        lambda d, s, xp=jnp: _col(d["s"] / smax * xp.exp(-d["t"] / s)),
        lambda c, s, x: c[0] * x["s"] / _num(smax) * _sym().exp(-x["t"] / _num(s)),
        shape="tau",
        unit=" s",
        inputs=("s", "t"),
    )


def _k_exp():
    return Kind(
        "exp(-t/tau)",
        lambda d, s, xp=jnp: _col(xp.exp(-d["t"] / s)),
        lambda c, s, x: c[0] * _sym().exp(-x["t"] / _num(s)),
        shape="tau",
        unit=" s",
        inputs=("t",),
    )


THERMAL_NAMED: dict[str, frozenset[str]] = {
    "speed_nonlinearity": frozenset({"(s/smax)^1.5", "(s/smax)^2", "(s/smax)^3"}),
    "ambient_temperature": frozenset({"T_a-T_c"}),
    "coolant_temperature": frozenset({"T_w-T_c"}),
}
"""The kinds each named thermal effect is made of (its support in the dictionary)."""

# time constants as fractions of the record: beyond half of it `exp(−t/τ)` is a drift
# (`t`, `t²` over the record), so longer ones are left to those kinds
_TAU_FRACTIONS = (0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5)


def thermal_sensor_dictionary(d: Mapping[str, np.ndarray]) -> list[Member]:
    """The thermal sensor slot's dictionary: `exp(−t/τ)` with `τ` as fractions of the
    record's length (`d["t"]`), `t`, `t²`."""
    tmax = float(np.max(d["t"]))
    out = [Member(_k_exp(), tmax * f) for f in _TAU_FRACTIONS]
    return out + [Member(_k_t()), Member(_k_t2())]


def thermal_heat_dictionary(d: Mapping[str, np.ndarray]) -> list[Member]:
    """The thermal heat-flow slot's dictionary from the calibration data `d` (arrays
    `s`, `T_chassis`, `T_air`, `T_water`, `t`): speed powers over the top speed (when the
    speed varies), temperature differences to the chassis (for the temperatures that
    vary), `(s/s_max)·exp(−t/τ)`, `exp(−t/τ)`, `t`, `t²`."""
    tmax = float(np.max(d["t"]))
    smax = float(np.max(np.abs(d["s"])))
    out: list[Member] = []
    if smax > 0 and float(np.ptp(d["s"])) > 0:
        out += [Member(_k_speed_power(smax, p)) for p in (1.5, 2.0, 3.0)]
        out += [Member(_k_sexp(smax), tmax * f) for f in _TAU_FRACTIONS]
    for key, sym, named in (
        ("T_air", "T_a", "ambient_temperature"),
        ("T_water", "T_w", "coolant_temperature"),
    ):
        if float(np.ptp(d[key] - d["T_chassis"])) > 0 and float(np.ptp(d[key])) > 0:
            out.append(Member(_k_tdiff(key, sym, named)))
    return out + thermal_sensor_dictionary(d)


# ------------------------------------------------------------------------------ tmf

TMF_NAMED: dict[str, frozenset[str]] = {}
"""The tmf library's effects are linear (a mode, a delay, a position or force
dependence of the TMF): no term of the tmf slots' dictionaries belongs to one."""


def _k_power(key: str, sym: str, scale: float, name: str, fn, sym_fn):
    """A power-like kind of the input `key` over its `scale`: `fn(x/scale)`."""
    return Kind(
        name,
        lambda d, s, xp=jnp: _col(fn(d[key] / scale, xp)),
        lambda c, s, x: c[0] * sym_fn(x[sym] / _num(scale)),
        inputs=(key,),
    )


def _cube(z, xp=jnp):
    return z**3


def _sabs(z, xp=jnp):
    return z * xp.abs(z)


def _k_tanh_of(key: str, sym: str, unit: str):
    return Kind(
        f"tanh({sym}/v0)",
        lambda d, s, xp=jnp: _col(xp.tanh(d[key] / s)),
        lambda c, s, x: c[0] * _sym().tanh(x[sym] / _num(s)),
        shape="v0",
        unit=unit,
        inputs=(key,),
    )


def _k_gain_amp(amax: float, p: int):
    """A gain that grows with the motion's amplitude `A`: `x_e·(A/A_max)^p`."""
    return Kind(
        f"x_e·(A/Amax)^{p}",
        lambda d, s, xp=jnp: _col(d["x_e"] * (d["amp"] / amax) ** p),
        lambda c, s, x: c[0] * x["x_e"] * (x["A"] / _num(amax)) ** p,
        inputs=("x_e", "amp"),
    )


def _k_out_clip(sym: str = "xhat_t", unit: str = " m", label: str = "xhat"):
    """`ŷ − clip(ŷ, ±L)` of the model's output `ŷ` (array `yhat`, symbol `sym`)."""
    return Kind(
        f"{label}-clip({label})",
        lambda d, s, xp=jnp: _col(d["yhat"] - xp.clip(d["yhat"], -s, s)),
        lambda c, s, x: c[0] * (x[sym] - _sym().Max(-_lim(s), _sym().Min(x[sym], _lim(s)))),
        shape="L",
        unit=unit,
        inputs=("yhat",),
    )


def _k_deadzone(sym: str, unit: str):
    """`clip(ŷ, ±d)` of the model's output `ŷ` (a dead zone of width `d`)."""
    return Kind(
        f"clip({sym})",
        lambda d, s, xp=jnp: _col(xp.clip(d["yhat"], -s, s)),
        lambda c, s, x: c[0] * _sym().Max(-_lim(s), _sym().Min(x[sym], _lim(s))),
        shape="d",
        unit=unit,
        inputs=("yhat",),
    )


def tmf_output_dictionary(d: Mapping[str, np.ndarray]) -> list[Member]:
    """The tmf's additive output slot (`x_t = T(s) x_e + h(x_e, ẋ_e, A)`): a stiffening
    or softening transmission (`(x_e/x_max)³`, `x_e|x_e|/x_max²`), a friction-like lost
    motion between encoder and tool (`tanh(ẋ_e/v₀)` with `v₀` as fractions of the top
    encoder speed, `sign(ẋ_e)`) and a gain that changes with the motion's amplitude
    (`x_e·(A/A_max)^p`, p = 1, 2). Inputs `x_e`, `xd_e`, `amp` (the slot experiment's)."""
    xmax = float(np.max(np.abs(d["x_e"])))
    vmax = float(np.max(np.abs(d["xd_e"])))
    amax = float(np.max(d["amp"]))
    sign = Kind(
        "sign(xdot_e)",
        lambda d_, s, xp=jnp: _col(xp.sign(d_["xd_e"])),
        lambda c, s, x: c[0] * _sym().sign(x["xdot_e"]),
        inputs=("xd_e",),
    )
    out = [
        Member(_k_power("x_e", "x_e", xmax, "(x_e/xmax)^3", _cube, lambda z: z**3)),
        Member(_k_power("x_e", "x_e", xmax, "x_e|x_e|", _sabs, lambda z: z * _sym().Abs(z))),
        Member(sign),
    ]
    grid = np.geomspace(0.005, 0.5, 9)  # a factor 1.8 between neighbours
    out += [Member(_k_tanh_of("xd_e", "xdot_e", " m/s"), vmax * f) for f in grid]
    return out + [Member(_k_gain_amp(amax, p)) for p in (1, 2)]


def tmf_static_dictionary(d: Mapping[str, np.ndarray]) -> list[Member]:
    """The tmf's static output nonlinearity (`x_t = g(x̂_t)`, `x̂_t` the calibrated TMF's
    output): `(x̂/x̂_max)³`, `x̂|x̂|/x̂_max²` and a clipped sensor or a travel stop
    `x̂ − clip(x̂, ±L)` with `L` at high quantiles of `|x̂|`."""
    y = np.asarray(d["yhat"])
    ymax = float(np.max(np.abs(y)))
    out = [
        Member(_k_power("yhat", "xhat_t", ymax, "(xhat/xhatmax)^3", _cube, lambda z: z**3)),
        Member(_k_power("yhat", "xhat_t", ymax, "xhat|xhat|", _sabs, lambda z: z * _sym().Abs(z))),
    ]
    return out + [
        Member(_k_out_clip(), float(np.quantile(np.abs(y), q))) for q in (0.7, 0.8, 0.9, 0.95)
    ]


def nearest_named(
    kinds: Sequence[str], named: Mapping[str, frozenset[str]]
) -> tuple[str | None, bool]:
    """The named effect nearest to a support of kinds: `(name, True)` when the support
    lies inside one named effect's kinds (the smallest such effect), else the named
    effect sharing most kinds `(name, False)`, or `(None, False)`."""
    s = set(kinds)
    if not s:
        return None, False
    inside = [(len(k), n) for n, k in named.items() if s <= k]
    if inside:
        return min(inside)[1], True
    share = [(len(s & k), -len(k), n) for n, k in named.items() if s & k]
    return (max(share)[2], False) if share else (None, False)
