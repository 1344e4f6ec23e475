"""The three-axis Cartesian machine: the kinematic chain against exact homogeneous matrices,
each test against its closed form on single-error machines, calibration of the 21
components (noise-free recovery, interval coverage), identifiability of test plans, and
bad input."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.polynomial import legendre as npleg
from scipy.spatial.transform import Rotation

from jaxvs.calibration import RESULTS, EquationError, calibrate
from jaxvs.models import (
    COMPONENTS,
    AngularLine,
    BallbarCircle,
    CartesianMachine,
    DiagonalLine,
    DriveAxis,
    LaserLine,
    MachineErrors,
    PositionLoop,
    RigidAxis,
    StraightnessLine,
    VelocityLoop,
    ViscousFriction,
)
from jaxvs.studies.machine import (
    ballbar_plan,
    calibrate_machine,
    compensated_error,
    complete_plan,
    diagonal_plan,
    identifiability,
    machine_residual,
    parameter_names,
    parameters,
    plan_jacobian,
    suggest_test,
)

TRAVEL = ((0.0, 0.5), (0.0, 0.4), (0.0, 0.4))
TOOL = (0.0, 0.0, -0.1)


def _drive():
    return DriveAxis(RigidAxis(100.0, ViscousFriction(200.0)), PositionLoop(30.0),
                     VelocityLoop(1e4))


def _machine(errors, **kw):
    kw.setdefault("tool_offset", TOOL)
    return CartesianMachine(_drive(), _drive(), _drive(), errors, **kw)


def _random_errors(rng, degree=3, scale=1.0):
    n = degree
    return MachineErrors(
        TRAVEL, n,
        positioning=scale * 4e-6 * rng.normal(size=(3, n)),
        straightness=scale * 3e-6 * rng.normal(size=(6, n - 1)),
        angular=scale * 1e-5 * rng.normal(size=(9, n)),
        squareness=scale * 1e-5 * rng.normal(size=3),
    )


def _one(name, coef, degree=2):
    """A machine whose only error is `name` with Legendre coefficients `coef` (P1, P2 ...)
    or the angle `coef` of a squareness."""
    kw = {}
    n = degree
    if name in COMPONENTS[18:]:
        sq = np.zeros(3)
        sq[COMPONENTS[18:].index(name)] = coef
        kw["squareness"] = sq
    else:
        for field, names, width in (("positioning", COMPONENTS[:3], n),
                                    ("straightness", COMPONENTS[3:9], n - 1),
                                    ("angular", COMPONENTS[9:18], n)):
            if name in names:
                c = np.zeros((len(names), width))
                c[names.index(name), : len(coef)] = coef
                kw[field] = c
    return _machine(MachineErrors(TRAVEL, n, **kw))


# ----------------------------------------------------------------------------- the chain


def _numpy_chain(errors: MachineErrors, chain, q, t):
    """Independent oracle: the product of exact 4×4 homogeneous matrices (rotation
    matrices from the rotation vector, no small-angle shortcut), the components from
    numpy's Legendre series and the axis directions normalised."""
    pos, strt = np.asarray(errors.positioning), np.asarray(errors.straightness)
    ang, sq = np.asarray(errors.angular), np.asarray(errors.squareness)
    dirs = np.array([[1, 0, 0], [-sq[0], 1, 0], [sq[1], -sq[2], 1]], float)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    H = np.eye(4)
    for j in chain:
        lo, hi = TRAVEL[j]
        u = 2 * (q[j] - lo) / (hi - lo) - 1
        val = lambda c, first: npleg.legval(u, np.r_[np.zeros(first), c])  # noqa: E731
        d = np.zeros(3)
        d[j] = val(pos[j], 1)
        others = [k for k in range(3) if k != j]
        d[others[0]], d[others[1]] = val(strt[2 * j], 2), val(strt[2 * j + 1], 2)
        eps = np.array([val(ang[3 * j + k], 1) for k in range(3)])
        Hj = np.eye(4)
        Hj[:3, :3] = Rotation.from_rotvec(eps).as_matrix()
        Hj[:3, 3] = q[j] * dirs[j] + d
        H = H @ Hj
    return (H @ np.r_[t, 1.0])[:3]


