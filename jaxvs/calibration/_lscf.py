"""Poles of measured FRFs: the polyreference least-squares complex frequency-domain estimator.

The (p)LSCF / PolyMAX estimator (Guillaume, Verboven, Vanlanduit, Van der Auweraer,
Peeters, "A poly-reference implementation of the least-squares complex frequency-domain
estimator", IMAC XXI, 2003; Peeters, Van der Auweraer, Guillaume, Leuridan, "The PolyMAX
frequency-domain method: a new standard for modal parameter estimation?", Shock and
Vibration 11, 2004, eqs. 1-13) fits every row `o` of the measured FRF matrix with a
right matrix-fraction model that shares one denominator,

    H_o(ω) = B_o(ω) A(ω)^-1,   B_o(ω) = Σ_r Ω_r(ω) β_or,   A(ω) = Σ_r Ω_r(ω) α_r,

with real coefficients `β_or` (1 x in) and `α_r` (in x in), polynomial order `p`, and the
discrete-time frequency mapping `Ω_r(ω) = exp(j ω Δt r)`, `Δt = π / ω_max` (the band's top
frequency acts as a Nyquist frequency, which keeps the basis orthogonal on a uniform grid).
The linearised equation error `W_o (B_o - H_o A)` is minimised in the least-squares sense;
eliminating the numerators gives the *reduced normal equations*
`M = Σ_o (T_o - S_o^T R_o^-1 S_o)` (PolyMAX eq. 8) in the denominator coefficients only,
which are solved with the highest coefficient fixed to the identity, `α_p = I` (eq. 9).
The poles are the eigenvalues `z_k` of the block companion matrix of `A` (eq. 12),
mapped back with `λ_k = ln(z_k) / Δt` [rad/s]; the left eigenvectors give the modal
participation factors and `B_o(z_k) v_k` the mode shapes.

Every order `1..max_order` comes from one assembly of the normal matrices of the
highest order: the lower-order matrices are their leading blocks, and the per-order
solves and eigenvalue problems run in one `vmap` by embedding each order's system in
the top-left corner of a fixed-size one (identity / zero padding, whose eigenvalues
sit exactly at `z = 0` and are discarded).

Pole *selection* from the stabilisation diagram is a discrete, non-differentiable
decision; it runs host-side in NumPy (see `select_poles`).
"""

import warnings
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Complex, Float, Int

from .._misc import require_x64

_UNITS = {"rad/s": 1.0, "Hz": 2.0 * np.pi}


# --------------------------------------------------------------------------------------
# Input handling shared by the estimator and the residue fit
# --------------------------------------------------------------------------------------


def _frfdata_arrays(omega, H, unit: str, where: str):
    """Unpack a `jaxvs.data.FRFData` given in place of `omega` (then `H` is omitted).

    Its grid is taken in `unit` (`frequency` [Hz] or `omega` [rad/s]) so that `band`
    keeps the user's unit; `H` is `(freq,)` or `(freq, out, in)`.
    """
    from ..data import FRFData

    if isinstance(omega, FRFData):
        if H is not None:
            raise TypeError(f"{where}: give either an FRFData or (omega, H), not both.")
        if omega.batch_shape:
            raise ValueError(
                f"{where}: the FRFData holds a family {omega.batch_shape}; members of a "
                "family have different poles. Fit one member at a time (index data.H)."
            )
        grid = omega.frequency if unit == "Hz" else omega.omega
        return grid, omega.H
    if H is None:
        raise TypeError(f"{where}: give omega and H (or one FRFData container).")
    return omega, H


