#!/usr/bin/python3
"""Press a tool into an organ and plot the force the hand feels against depth.

    PYTHONPATH=build/python python3 python/examples/press_curve.py [@kidney | scene.xml] -o press.png
"""
import argparse

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import tissue

p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
p.add_argument("scene", nargs="?", default="@kidney")
p.add_argument("--backend", default=None, help="cpu or cuda (default: the scene's)")
p.add_argument("--depth", type=float, default=4e-3, help="press depth (m)")
p.add_argument("--quick", action="store_true", help="a shorter run (tests)")
p.add_argument("-o", "--output", default="press_curve.png")
a = p.parse_args()

sim = tissue.Simulation.load(a.scene, backend=a.backend)
X = sim.rest_positions
top = X[np.argmax(X[:, 2])]                  # the highest surface point
r = sim.tool_radius(0)
ramp = 150 if a.quick else 1000              # ticks of 1 ms: a slow, quasi-static press
depth, force = [], []
for k in range(1, ramp + 1):
    d = a.depth * k / ramp
    sim.set_tool_pose(0, top + [0.0, 0.0, r - d])
    depth.append(d)
    force.append(sim.step().tools[0].force[2])
print(f"{sim.name} on {sim.backend} ({sim.device_name}): {force[-1]:.4f} N at {1e3 * a.depth:.1f} mm")

fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
ax.plot(1e3 * np.array(depth), force)
ax.set_xlabel("press depth (mm)")
ax.set_ylabel("force on the tool, vertical (N)")
ax.set_title(f"{sim.name}: {r * 1e3:.0f} mm probe, {sim.backend} {sim.precision}")
ax.grid(alpha=0.3)
fig.savefig(a.output, dpi=120)
print(f"wrote {a.output}")