@pytest.mark.parametrize("structure", ["WXYFZT", "WYFXZT"])
def test_chain_matches_exact_homogeneous_matrices_to_second_order(structure):
    rng = np.random.default_rng(1)
    q = np.array([0.37, 0.11, 0.29])
    t = np.array([0.02, -0.03, -0.15])
    gaps = []
    for scale in (10.0, 5.0):
        errs = _random_errors(np.random.default_rng(2), scale=scale)
        m = _machine(errs, structure=structure, tool_offset=t)
        got = np.asarray(m.tool_point(jnp.asarray(q)))
        want = _numpy_chain(errs, m.chain, q, t)
        gaps.append(np.max(np.abs(got - want)))
    # the chain linearises only the rotations: the gap is O(ε² L), ε ~ 1e-4 rad here,
    # L ~ 0.5 m, and halving every error quarters it (second-order agreement)
    assert gaps[0] < 5 * (1e-4) ** 2
    assert gaps[1] / gaps[0] == pytest.approx(0.25, abs=0.03)
    del rng


def test_stacking_order_sets_the_abbe_arms():
    # yaw of Y (ECY): in WXYFZT only the tool offset follows Y (no lateral arm), in WYFXZT
    # the X axis does: the tool moves in Y by ECY·x
    c = 2e-5  # ECY = c·P1(u)
    q = jnp.array([0.4, 0.3, 0.2])
    u = 2 * 0.3 / 0.4 - 1
    a = _one("ECY", [c]).volumetric_error(*q)
    m2 = _one("ECY", [c])
    m2 = CartesianMachine(m2.x_axis, m2.y_axis, m2.z_axis, m2.errors, structure="WYFXZT",
                          tool_offset=TOOL)
    b = m2.volumetric_error(*q)
    np.testing.assert_allclose(a, 0.0, atol=1e-18)  # arm (0, 0, z + t_z) ∥ rotation axis
    np.testing.assert_allclose(b, [0.0, c * u * 0.4, 0.0], rtol=1e-9, atol=1e-18)


def test_volumetric_error_over_a_grid_in_one_call():
    m = _machine(_random_errors(np.random.default_rng(3)))
    g = [np.linspace(lo, hi, 7) for lo, hi in TRAVEL]
    X, Y, Z = np.meshgrid(*g, indexing="ij")
    E = m.volumetric_error(X, Y, Z)
    assert E.shape == (7, 7, 7, 3)
    i, j, k = 2, 5, 1
    q = jnp.array([g[0][i], g[1][j], g[2][k]])
    np.testing.assert_allclose(E[i, j, k], m.tool_point(q) - q - m.tool_offset, rtol=1e-12)


# ----------------------------------------------------------------------------- closed forms


def test_laser_line_reads_the_abbe_error_of_a_yaw():
    # a pure yaw ECX(x) = c·P1(u): on a laser X line at y0 the tool is displaced by −ECX·y0
    # along X (Abbé error = arm × angle; Bryan 1979, Precision Engineering 1(3))
    c, y0 = 3e-5, 0.3
    m = _one("ECX", [c])
    test = LaserLine("x", (0.0, y0, 0.2), n=6, bidirectional=False)
    x = np.linspace(0.0, 0.5, 6)
    ecx = c * (2 * x / 0.5 - 1)
    np.testing.assert_allclose(test.predict(m)[0], -y0 * (ecx - ecx[0]), rtol=1e-12, atol=1e-18)


def test_ballbar_reads_the_squareness_ellipse_at_45_degrees():
    # EC0Y = α: the Y line leans by −α towards X, x_actual = x − α·y; the radius deviation
    # is −α R sin θ cos θ = −(α R / 2) sin 2θ: an ellipse with its axes at ±45° (ISO 230-4)
    alpha, R = 2e-5, 0.15
    m = _one("EC0Y", alpha)
    test = BallbarCircle("xy", (0.25, 0.2, 0.2), R, n=36)
    want = -(alpha * R / 2) * np.sin(2 * test.theta)
    # second order in α: α² R ~ 6e-11 m
    np.testing.assert_allclose(test.predict(m), want, atol=2 * alpha**2 * R)
    got = np.asarray(test.predict(m))
    assert np.argmin(got) == 36 // 8  # minimum at 45°