def prepare_frf(
    omega: ArrayLike,
    H: ArrayLike,
    *,
    band,
    unit: str,
    weights: ArrayLike | None,
    where: str,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, tuple[int, ...]]:
    """Validate and normalise FRF data (host side; the data are concrete arrays).

    **Returns:** `(omega [rad/s] (freq,), H (freq, out, in), weights (freq, out) or None,
    io_shape)` restricted to `band`, where `io_shape` is `()`, `(out,)` or `(out, in)`
    as given.
    """
    require_x64(where, "the normal equations square the condition number of the polynomial basis")
    if unit not in _UNITS:
        raise ValueError(f"{where}: unit must be 'rad/s' or 'Hz'; got {unit!r}.")
    scale = _UNITS[unit]
    try:
        w = np.asarray(omega)
        h = np.asarray(H)
    except Exception as e:  # traced values: pole estimation is host-side
        raise TypeError(
            f"{where}: omega and H must be concrete arrays (the pole estimation and "
            "selection run outside jit). Call it outside jax.jit / vmap."
        ) from e
    if np.iscomplexobj(w):
        raise TypeError(f"{where}: omega is a real frequency grid; got a complex array.")
    if w.ndim != 1:
        raise ValueError(f"{where}: omega must be 1-D (freq,); got shape {w.shape}.")
    if h.ndim < 1 or h.ndim > 3 or h.shape[0] != w.shape[0]:
        raise ValueError(
            f"{where}: H must have shape (freq,), (freq, out) or (freq, out, in) with "
            f"freq = len(omega) = {w.shape[0]}; got {h.shape}. Put the frequency axis first."
        )
    if not np.issubdtype(h.dtype, np.number):
        raise TypeError(f"{where}: H must be numeric (complex FRF values); got {h.dtype}.")
    w = w.astype(np.float64) * scale
    h = h.astype(np.complex128)
    if not np.all(np.isfinite(w)):
        raise ValueError(f"{where}: omega contains NaN or inf.")
    if np.any(np.diff(w) <= 0):
        raise ValueError(
            f"{where}: omega must be strictly increasing; sort the bins (and H with them)."
        )
    io_shape = h.shape[1:]
    h3 = h.reshape(h.shape[0], *(io_shape + (1,) * (2 - len(io_shape))))
    if weights is not None:
        wt = np.asarray(weights, dtype=np.float64)
        if wt.shape == w.shape:
            wt = np.broadcast_to(wt[:, None], h3.shape[:2])
        if wt.shape != h3.shape[:2]:
            raise ValueError(
                f"{where}: weights must have shape (freq,) or (freq, out) = "
                f"{h3.shape[:2]}; got {np.shape(weights)}."
            )
        if not np.all(np.isfinite(wt)) or np.any(wt < 0):
            raise ValueError(f"{where}: weights must be finite and >= 0.")
    else:
        wt = None
    if band is not None:
        lo, hi = (float(b) * scale for b in band)
        if not lo < hi:
            raise ValueError(f"{where}: band must be (low, high) with low < high; got {band}.")
        keep = (w >= lo) & (w <= hi)
        if not np.any(keep):
            raise ValueError(
                f"{where}: band [{band[0]}, {band[1]}] {unit} lies outside the data, which "
                f"covers [{w[0] / scale:g}, {w[-1] / scale:g}] {unit}."
            )
        w, h3 = w[keep], h3[keep]
        wt = None if wt is None else wt[keep]
    bad = ~np.isfinite(h3)
    if np.any(bad):
        f_bad = np.nonzero(np.any(bad, axis=(1, 2)))[0]
        raise ValueError(
            f"{where}: H contains NaN or inf at {f_bad.size} frequencies (first at "
            f"{w[f_bad[0]] / scale:g} {unit}); drop those bins or choose a band without them."
        )
    if w[0] <= 0:
        raise ValueError(
            f"{where}: the frequencies must be > 0; drop the DC bin (it carries no valid "
            "FRF value in impact or shaker tests), e.g. with band=(f_min, f_max)."
        )
    return w, h3, wt, tuple(io_shape)


# --------------------------------------------------------------------------------------
# The stabilisation diagram
# --------------------------------------------------------------------------------------


