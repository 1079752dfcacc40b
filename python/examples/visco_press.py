#!/usr/bin/python3
"""A held press on the viscoelastic kidney: the force felt against the Prony series' prediction.

    PYTHONPATH=build/python python3 python/examples/visco_press.py -o visco_press.png

Runs "@kidney-visco" (Prony terms on the kidney's shear stress, the press
held 3 s) and the elastic "@kidney" along the same tool path, tick by tick.
The prediction is Boltzmann superposition of the elastic force history with
the material's relaxation function G(t) = 1 - sum g_i (1 - exp(-t / tau_i)):
F(t) = sum_k G(t - t_k) (F_e(t_k) - F_e(t_k-1)), exact for a linear
viscoelastic body whose whole response relaxes; the kidney's volumetric
stress does not relax and its strains are finite, which the comparison
measures (docs/materials.md).
"""
import argparse
import json

import numpy as np

import tissue

G_TERMS = [(0.3, 0.2), (0.2, 2.0)]  # io/kidney.hpp kKidneyPronyG / kKidneyPronyTau

p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
p.add_argument("--backend", default=None, help="cpu or cuda (default: the scene's)")
p.add_argument("--precision", default=None)
p.add_argument("--ticks", type=int, default=0, help="ticks to run (default: the whole path)")
p.add_argument("--quick", action="store_true", help="0.6 s of the hold only (tests)")
p.add_argument("--json", default=None, help="also write the curves here")
p.add_argument("-o", "--output", default=None, help="plot (PNG)")
a = p.parse_args()

visco = tissue.Simulation.load("@kidney-visco", backend=a.backend, precision=a.precision)
elastic = tissue.Simulation.load("@kidney", backend=a.backend, precision=a.precision)
visco.follow_scene_path(0)
ticks = a.ticks or (900 if a.quick else 3500)
t, fv, fe, tip = [], [], [], []
for k in range(ticks):
    rv = visco.step()
    pose = rv.tools[0]
    elastic.set_tool_pose(0, pose.tip, pose.axis)
    re = elastic.step()
    t.append(visco.time)
    tip.append(np.array(pose.tip))
    fv.append(float(np.linalg.norm(rv.tools[0].force)))
    fe.append(float(np.linalg.norm(re.tools[0].force)))
t, fv, fe = np.array(t), np.array(fv), np.array(fe)


def G(s):
    return 1 - sum(g * (1 - np.exp(-s / tau)) for g, tau in G_TERMS)


dF = np.diff(np.concatenate([[0.0], fe]))
pred = np.array([np.sum(G(t[i] - t[: i + 1]) * dF[: i + 1]) for i in range(len(t))])

# the hold: the ticks whose tool tip is where it is at the elastic force's peak
deep = tip[int(np.argmax(fe))]
hold = np.where([np.linalg.norm(x - deep) < 1e-9 for x in tip])[0]
h0, h1 = hold[0], hold[-1]
rows = []
for s in (0.0, 0.1, 0.2, 0.5, 1.0, 2.0, 2.9):
    i = h0 + int(round(s / (t[1] - t[0])))
    if i <= h1:
        rows.append({"hold_s": s, "elastic_N": fe[i], "visco_N": fv[i], "prony_prediction_N": pred[i],
                     "visco_over_prediction": fv[i] / pred[i]})
print(f"{visco.name} on {visco.backend} {visco.precision} ({visco.device_name}), hold {t[h0]:.3f}..{t[h1]:.3f} s")
print(f"{'hold s':>7} {'elastic N':>10} {'visco N':>10} {'predicted N':>12} {'visco/pred':>10}")
for r in rows:
    print(f"{r['hold_s']:7.1f} {r['elastic_N']:10.5f} {r['visco_N']:10.5f} {r['prony_prediction_N']:12.5f} "
          f"{r['visco_over_prediction']:10.4f}")
drop = 1 - fv[h1] / fv[h0]
print(f"relaxed over the hold: {100 * drop:.1f} % (prediction {100 * (1 - pred[h1] / pred[h0]):.1f} %)")
if a.json:
    with open(a.json, "w") as f:
        json.dump({"backend": visco.backend, "precision": visco.precision, "device": visco.device_name,
                   "hold_start_s": float(t[h0]), "rows": rows, "relaxed_fraction": float(drop),
                   "predicted_fraction": float(1 - pred[h1] / pred[h0])}, f, indent=1)
if a.output:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4), layout="constrained")
    ax.plot(t, fe, label="elastic (@kidney)", color="0.6")
    ax.plot(t, fv, label="viscoelastic (@kidney-visco)")
    ax.plot(t, pred, "--", label="Prony series prediction")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|force on the tool| (N)")
    ax.set_title(f"held press on the kidney, {visco.backend} {visco.precision}")
    ax.legend()
    fig.savefig(a.output, dpi=110)