def test_diagonal_reads_the_length_change_of_a_scale_error():
    # the same positioning scale k on X, Y and Z: every length grows by k, the diagonal
    # reads k · |q_i − q_0| (ISO 230-6)
    k = 2e-5
    errs = MachineErrors(
        TRAVEL, 2,
        positioning=np.array([[k * (hi - lo) / 2, 0.0] for lo, hi in TRAVEL]),
    )
    m = _machine(errs)
    for signs in ((1, 1, 1), (-1, 1, 1)):
        test = DiagonalLine(signs, n=5)
        q = test.points(m)[0][:5]
        L = np.linalg.norm(np.asarray(q - q[0]), axis=1)
        np.testing.assert_allclose(test.predict(m), np.stack([k * L, k * L]), atol=1e-15)


def test_reversal_shows_in_the_laser_reverse_run():
    m = _machine(MachineErrors(TRAVEL, 2), reversal=(4e-6, 0.0, 0.0))
    y = LaserLine("x", (0.0, 0.2, 0.2), n=5).predict(m)
    # forward run at the zero, the reverse run shifted by −B (ISO 230-2 reversal value)
    # rounding of P − q at positions of 0.5 m: 1e-15 m
    np.testing.assert_allclose(y, [[0.0] * 5, [-4e-6] * 5], atol=1e-15)


def test_straightness_and_angular_read_their_component():
    m = _one("EYX", [2e-6])  # EYX = 2e-6 P2(u): a bow (straightness starts at P2)
    x = np.linspace(0.0, 0.5, 9)
    bow = 2e-6 * npleg.legval(2 * x / 0.5 - 1, [0, 0, 1])
    want = bow - np.polyval(np.polyfit(x, bow, 1), x)
    got = StraightnessLine("x", "y", (0.0, 0.2, 0.2), n=9).predict(m)
    np.testing.assert_allclose(got, want, atol=1e-15)
    m = _one("EBX", [1e-5, -4e-6])
    ebx = npleg.legval(2 * x / 0.5 - 1, [0, 1e-5, -4e-6])
    got = AngularLine("x", "y", (0.0, 0.2, 0.2), n=9).predict(m)
    np.testing.assert_allclose(got, ebx - ebx[0], atol=1e-18)


# ----------------------------------------------------------------------------- calibration


def test_complete_plan_recovers_all_21_noise_free():
    truth = _machine(_random_errors(np.random.default_rng(4), degree=2),
                     reversal=(3e-6, -2e-6, 1e-6))
    nominal = _machine(MachineErrors(TRAVEL, 2))
    plan = complete_plan(nominal, n=5)
    assert len(plan) >= 30
    out = calibrate_machine(nominal, plan, [t.predict(truth) for t in plan])
    # noise-free readings: the truth is the optimum, to rounding of the normal equations
    np.testing.assert_allclose(parameters(out.machine), parameters(truth), rtol=1e-9,
                               atol=1e-14)
    before, after = compensated_error(truth, out.machine, jnp.asarray([[0.1, 0.3, 0.2]]))
    # one-step compensation leaves the second-order term ∇E · E, |∇E| ~ 1e-4 here
    assert float(jnp.max(jnp.abs(after))) < 1e-4 * float(jnp.max(jnp.abs(before)))