class StabilisationDiagram(eqx.Module):
    """Poles of every model order of the pLSCF estimator and their stability flags.

    Poles are padded to a fixed count per order (`pole` axis); `valid` marks the
    physical ones: complex (upper half plane), stable, with a natural frequency inside
    the analysed band. A pole of order `p` is compared with the nearest (in frequency)
    valid pole of order `p - 1`.

    **Fields:**

    - `orders`: `(order,)` polynomial orders `p` (each gives `p * in` poles).
    - `omega_n`: `(order, pole)` natural frequencies `|λ|` [rad/s].
    - `zeta`: `(order, pole)` damping ratios `-Re λ / |λ|` [-].
    - `vectors`: `(order, pole, out * in)` direction of the residue matrix
      `mode shape ⊗ participation factor`, unit norm.
    - `valid`: `(order, pole)` physical pole.
    - `previous`: `(order, pole)` index of the nearest valid pole of the previous order
      (`-1` if none).
    - `stable_frequency`, `stable_damping`, `stable_vector`: `(order, pole)` relative
      frequency change `<= frequency_tol`, relative damping change `<= damping_tol`,
      MAC with the previous pole's vector `>= mac_tol`.
    - `omega`: `(freq,)` the analysed frequency grid [rad/s].
    - `indicator`: `(freq,)` mean |H| over all FRFs (each normalised to unit RMS), the
      curve drawn behind a stabilisation chart.
    - `frequency_tol`, `damping_tol`, `mac_tol`: the criteria (static).
    """

    orders: Int[Array, " order"]
    omega_n: Float[Array, "order pole"]
    zeta: Float[Array, "order pole"]
    vectors: Complex[Array, "order pole channel"]
    valid: Bool[Array, "order pole"]
    previous: Int[Array, "order pole"]
    stable_frequency: Bool[Array, "order pole"]
    stable_damping: Bool[Array, "order pole"]
    stable_vector: Bool[Array, "order pole"]
    omega: Float[Array, " freq"]
    indicator: Float[Array, " freq"]
    frequency_tol: float = eqx.field(static=True)
    damping_tol: float = eqx.field(static=True)
    mac_tol: float = eqx.field(static=True)

    @property
    def stable(self) -> Bool[Array, "order pole"]:
        """Poles stable in frequency, damping and vector (the usual 's' symbol)."""
        return self.valid & self.stable_frequency & self.stable_damping & self.stable_vector

    @property
    def status(self) -> Int[Array, "order pole"]:
        """Chart symbol per pole: `-1` not physical, `0` new ('o'), `1` stable frequency
        ('f'), `2` frequency and damping ('d'), `3` frequency and vector ('v'), `4` all ('s')."""
        f, d, v = self.stable_frequency, self.stable_damping, self.stable_vector
        code = jnp.where(f, jnp.where(d & v, 4, jnp.where(v, 3, jnp.where(d, 2, 1))), 0)
        return jnp.where(self.valid, code, -1)

    @property
    def frequency_hz(self) -> Float[Array, "order pole"]:
        """Natural frequencies [Hz]."""
        return self.omega_n / (2 * jnp.pi)


def _normal_matrices(
    omega: Float[Array, " freq"],
    H: Complex[Array, "freq out in"],
    W: Float[Array, "freq out"],
    p_max: int,
    dt: Float[Array, ""],
):
    """`R_o, S_o, T_o` of PolyMAX eq. 7 for the highest order (real parts).

    With `X_o = W_o Ω` and `Y_o = -W_o (Ω ⊗ H_o)`: `R_o = Re X_o^H X_o`,
    `S_o = Re X_o^H Y_o`, `T_o = Re Y_o^H Y_o`; taking real parts imposes real
    polynomial coefficients.
    """
    r = jnp.arange(p_max + 1)
    Om = jnp.exp(1j * omega[:, None] * dt * r)  # (freq, p+1)
    W2 = W**2
    F, n_out, n_in = H.shape
    R = jnp.einsum("fo,fr,fs->ors", W2, jnp.conj(Om), Om).real
    S = -jnp.einsum("fo,fr,fs,foi->orsi", W2, jnp.conj(Om), Om, H).real
    T = jnp.einsum("fo,fr,foi,fs,foj->orisj", W2, jnp.conj(Om), jnp.conj(H), Om, H).real
    P1 = p_max + 1
    return R, S.reshape(n_out, P1, P1 * n_in), T.reshape(n_out, P1 * n_in, P1 * n_in)


