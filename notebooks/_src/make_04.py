"""Generate and execute notebooks/04_axis_drives_emps.ipynb (run from the repository root)."""

import nbformat as nbf
from _build import build

md, code = nbf.v4.new_markdown_cell, nbf.v4.new_code_cell
cells = [
    md(
        "# 04 — CNC axis drives and the EMPS benchmark\n\n"
        "The drive study (Pislaru 2001): cascade-controlled feed drives built from composable "
        "`equinox` modules — P position loop, PI velocity loop, current loop or DC motor, "
        "rigid / two-mass / distributed ball screw, friction laws, backlash, saturation, "
        "encoder quantisation — simulated through diffrax, batched over variants, and "
        "calibrated in closed loop with the known controller. Then modal identification "
        "(generalised eigenvalues, Morlet wavelet damping), the two-axis ball-bar test, and "
        "the real Electro-Mechanical Positioning System (EMPS) of Janot, Gautier & Brunot "
        "(2019)."
    ),
    code(
        "import json\n"
        "import jax\n"
        "jax.config.update('jax_enable_x64', True)\n"
        "import jax.numpy as jnp\n"
        "import numpy as np\n"
        "import matplotlib.pyplot as plt\n"
        "from IPython.display import Markdown, display\n"
        "import jaxvs\n"
        "from jaxvs.models import (AsymmetricFriction, BallScrew, CoulombViscousFriction, "
        "DriveAxis,\n"
        "    ForceGain, GeometricErrors, PositionLoop, RigidAxis, StribeckFriction, "
        "VelocityLoop,\n"
        "    ViscousFriction, XYTable, ballbar_test)\n"
        "from jaxvs.data import load_emps, trapezoid\n"
        "from jaxvs.studies import calibrate_drive\n"
        "from jaxvs.signal import cwt_morlet, cwt_ridge, cwt_damping\n"
        "from jaxvs.plotting import ballbar_plot, bode_plot, scalogram_plot\n"
        "%matplotlib inline\n"
        "DATA = '../../shared/data/EMPS/'"
    ),
    md(
        "## Friction laws\n\n"
        "Every law replaces `sign(v)` by `tanh(v / velocity_scale)`; the sharpness "
        "`velocity_scale` [m/s] is the speed where the smooth sign reaches 0.76."
    ),
    code(
        "v = jnp.linspace(-0.05, 0.05, 801)\n"
        "laws = {\n"
        "    'Coulomb + viscous (EMPS IDIM)': CoulombViscousFriction(20.39, 203.5, -3.16),\n"
        "    'asymmetric (EMPS eq. 12)': AsymmetricFriction(20.14, 166.7, 20.63, 240.4),\n"
        "    'Stribeck (Fs = 28 N, vs = 5 mm/s)': StribeckFriction(20.0, 28.0, 5e-3, 200.0),\n"
        "}\n"
        "fig, ax = plt.subplots(figsize=(6, 3.2))\n"
        "for name, law in laws.items():\n"
        "    ax.plot(1e3 * v, law(v), label=name)\n"
        "ax.set_xlabel('velocity [mm/s]'); ax.set_ylabel('friction force [N]'); "
        "ax.legend(fontsize=8); ax.grid(alpha=0.3)"
    ),
    md(
        "## Ball screw: lumped against distributed, natural frequencies by (K, M)\n\n"
        "`BallScrew` turns geometry into linear-equivalent masses and springs "
        "(torsion reflected through the lead). The lumped model is two masses and one "
        "spring; the hybrid model splits the shaft into torsional finite elements. "
        "Natural frequencies come from the generalised eigenproblem `K φ = ω² M φ`."
    ),
    code(
        "screw = BallScrew(length=0.8, diameter=0.025, lead=0.01, nut_stiffness=2e8, "
        "bearing_stiffness=4e8)\n"
        "lumped = screw.lumped_axis(1.5e-4, 150.0, ViscousFriction(300.0), damping=2e-4)\n"
        "dist = screw.distributed_axis(1.5e-4, 150.0, ViscousFriction(300.0), n_segments=12, "
        "damping=2e-4)\n"
        "print('lumped modes [Hz]     :', np.round(np.asarray(lumped.normal_modes().omega_n)"
        "[1:] / 2 / np.pi, 1))\n"
        "print('distributed modes [Hz]:', np.round(np.asarray(dist.normal_modes().omega_n)"
        "[1:5] / 2 / np.pi, 1))\n"
        "loops = {name: DriveAxis(m, PositionLoop(30.0), VelocityLoop(5e4, 20.0))\n"
        "         for name, m in (('lumped', lumped), ('distributed', dist))}\n"
        "f = np.logspace(-0.5, 3.2, 400)\n"
        "H = [np.asarray(d.frequency_response(2 * np.pi * f)) for d in loops.values()]\n"
        "H += [np.asarray(d.frequency_response(2 * np.pi * f, output='force')) / 1e6 "
        "for d in loops.values()]\n"
        "bode_plot(f, H, labels=['q/r lumped', 'q/r distributed', 'force/r lumped [MN/m]', "
        "'force/r distributed [MN/m]'], styles=['-', '--', '-', '--'], "
        "title='closed position loop, linearised');"
    ),
    md(
        "## A digital drive following a trapezoidal move\n\n"
        "1 kHz controller with zero-order hold, backlash in the nut (±5 µm), Coulomb friction, "
        "an encoder of 1 µm; the loop's stability is checked from its one-sample map before "
        "simulating."
    ),
    code(
        "mech = screw.lumped_axis(1.5e-4, 150.0, CoulombViscousFriction(30.0, 300.0, "
        "velocity_scale=1e-3), backlash=5e-6)\n"
        "drive = DriveAxis(mech, PositionLoop(30.0), VelocityLoop(5e4, 20.0, limit=2e4), "
        "sample_time=1e-3,\n"
        "                  encoder_resolution=1e-6, n_substeps=8)\n"
        "print('largest |z| of the sampled loop:', np.max(np.abs(drive.sampled_poles()[1:])))\n"
        "move = trapezoid(0.1, 0.1, 1.0, 1e-3, dwell=0.3)\n"
        "res = drive.simulate(jnp.asarray(move.position), 1e-3)\n"
        "fig, ax = plt.subplots(2, 1, sharex=True, figsize=(7, 4))\n"
        "ax[0].plot(move.t, 1e3 * move.velocity, label='reference')\n"
        "ax[0].plot(move.t, 1e3 * np.asarray(res.velocity), '--', label='table')\n"
        "ax[0].set_ylabel('velocity [mm/s]'); ax[0].legend()\n"
        "ax[1].plot(move.t, 1e6 * (move.position - np.asarray(res.position)))\n"
        "ax[1].set_ylabel('following error [µm]'); ax[1].set_xlabel('time [s]');"
    ),
    md(
        "## Damping from a free decay: Morlet wavelet against the truth\n\n"
        "Along the ridge of a mode, `ln|W|` decays with slope `−ζω_n` (Staszewski 1997)."
    ),
    code(
        "dt = 2e-4\n"
        "t = dt * np.arange(8192)\n"
        "modes = [(45.0, 0.02, 1.0), (160.0, 0.035, 0.4)]\n"
        "x = sum(a * np.exp(-z * 2 * np.pi * fn * t) * np.sin(2 * np.pi * fn * "
        "np.sqrt(1 - z**2) * t) for fn, z, a in modes)\n"
        "x = x + 0.005 * np.random.default_rng(0).standard_normal(t.size)\n"
        "freqs = np.geomspace(20, 300, 120)\n"
        "W = cwt_morlet(x, dt, freqs, omega0=10.0)\n"
        "scalogram_plot(t, freqs, W, title='Morlet CWT of a two-mode free decay')\n"
        "# well-separated modes: the default omega0 = 6 gives the best time resolution\n"
        "for fn, z, _ in modes:\n"
        "    est = cwt_damping(x, dt, (0.8 * fn, 1.2 * fn))\n"
        "    print(f'{fn:5.0f} Hz: ζ true {z:.4f}, CWT {float(est.zeta):.4f} "
        "({100 * abs(float(est.zeta) - z) / z:.1f} %)')"
    ),
    md(
        "## Ball-bar test\n\n"
        "Two drives with PI velocity loops interpolate a 50 mm circle at 3 m/min. Friction "
        "gives reversal spikes at the quadrants, a 5 % lower position gain on Y a "
        "servo-mismatch ellipse, an out-of-squareness of 1 mrad a squareness ellipse (both at "
        "±45°; only the mismatch ellipse flips with the direction of travel)."
    ),
    code(
        "def axis(kp, Fc=20.0):\n"
        "    return DriveAxis(RigidAxis(10.0, CoulombViscousFriction(Fc, 50.0, "
        "velocity_scale=1e-3)),\n"
        "                     PositionLoop(kp), VelocityLoop(2000.0, 100.0), sample_time=1e-3, "
        "n_substeps=8)\n"
        "R, F = 0.05, 0.05\n"
        "cases = {\n"
        "    'friction only': XYTable(axis(40.0), axis(40.0)),\n"
        "    'kp_y = 38 1/s (mismatch)': XYTable(axis(40.0), axis(38.0)),\n"
        "    'squareness 1 mrad': XYTable(axis(40.0), axis(40.0), "
        "GeometricErrors(squareness=1e-3)),\n"
        "}\n"
        "results = [ballbar_test(tab, R, F, 1e-3) for tab in cases.values()]\n"
        "ballbar_plot(results, labels=list(cases), title='simulated ball-bar test');"
    ),
    md(
        "## EMPS: the closed loop with the published controller\n\n"
        "The description's controller (`vir = kp·kv·(qr − q) − kv·q̇`, velocity "
        "`(q_k − q_{k−2})/(2dt)`, ±10 V, `force = gτ·vir`, 1 kHz) and the published IDIM-LS "
        "parameters, simulated from the measured reference."
    ),
    code(
        "est = load_emps(DATA + 'DATA_EMPS.mat')\n"
        "md_ = est.metadata\n"
        "def emps_drive(mech):\n"
        "    return DriveAxis(mech, PositionLoop(md_['kp']), VelocityLoop(md_['kv'], "
        "limit=10.0),\n"
        "                     ForceGain(md_['gtau']), sample_time=1e-3, "
        "velocity_estimate='central')\n"
        "idim = emps_drive(RigidAxis(95.1089, CoulombViscousFriction(20.3935, 203.5034, "
        "-3.1648)))\n"
        "sim = idim.simulate(jnp.asarray(est['r']), est.dt, q0=float(est['q'][0]))\n"
        "rel = lambda a, b: 100 * np.linalg.norm(np.asarray(a) - np.asarray(b)) / "
        "np.linalg.norm(np.asarray(b))\n"
        "print(f\"position error {rel(sim.position, est['q']):.4f} %  (published 0.0138 %)\")\n"
        "print(f\"force error    {rel(sim.force, est['u']):.2f} %    (published 5.85 %)\")\n"
        "fig, ax = plt.subplots(figsize=(8, 3))\n"
        "ax.plot(est.t, est['u'], lw=0.6, label='measured force')\n"
        "ax.plot(est.t, sim.force, lw=0.6, label='simulated force')\n"
        "ax.set_xlim(4, 9); ax.set_xlabel('time [s]'); ax.set_ylabel('force [N]'); ax.legend();"
    ),
    md(
        "### Closed-loop calibration with the known controller (input error, DIDIM)\n\n"
        "Only the plant is free; every iterate is a full closed-loop simulation, "
        "differentiated in forward mode for Levenberg–Marquardt."
    ),
    code(
        "guess = emps_drive(RigidAxis(90.0, CoulombViscousFriction(15.0, 180.0, 0.0)))\n"
        "didim = calibrate_drive(guess, est, criterion='input')\n"
        "print(didim.summary())"
    ),
    md(
        "### Beating the published validation error\n\n"
        "`benchmarks/emps.py` runs the same calibration for richer friction models and "
        "validates every model on `DATA_EMPS_PULSES.mat` (not used for calibration). Its "
        "measured table:"
    ),
    code(
        "res = json.load(open('../benchmarks/results/emps.json'))['closed_loop']\n"
        "rows = ['| model | force error, estimation | force error, validation (simulated) | "
        "validation (inverse model) |', '|---|---:|---:|---:|',\n"
        "        '| published (IDIM-LS, §3.4–3.5) | 5.85 % | 8.94 % | 5.98 % |']\n"
        "for name, e in res['models'].items():\n"
        "    s = e['simulation']\n"
        "    rows.append(f\"| {name} | {s['estimation']['force']:.2f} % | "
        "{s['validation']['force']:.2f} % | {e['inverse_model_force']['validation']:.2f} % |\")\n"
        "display(Markdown('\\n'.join(rows)))"
    ),
    md(
        "## EMPS on the official benchmark split\n\n"
        "The identification community's task on the same data (`jaxvs.studies.benchmarks.EMPS`): "
        "from the motor force `u = gτ·vir` simulate the position `qm` free-run; train on "
        "`DATA_EMPS.mat`, test on `DATA_EMPS_PULSES.mat`; the first 20 samples of a record "
        "may initialise the state; score the RMSE of the position after them. A model is "
        "anything callable as `model(u, y_init) -> y`; `OpenLoopAxis` is the rigid axis of "
        "the description with `jaxvs.models` friction laws, calibrated here by multiple "
        "shooting on the training file (a short run: 20 Levenberg–Marquardt steps)."
    ),
    code(
        "from jaxvs.studies.benchmarks import EMPS, OpenLoopAxis, fit_multiple_shooting, "
        "score_predictor\n"
        "task_data = EMPS.load(DATA)\n"
        "u_tr, y_tr = EMPS.arrays(task_data.train[0])\n"
        "guess = OpenLoopAxis(RigidAxis(95.0, CoulombViscousFriction(20.0, 200.0, 0.0)), "
        "sample_time=EMPS.sample_time)\n"
        "shot = fit_multiple_shooting(guess, u_tr, y_tr, output_scale=1e-3, "
        "state_scale=(1e-3, 2e-3), max_steps=20)\n"
        "published = OpenLoopAxis(RigidAxis(95.1089, CoulombViscousFriction(20.3935, 203.5034, "
        "-3.1648)), sample_time=EMPS.sample_time)\n"
        "u_te, y_te = EMPS.arrays(task_data.test[0])\n"
        "fig, ax = plt.subplots(figsize=(8, 3))\n"
        "for name, model in (('published IDIM-LS parameters', published),\n"
        "                    (f'multiple shooting ({int(shot.num_steps)} LM steps)', shot.model)):\n"
        "    s = score_predictor(EMPS, model, task_data)\n"
        "    print(f\"{name}: train {s.mean('rmse', 'train'):.2f} mm, test {s.mean('rmse'):.2f} mm\")\n"
        "    ax.plot(task_data.test[0].t, 1e3 * (np.asarray(model(u_te, y_te[:EMPS.init_window])) "
        "- y_te)[:, 0], lw=0.8, label=name)\n"
        "ax.set_xlabel('time [s]'); ax.set_ylabel('free-run position error [mm]'); "
        "ax.set_title('test file DATA_EMPS_PULSES.mat'); ax.legend(fontsize=8); ax.grid(alpha=0.3);"
    ),
    md(
        "The full comparison — several friction structures, structure selection on held-out "
        "training data, the published black-box networks — is `benchmarks/emps_official.py`; "
        "its measured report:"
    ),
    code(
        "report = open('../benchmarks/results/emps_official.md').read()\n"
        "display(Markdown(report.split('\\n', 1)[1]))  # without its title"
    ),
]
build(cells, "04_axis_drives_emps.ipynb")