@pytest.mark.slow
def test_intervals_cover_the_truth_at_the_nominal_rate():
    """Monte Carlo: 240 noise realisations calibrated in one vmapped call; the 95 %
    intervals of every parameter cover the truth in 95 % of the runs."""
    truth = _machine(_random_errors(np.random.default_rng(5), degree=2),
                     reversal=(3e-6, -2e-6, 1e-6))
    nominal = _machine(MachineErrors(TRAVEL, 2))
    plan = complete_plan(nominal, n=4)
    clean = [t.predict(truth) for t in plan]
    runs = 240

    def one(key):
        keys = jax.random.split(key, len(plan))
        ys = [(y + t.sigma * jax.random.normal(k, y.shape))[None]
              for t, y, k in zip(plan, clean, keys)]
        res = calibrate(nominal, {"tests": plan, "readings": ys, "prior": None},
                        EquationError(machine_residual),
                        free=lambda m: (m.errors.positioning, m.errors.straightness,
                                        m.errors.angular, m.errors.squareness, m.reversal),
                        throw=False)
        return res.confidence_intervals, res.result

    ci, result = eqx.filter_jit(jax.vmap(one))(jax.random.split(jax.random.key(0), runs))
    assert bool(jnp.all(result == RESULTS.successful))
    theta = np.asarray(parameters(truth))
    cover = np.mean((np.asarray(ci[..., 0]) <= theta) & (theta <= np.asarray(ci[..., 1])))
    # 240 runs × 33 correlated parameters: the coverage of 95 % intervals lies within
    # ±2.5 % of nominal (binomial std over 240 runs alone is 1.4 %)
    assert 0.925 <= cover <= 0.975, cover


def test_diagonals_cannot_separate_the_components():
    nominal = _machine(MachineErrors(TRAVEL, 3))
    rep = identifiability(nominal, diagonal_plan(nominal, n=9))
    n = 3
    p = len(parameter_names(nominal))
    # independent bound: each diagonal's readings are one polynomial in the diagonal's
    # coordinate of degree <= n + 1 (components of degree n, times Abbé arms linear in
    # it) with its zero fixed, and the reverse run adds at most the reversal values: the
    # four diagonals see at most 4 (n + 1) + 3 directions (Chapman, "Limitations of laser
    # diagonal measurements", Precision Engineering 27, 2003)
    assert rep.content["rank"] <= 4 * (n + 1) + 3
    assert len(rep.content["unidentifiable"]) >= p - (4 * (n + 1) + 3)
    assert set(rep.unidentified_components) >= set(COMPONENTS[:18])
    # the roll of Z moves a tool on the spindle axis nowhere: its columns are zero and it
    # is reported as not identified
    J = np.asarray(plan_jacobian(nominal, diagonal_plan(nominal, n=9)))
    ecz = [i for i, n in enumerate(parameter_names(nominal)) if n.startswith("ECZ")]
    assert np.max(np.abs(J[:, ecz])) <= 1e-9 * np.max(np.abs(J))
    assert "ECZ" in rep.unidentified_components
    md = rep.to_markdown()
    assert "not identifiable" in md and "ECZ" in md


def test_ballbars_alone_cannot_give_the_positioning_scale():
    nominal = _machine(MachineErrors(TRAVEL, 2))
    rep = identifiability(nominal, ballbar_plan(nominal))
    # the same scale on every axis only changes the mean radius, which a ball bar does
    # not know: EXX[P1], EYY[P1], EZZ[P1] in one null combination
    assert any({"EXX[P1]", "EYY[P1]", "EZZ[P1]"} <= set(c["combination"])
               for c in rep.content["unidentifiable"])


def test_suggestion_ranks_a_test_that_sees_what_the_plan_misses():
    nominal = _machine(MachineErrors(TRAVEL, 2))
    plan = ballbar_plan(nominal)
    cands = [AngularLine("x", "y", (0.0, 0.2, 0.2), n=5),
             LaserLine("x", (0.0, 0.2, 0.2), n=5),
             BallbarCircle("xy", (0.25, 0.2, 0.2), 0.1)]
    rows = suggest_test(nominal, plan, cands, grid=3)
    assert rows[0]["test"] == "(current plan)"
    # a repeated ball bar adds least; a laser line along X (the scale the ball bars miss)
    # and an angular line (Abbé terms) both lower the worst volumetric uncertainty
    assert rows[-1]["index"] == 2
    assert all(r["worst_std"] < rows[0]["worst_std"] for r in rows[1:3])