def _poles_of_order(p, R, S, T, dt, n_in: int, p_max: int):
    """Poles, mode shapes and participation factors of order `p` (traced integer).

    The order-`p` normal matrices are the leading blocks of the order-`p_max` ones; they
    are embedded in fixed-size systems (identity where a matrix is inverted, zero where
    it is multiplied), so every order shares one compiled program.
    """
    P1 = p_max + 1
    coef = jnp.arange(P1)
    keep_c = coef <= p  # numerator / denominator coefficients 0..p
    keep_a = jnp.repeat(keep_c, n_in)  # denominator entries (block r, row i)
    eye_r = jnp.eye(P1, dtype=R.dtype)
    Rp = jnp.where(keep_c[:, None] & keep_c[None, :], R, eye_r)
    Sp = jnp.where(keep_c[:, None] & keep_a[None, :], S, 0.0)
    Tp = jnp.where(keep_a[:, None] & keep_a[None, :], T, 0.0)
    RinvS = jnp.linalg.solve(Rp, Sp)  # (out, p+1, (p+1) in)
    M = jnp.sum(Tp - jnp.einsum("ors,orc->osc", Sp, RinvS), axis=0)
    # α_p = I: solve M[:pI, :pI] α_{0..p-1} = -M[:pI, pI:(p+1)I] with I = n_in (eq. 9)
    free = jnp.repeat(coef < p, n_in)
    eye_a = jnp.eye(P1 * n_in, dtype=M.dtype)
    A_sys = jnp.where(free[:, None] & free[None, :], M, eye_a)
    rhs = jax.lax.dynamic_slice(M, (0, p * n_in), (P1 * n_in, n_in))
    rhs = jnp.where(free[:, None], rhs, 0.0)
    alpha = -jnp.linalg.solve(A_sys, rhs)  # (P1 n_in, n_in), zero beyond block p-1
    alpha_full = alpha + jax.lax.dynamic_update_slice(
        jnp.zeros_like(alpha), jnp.eye(n_in, dtype=alpha.dtype), (p * n_in, 0)
    )
    beta = -jnp.einsum("orc,ci->ori", RinvS, alpha_full)  # (out, P1, in), β_o,r rows

    # Block companion matrix of A(z) = z^p I + Σ_{r<p} α_r z^r (eq. 12) in the form
    # C[j, j+1] = I (j < p-1), C[p-1, c] = -α_c, embedded in the top-left corner of a
    # (p_max n_in)-square matrix whose other rows are zero (eigenvalues exactly 0).
    n = p_max * n_in
    blk = jnp.arange(n) // n_in
    C = jnp.where(
        (blk[:, None] + 1 == blk[None, :]) & (blk[:, None] < p - 1),
        jnp.eye(n, k=n_in, dtype=alpha.dtype),
        0.0,
    )
    # (n_in, n): [-α_0, -α_1, ..., -α_{p_max-1}], row j of block c = row j of α_c.
    last_row = jnp.transpose(alpha[:n].reshape(p_max, n_in, n_in), (1, 0, 2))
    last_row = -last_row.reshape(n_in, n)
    C = jnp.where((blk == p - 1)[:, None], jnp.tile(last_row, (p_max, 1)), C)
    z, vl, vr = jax.lax.linalg.eig(C, compute_left_eigenvectors=True)
    # Right eigenvector x = [v; z v; ...]: v spans the null space of A(z_k);
    # left eigenvector: its block p-1 is the participation factor l with l^T A(z_k) = 0.
    v = vr[:n_in, :]  # (n_in, n)
    l_ = jnp.conj(jax.lax.dynamic_slice(vl, ((p - 1) * n_in, 0), (n_in, n)))
    zr = z[None, :] ** coef[:, None]  # (P1, n)
    psi = jnp.einsum("ori,rk,ik->ok", beta.astype(z.dtype), zr, v)  # (out, n)
    vec = jnp.einsum("ok,ik->koi", psi, l_).reshape(n, -1)
    vec = vec / jnp.maximum(jnp.linalg.norm(vec, axis=1, keepdims=True), 1e-300)
    lam = jnp.log(jnp.where(z == 0, 1.0, z)) / dt
    return z, lam, vec


def _mac(a: Complex[Array, "... c"], b: Complex[Array, "... c"]) -> Float[Array, "..."]:
    """Modal assurance criterion `|a^H b|² / (|a|² |b|²)` (Allemang, 2003)."""
    num = jnp.abs(jnp.sum(jnp.conj(a) * b, axis=-1)) ** 2
    den = jnp.sum(jnp.abs(a) ** 2, axis=-1) * jnp.sum(jnp.abs(b) ** 2, axis=-1)
    return num / jnp.where(den > 0, den, 1.0)


