"""Generate and execute notebooks/05_sim_to_real_gap.ipynb (run from the repository root)."""

import nbformat as nbf
from _build import build

md, code = nbf.v4.new_markdown_cell, nbf.v4.new_code_cell
cells = [
    md(
        "# 05 — Sim-to-real gap diagnosis\n\n"
        "A calibrated model still disagrees with the machine. `jaxvs.diagnose` answers three "
        "questions, on data the calibration never saw:\n\n"
        "1. **Where** is the gap? A gap map over time windows, frequency bands and operating "
        "points (velocity reversals, speed, position, direction, recorded signals such as the "
        "EMPS force pulses), with circular-shift permutation p-values that respect the "
        "residual's autocorrelation and Benjamini–Hochberg control of false discoveries.\n"
        "2. **Which** unmodelled effect causes it? Every candidate of the family's library "
        "(the effect names of the Contracts page) is a differentiable augmentation of the nominal model that equals it "
        "at zero size; each is added and the whole model is recalibrated by "
        "Levenberg–Marquardt. A candidate is accepted only when its best fit is physically "
        "admissible (a causal delay, a gap above the encoder step, a lightly damped mode, "
        "non-negative friction), its held-out gap reduction has a moving-block bootstrap "
        "interval excluding zero, and that reduction beats the **null**: what the same "
        "candidate gains on effect-free records simulated from the calibrated nominal model "
        "through the recorded set-up (closed loop with the identified controller, the "
        "record's encoder step, noise and preprocessing). Among those that pass, the largest "
        "held-out reduction wins; effects are added greedily until none passes.\n"
        "3. **How far** does the gap shrink, and what is left against the noise floor?\n\n"
        "The verdict comes first, in one line: `adequate` (nothing needed, the remaining "
        "held-out gap within the null), `explained` (named effects close the gap), "
        "`partly_explained` (named effects, something else remains) or `unexplained` "
        "(the record shows an effect that is in no library; where it lies is said).\n\n"
        "First on the real EMPS drive, then blind on a twin with a hidden effect, then on "
        "a record whose effect is in no library."
    ),
    code(
        "import jax\n"
        "jax.config.update('jax_enable_x64', True)\n"
        "import jax.random as jr\n"
        "from IPython.display import Markdown, display\n"
        "import matplotlib.pyplot as plt\n"
        "import jaxvs\n"
        "import numpy as np\n"
        "from jaxvs.data import Record\n"
        "from jaxvs.plotting import plot_verdict\n"
        "from jaxvs.plotting._diagnosis import plot_gap_map, plot_before_after, plot_spectra\n"
        "from jaxvs.twins import SpindleThermalTwin\n"
        "from jaxvs.twins import DriveTwin, draw_drive_effect\n"
        "DATA = '../../shared/data/EMPS'"
    ),
    md(
        "## EMPS: a real prismatic drive\n\n"
        "Nominal model: the rigid axis `M q̈ + Fv q̇ + offset = u` *without* Coulomb friction, "
        "calibrated on `DATA_EMPS.mat` and validated on `DATA_EMPS_PULSES.mat` (which carries "
        "force pulses). The files are read as they are."
    ),
    code(
        "emps = jaxvs.diagnose(f'{DATA}/DATA_EMPS.mat', f'{DATA}/DATA_EMPS_PULSES.mat',\n"
        "                      family='drive', max_effects=3, progress=True,\n"
        "                      discover=False)  # discovery on EMPS: see the diagnosis guide\n"
        "print(emps.status_line)\n"
        "display(Markdown(emps.to_markdown()))"
    ),
    md(
        "Coulomb friction is named first, with `Fc` within about 1 % of the "
        "published IDIM-LS value 20.39 N, then asymmetric friction replaces it — as the EMPS "
        "description found — and nothing else passes the null. Once Coulomb friction is in, the remaining gap concentrates at the velocity "
        "reversals, at standstill and while the force pulses of the validation file are on:"
    ),
    code(
        "for r in emps['rounds'][1:]:\n"
        "    print(f\"before round {r['round']}:\")\n"
        "    for w in r.get('where_before', []):\n"
        "        print(f\"   {w['label']:40s} share of gap {w['share']:.2f} on {w['fraction']:.2f} of the samples\")"
    ),
    code(
        "fig, axs = plt.subplots(1, 2, figsize=(15, 4.5))\n"
        "plot_gap_map(emps, ax=axs[0])\n"
        "plot_spectra(emps, ax=axs[1])\n"
        "fig.tight_layout()"
    ),
    code("plot_before_after(emps);"),
    md(
        "## Blind: a drive twin with a hidden effect\n\n"
        "The twin's motor and load are coupled by a spring-damper (a two-mass resonance, "
        "simulated with its own integrator and controller sampling — not the library's "
        "augmentation), and its nominal parameters are perturbed by 10 %. The diagnosis sees "
        "only the two records. `benchmarks/blind_diagnosis.py` runs many such cases over all "
        "effects and families, including the ones it gets wrong."
    ),
    code(
        "k1, k2, k3, k4 = jr.split(jr.key(7), 4)\n"
        "hidden = draw_drive_effect(k1, 'resonance', magnitude=0.5)\n"
        "twin = DriveTwin(effects=hidden).perturb(k2, 0.1)\n"
        "cal, val = twin.experiment(k3, duration=12.0), twin.experiment(k4, duration=6.0)\n"
        "blind = jaxvs.diagnose(cal, val, family='drive', max_effects=2, progress=True)\n"
        "display(Markdown(blind.to_markdown()))\n"
        "print('hidden:', hidden)\n"
        "print('named :', blind.verdict['effects'], '-> primary', blind.verdict['primary'])"
    ),
    code("plot_before_after(blind);"),
    md(
        "## The same twin without the effect: `adequate`\n\n"
        "The same records (same reference, same noise) of the twin with its hidden effect "
        "switched off. The rigid model leaves a gap of quantisation, velocity estimation "
        "and loop artefacts, several times the white-noise floor; the null carries the same "
        "artefacts, so no candidate beats it, and the remaining gap lies within the null: the "
        "verdict is `adequate`."
    ),
    code(
        "free_twin = twin.without_effects()\n"
        "cal0, val0 = free_twin.experiment(k3, duration=12.0), free_twin.experiment(k4, duration=6.0)\n"
        "free = jaxvs.diagnose(cal0, val0, family='drive', max_effects=2, progress=True)\n"
        "rows = ['| record | verdict | named effects | validation gap | null floor | white-noise floor |',\n"
        "        '|---|---|---|---|---|---|']\n"
        "for label, rep in (('hidden resonance', blind), ('no effect', free)):\n"
        "    g, v = rep.gap, rep.verdict\n"
        "    named = ', '.join(v['effects']) or 'none'\n"
        "    rows.append(f\"| {label} | {v['status']} | {named} | {100 * g['validation']:.2f} % | \"\n"
        "                f\"{100 * g['noise_floor']:.2f} % | {100 * g['noise_floor_white']:.2f} % |\")\n"
        "display(Markdown('\\n'.join(rows)))\n"
        "assert free.verdict['effects'] == [] and blind.verdict['primary'] == 'resonance'"
    ),
    md(
        "## An effect in no library: `unexplained`, and where it lies\n\n"
        "The spindle thermal twin without any effect, but its bearing thermocouple starts "
        "drifting after the first 4 h of the 12 h record, by 1 K at the end. No library "
        "effect of the thermal family is a sensor drift. The diagnosis must not name one, "
        "and must not call the model adequate either: the remaining gap is above what "
        "the null's effect-free records leave, and the gap map of the final residual says "
        "where it lies."
    ),
    code(
        "rec = SpindleThermalTwin().experiment(jr.key(11), duration=12 * 3600.0)\n"
        "sig = {k: np.asarray(rec[k]) for k in rec.names}\n"
        "late = np.clip((np.linspace(0, 1, len(rec)) - 1 / 3) / (2 / 3), 0, 1)\n"
        "sig['T_bearing'] = sig['T_bearing'] + 1.0 * late**2  # drifts by 1 K after 4 h\n"
        "drift = jaxvs.diagnose(Record(sig, dt=rec.dt), family='thermal')\n"
        "print(drift.status_line)\n"
        "for w in drift.verdict['remainder']['where']:\n"
        "    print(f\"   {w['label']:45s} share {w['share']:.2f} of the remainder on \"\n"
        "          f\"{w['fraction']:.2f} of the samples, p = {w['p_value']:.2g}\")\n"
        "plot_verdict(drift);\n"
        "assert drift.verdict['status'] == 'unexplained' and drift.verdict['effects'] == []"
    ),
    md(
        "## Discovery: what the unexplained remainder is\n\n"
        "Because the remainder stays above the null, `diagnose` went on to **discovery** "
        "(`jaxvs.diagnosis.discover`, on by default; `--no-discover` on the command line "
        "switches it off). The thermal family has two physical slots a missing term can "
        "enter: an additional heat flow into the bearing node (a function of speed, "
        "temperatures and time, passing through the bearing's lag when the model has one) "
        "and an additive term of the bearing sensor (a function of time). In each slot a "
        "flexible term (cubic B-splines, linear in its coefficients) is calibrated jointly "
        "with the model by the one Levenberg–Marquardt kernel and scored on held-out data "
        "against the same step run on the null's effect-free records. When it fires, a "
        "typed dictionary of physical terms (speed powers, temperature differences, `t`, "
        "`t²`, `exp(−t/τ)`) is reduced by backward elimination on the Bayesian evidence "
        "with block-bootstrap stability selection, and the formula is recalibrated and "
        "accepted only when it removes at least 80 % of what the flexible term removes. "
        "Otherwise the answer is the flexible term's shape and \"no formula found\"."
    ),
    code(
        "from jaxvs.plotting import plot_discovered\n"
        "found = drift.discovered\n"
        "print(found.message)\n"
        "print('slot :', found.slot, '| input:', found.input)\n"
        "print('flexible term: held-out shrink', round(found.flexible['shrink'], 3),\n"
        "      '| null threshold of the reduction', f\"{found.flexible['null_threshold']:.2g}\")\n"
        "if found.formula is not None:\n"
        "    print('formula:', found.formula, '| share of the flexible gain', round(found.share, 2))\n"
        "plot_discovered(found);\n"
        "assert found.fired and found.input == 'time (sensor)'"
    ),
    md(
        "The drift is placed in the sensor slot, on time, as built; no term in speed, "
        "temperatures or speed·time does better on held-out data. Its exact law, a "
        "quadratic onset after 4 h, is not one of the dictionary's kinds: the formula is the "
        "combination of `t`, `t²` and `exp(−t/τ)` that the evidence keeps, and it is "
        "accepted because it predicts the held-out block (it extends the drift where the "
        "flexible term, flat beyond its calibration data, cannot). Read it as a description "
        "of the drift over this record, not as its physical law. On a drive whose viscous "
        "friction fades as it warms up, the same step finds the true formula "
        "`40·v·exp(−t/8)` (`benchmarks/discovery.py`); a term outside the dictionary that "
        "the kinds cannot imitate gets \"no formula found\" and the flexible term's shape."
    ),
    md(
        "The same call serves the `tmf` and `thermal` families (`jaxvs diagnose DATA ... "
        "--family tmf|thermal`); `benchmarks/blind_diagnosis.py` runs the blind benchmark "
        "over all families, with sensitivity per family, specificity on effect-free "
        "records and an out-of-library set (four effects per family in no library, each "
        "at two sizes), and the state of every verdict."
    ),
]
build(cells, "05_sim_to_real_gap.ipynb", timeout=1500)