# ----------------------------------------------------------------------------- bad input


def test_bad_input_is_refused_with_a_clear_message():
    with pytest.raises(ValueError, match="outside the X travel.*mm"):
        MachineErrors.from_tables(TRAVEL, {"EXX": ([0.0, 100.0, 200.0, 500.0], [0, 1e-6, 0, 0])},
                                  degree=2)
    with pytest.raises(ValueError, match="travel is probably in mm"):
        MachineErrors(((0, 500), (0, 400), (0, 400)))
    with pytest.raises(ValueError, match="probably in mm or µm"):
        MachineErrors(TRAVEL, 2, positioning=np.full((3, 2), 5.0))
    with pytest.raises(ValueError, match="unknown error component 'EXQ'"):
        MachineErrors.from_tables(TRAVEL, {"EXQ": ([0.0, 0.5], [0.0, 0.0])})
    with pytest.raises(ValueError, match="tool_offset .* probably in mm"):
        _machine(MachineErrors(TRAVEL, 2), tool_offset=(0, 0, -150.0))
    with pytest.raises(ValueError, match="structure must read"):
        _machine(MachineErrors(TRAVEL, 2), structure="XYZ")
    with pytest.raises(ValueError, match="roll of the vertical Z"):
        AngularLine("z", "z")
    with pytest.raises(ValueError, match="probably in mm"):
        BallbarCircle("xy", (250.0, 200.0, 200.0), 100.0)
    m = _machine(MachineErrors(TRAVEL, 2))
    with pytest.raises(ValueError, match="outside the travel"):
        m.volumetric_error(250.0, 0.2, 0.2)
    with pytest.raises(ValueError, match="outside the travel"):
        BallbarCircle("xy", (0.25, 0.2, 0.2), 0.3).check(m)
    plan = diagonal_plan(m, n=5)
    with pytest.raises(ValueError, match="cannot separate .*ECZ"):
        calibrate_machine(m, plan, [t.predict(m) for t in plan])
    with pytest.raises(ValueError, match="readings of 'diagonal"):
        calibrate_machine(m, plan, [np.zeros(3)] * 4, prior=(1e-5, 1e-5))


# ----------------------------------------------------------------------------- files


def test_laser_and_ballbar_csv(tmp_path):
    from jaxvs.data import load_ballbar_csv, load_laser_csv

    rows = ["target [mm], deviation [um], run, direction"]
    for run in (1, 2):
        for d, sign in (("+", 1), ("-", -1)):
            for x in (0, 250, 500):
                rows.append(f"{x}, {x / 100 + sign}, {run}, {d}")
    f = tmp_path / "x.csv"
    f.write_text("\n".join(rows) + "\n")
    runs = load_laser_csv(f)
    np.testing.assert_allclose(runs.targets, [0.0, 0.25, 0.5])  # mm -> m
    assert runs.deviations.shape == (2, 2, 3)
    np.testing.assert_allclose(runs.reversal, 2e-6)  # µm -> m
    f.write_text("\n".join(rows[:-1]) + "\n")
    with pytest.raises(ValueError, match="no reverse reading at target 0.5 m"):
        load_laser_csv(f)

    b = tmp_path / "bb.csv"
    b.write_text("# radius: 100 mm\nangle [deg], deviation [um]\n0, 0.5\n90, -0.5\n180, 0.2\n")
    data = load_ballbar_csv(b, radius=0.1)
    np.testing.assert_allclose(data.angle, [0.0, np.pi / 2, np.pi])
    np.testing.assert_allclose(data.deviation, [5e-7, -5e-7, 2e-7])
    with pytest.raises(ValueError, match="100 mm bar but the test expects 150 mm"):
        load_ballbar_csv(b, radius=0.15)
    b.write_text("angle [deg], deviation\n0, 0.5\n90, -0.5\n")
    with pytest.raises(ValueError, match=r"deviation \[um\]"):
        load_ballbar_csv(b)