class StabilisationCriteria(eqx.Module):
    """When a pole counts as stable in the stabilisation diagram, and which tracks are
    kept ([`modal_fit`][]).

    **Fields:**

    - `frequency_tol`, `damping_tol`: relative change to the previous order below which a
      pole is stable (default 1 %, 5 %).
    - `mac_tol`: lowest MAC with the previous pole's residue direction (default 0.98).
    - `min_orders`: orders a track must be stable over to be kept (see
      [`select_poles`][]; default there).
    """

    frequency_tol: float = 0.01
    damping_tol: float = 0.05
    mac_tol: float = 0.98
    min_orders: int | None = None


@eqx.filter_jit
def _diagram_arrays(omega, H, W, p_max: int, freq_tol, damp_tol, mac_tol):
    dt = jnp.pi / omega[-1]
    n_in = H.shape[2]
    R, S, T = _normal_matrices(omega, H, W, p_max, dt)
    orders = jnp.arange(1, p_max + 1)
    z, lam, vec = jax.vmap(
        lambda p: _poles_of_order(p, R, S, T, dt, n_in, p_max)
    )(orders)
    wn = jnp.abs(lam)
    zeta = -lam.real / jnp.where(wn > 0, wn, 1.0)
    # Physical poles: not padding, upper half plane, stable, inside the band.
    valid = (
        (jnp.abs(z) > 0)
        & jnp.isfinite(lam)
        & (lam.imag > 0)
        & (lam.real < 0)
        & (wn >= omega[0])
        & (wn <= omega[-1])
    )
    # Compare every pole with the nearest valid pole (in frequency) of the previous order.
    prev_wn, prev_zeta, prev_vec, prev_valid = wn[:-1], zeta[:-1], vec[:-1], valid[:-1]

    def compare(wn_k, zeta_k, vec_k, pwn, pzeta, pvec, pvalid):
        d = jnp.abs(wn_k[:, None] - pwn[None, :]) / wn_k[:, None]
        d = jnp.where(pvalid[None, :], d, jnp.inf)
        j = jnp.argmin(d, axis=1)
        has = jnp.isfinite(jnp.min(d, axis=1))
        df = jnp.min(d, axis=1)
        dz = jnp.abs(zeta_k - pzeta[j]) / jnp.where(zeta_k > 0, zeta_k, 1.0)
        mac = _mac(vec_k, pvec[j])
        return jnp.where(has, j, -1), has & (df <= freq_tol), has & (dz <= damp_tol), (
            has & (mac >= mac_tol)
        )

    prev, sf, sd, sv = jax.vmap(compare)(
        wn[1:], zeta[1:], vec[1:], prev_wn, prev_zeta, prev_vec, prev_valid
    )
    first = jnp.zeros_like(valid[:1])
    prev = jnp.concatenate([jnp.full_like(prev[:1], -1), prev])
    sf, sd, sv = (jnp.concatenate([first, x]) & valid for x in (sf, sd, sv))
    return orders, wn, zeta, vec, valid, prev, sf, sd, sv


def _default_weights(H3: np.ndarray) -> np.ndarray:
    """Heuristic: one scalar weight per output row, `1 / RMS|H_o|`, so every FRF row
    counts alike in the common-denominator fit whatever its amplitude."""
    rms = np.sqrt(np.mean(np.abs(H3) ** 2, axis=(0, 2)))
    rms = np.where(rms > 0, rms, 1.0)
    return np.broadcast_to(1.0 / rms, H3.shape[:2])


def _check_order(n_freq: int, n_out: int, n_in: int, max_order: int, where: str) -> None:
    if not isinstance(max_order, (int, np.integer)) or max_order < 2:
        raise ValueError(f"{where}: max_order must be an integer >= 2; got {max_order!r}.")
    # Real equations 2 F n_out n_in against unknowns (p+1) n_out n_in (numerators) and
    # p n_in² (denominator).
    need = ((max_order + 1) * n_out * n_in + max_order * n_in**2) / (2 * n_out * n_in)
    if n_freq < need:
        raise ValueError(
            f"{where}: {n_freq} frequency points are too few for max_order={max_order} "
            f"with {n_out} output(s) and {n_in} input(s) (need at least {int(np.ceil(need))}). "
            "Lower max_order or give more frequency points (a wider band)."
        )


def stabilisation_diagram(
    omega: ArrayLike,
    H: ArrayLike | None = None,
    *,
    max_order: int = 40,
    band: tuple[float, float] | None = None,
    unit: Literal["rad/s", "Hz"] = "rad/s",
    weights: ArrayLike | None = None,
    frequency_tol: float = 0.01,
    damping_tol: float = 0.05,
    mac_tol: float = 0.98,
) -> StabilisationDiagram:
    """Poles of the pLSCF (PolyMAX) estimator for orders `1..max_order`, with stability flags.

    **Arguments:**

    - `omega`: `(freq,)` strictly increasing frequencies in `unit`, all > 0 inside `band`;
      or a `jaxvs.data.FRFData` (then `H` is omitted; its grid is read in `unit`).
    - `H`: `(freq,)`, `(freq, out)` or `(freq, out, in)` complex FRFs (any quantity; the
      poles do not depend on it).
    - `max_order`: highest polynomial order `p` (each order gives `p * in` poles). An
      order of `2 * n_modes` fits noiseless data; measured data need a margin (heuristic:
      2-4 times that) for the noise and out-of-band modes to be absorbed.
    - `band`: `(low, high)` in `unit`; only these bins are fitted.
    - `unit`: `"rad/s"` or `"Hz"` for `omega` and `band`.
    - `weights`: `(freq,)` or `(freq, out)` weights `W_o(ω)` of the equation error;
      default `1 / RMS|H_o|` per output.
    - `frequency_tol`, `damping_tol`: relative change to the previous order below which a
      pole counts as stable in frequency (1 %) and damping (5 %), as is common in
      PolyMAX charts (Peeters et al. 2004, §3).
    - `mac_tol`: lowest MAC between the residue directions (mode shape ⊗ participation
      factor) of consecutive orders for a stable vector (0.98). With one FRF the vector
      is a scalar and always stable.

    **Returns:**

    A [`StabilisationDiagram`][] (all frequencies in rad/s).
    """
    where = "stabilisation_diagram"
    omega, H = _frfdata_arrays(omega, H, unit, where)
    w, h3, wt, _ = prepare_frf(omega, H, band=band, unit=unit, weights=weights, where=where)
    _check_order(w.shape[0], h3.shape[1], h3.shape[2], max_order, where)
    for name, val in (("frequency_tol", frequency_tol), ("damping_tol", damping_tol)):
        if not val > 0:
            raise ValueError(f"{where}: {name} must be > 0; got {val}.")
    if not 0 < mac_tol <= 1:
        raise ValueError(f"{where}: mac_tol must be in (0, 1]; got {mac_tol}.")
    W = _default_weights(h3) if wt is None else wt
    arrays = _diagram_arrays(
        jnp.asarray(w),
        jnp.asarray(h3),
        jnp.asarray(W),
        int(max_order),
        frequency_tol,
        damping_tol,
        mac_tol,
    )
    rms = np.sqrt(np.mean(np.abs(h3) ** 2, axis=0))
    indicator = np.mean(np.abs(h3) / np.where(rms > 0, rms, 1.0), axis=(1, 2))
    return StabilisationDiagram(
        *arrays,
        omega=jnp.asarray(w),
        indicator=jnp.asarray(indicator),
        frequency_tol=float(frequency_tol),
        damping_tol=float(damping_tol),
        mac_tol=float(mac_tol),
    )


# --------------------------------------------------------------------------------------
# Automatic selection of physical poles
# --------------------------------------------------------------------------------------


class PoleTrack(eqx.Module):
    """A chain of stable poles that persist over consecutive model orders.

    **Fields:** `omega_n` [rad/s] and `zeta` [-]: the medians over the chain (heuristic:
    robust against the odd order that fits noise); `n_orders`: number of orders in the
    chain; `lowest_order`: where it first became stable.
    """

    omega_n: float
    zeta: float
    n_orders: int
    lowest_order: int


def pole_tracks(diagram: StabilisationDiagram) -> list[PoleTrack]:
    """Group the fully stable poles of a diagram into tracks (clusters over orders).

    Each stable pole is linked to the pole of the previous order it was compared with
    (the `previous` index of the diagram); connected chains are tracks. Tracks broken
    by an unstable order are merged when their median frequencies agree within
    `frequency_tol` and their orders do not overlap. Sorted by `n_orders`, longest first.
    """
    stable = np.asarray(diagram.stable)
    prev = np.asarray(diagram.previous)
    wn, zeta = np.asarray(diagram.omega_n), np.asarray(diagram.zeta)
    orders = np.asarray(diagram.orders)
    n_ord, n_pole = stable.shape
    parent = np.arange(n_ord * n_pole)

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for k, i in zip(*np.nonzero(stable)):
        if k > 0 and prev[k, i] >= 0:
            a, b = find(k * n_pole + i), find((k - 1) * n_pole + prev[k, i])
            if a != b:
                parent[a] = b
    groups: dict[int, list[tuple[int, int]]] = {}
    for k, i in zip(*np.nonzero(stable)):
        groups.setdefault(find(k * n_pole + i), []).append((k, i))
    raw = []
    for members in groups.values():
        ks = np.array([m[0] for m in members])
        ii = np.array([m[1] for m in members])
        raw.append([set(ks.tolist()), wn[ks, ii].tolist(), zeta[ks, ii].tolist()])
    # Merge tracks of the same mode broken by one unstable order.
    raw.sort(key=lambda t: np.median(t[1]))
    merged: list[list] = []
    for t in raw:
        if merged:
            m = merged[-1]
            f_m, f_t = np.median(m[1]), np.median(t[1])
            if abs(f_t - f_m) <= diagram.frequency_tol * f_m and not (m[0] & t[0]):
                m[0] |= t[0]
                m[1] += t[1]
                m[2] += t[2]
                continue
        merged.append(t)
    tracks = [
        PoleTrack(
            omega_n=float(np.median(t[1])),
            zeta=float(np.median(t[2])),
            n_orders=len(t[0]),
            lowest_order=int(orders[min(t[0])]),
        )
        for t in merged
    ]
    tracks.sort(key=lambda t: (-t.n_orders, t.omega_n))
    return tracks


def select_poles(
    diagram: StabilisationDiagram,
    *,
    n_modes: int | None = None,
    min_orders: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Pick the physical poles of a stabilisation diagram.

    **Arguments:**

    - `diagram`: from [`stabilisation_diagram`][].
    - `n_modes`: take exactly the `n_modes` longest tracks (the user's override). A
      warning is given when fewer tracks exist.
    - `min_orders`: without `n_modes`, keep every track stable over at least this many
      orders; default (heuristic) a quarter of the orders of the diagram, at least 3.

    **Returns:**

    `(omega_n [rad/s], zeta)` of the selected modes, sorted by frequency.
    """
    tracks = pole_tracks(diagram)
    if not tracks:
        raise ValueError(
            "select_poles: no pole is stable in frequency, damping and vector. Raise "
            "max_order, widen the band, or relax frequency_tol / damping_tol / mac_tol."
        )
    if n_modes is not None:
        if not isinstance(n_modes, (int, np.integer)) or n_modes < 1:
            raise ValueError(f"select_poles: n_modes must be a positive integer; got {n_modes!r}.")
        if n_modes > len(tracks):
            warnings.warn(
                f"select_poles: n_modes={n_modes} requested but only {len(tracks)} stable "
                f"pole track(s) were found; using {len(tracks)}. Raise max_order or relax "
                "the stability tolerances to find more.",
                stacklevel=3,
            )
        chosen = tracks[:n_modes]
    else:
        n_ord = int(np.asarray(diagram.orders).shape[0])
        threshold = max(3, n_ord // 4) if min_orders is None else int(min_orders)
        chosen = [t for t in tracks if t.n_orders >= threshold]
        if not chosen:
            raise ValueError(
                f"select_poles: no pole track is stable over {threshold} orders (longest: "
                f"{tracks[0].n_orders}). Raise max_order, lower min_orders, or give n_modes."
            )
    chosen.sort(key=lambda t: t.omega_n)
    return np.array([t.omega_n for t in chosen]), np.array([t.zeta for t in chosen])
