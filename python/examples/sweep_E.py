#!/usr/bin/python3
"""Sweep Young's modulus: the equilibrium force of one press on a block.

A Neo-Hookean body's stress at a given deformation is proportional to E
(nu fixed), so the force of the same press is too: the plot shows the line
through the origin that the points must follow.

    PYTHONPATH=build/python python3 python/examples/sweep_E.py -o sweep.png
"""
import argparse

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import tissue

p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
p.add_argument("--backend", default="cpu")
p.add_argument("--quick", action="store_true", help="fewer moduli (tests)")
p.add_argument("-o", "--output", default="sweep_E.png")
a = p.parse_args()

nx, ny, nz = 8, 8, 4
nodes, tets = tissue.box_mesh(nx, ny, nz, (0.03, 0.03, 0.015))   # a 30 x 30 x 15 mm block
fixed = [tissue.box_node(nx, ny, i, j, 0) for j in range(ny + 1) for i in range(nx + 1)]
moduli = [2e3, 8e3] if a.quick else [1e3, 2e3, 4e3, 8e3, 16e3]  # Pa: soft tissue's range
depth, radius = 1e-3, 4e-3
forces = []
for E in moduli:
    sim = tissue.Simulation.from_mesh(nodes, tets, E=E, nu=0.45, fixed=fixed, tool_radii=[radius],
                                      backend=a.backend, precision="double")
    for k in range(1, 501):  # a 200 ms press, then held
        sim.set_tool_pose(0, [0.015, 0.015, 0.015 + radius - depth * min(1.0, k / 200)])
        last = sim.step()
    forces.append(last.tools[0].force[2])
    print(f"E = {E:8.0f} Pa: {forces[-1]:.5f} N  (equilibrium: {last.equilibrium})")

slope = np.dot(moduli, forces) / np.dot(moduli, moduli)
fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
ax.plot(np.array(moduli) / 1e3, forces, "o", label="simulated")
ax.plot([0, moduli[-1] / 1e3], [0, slope * moduli[-1]], "--", label="F proportional to E")
ax.set_xlabel("Young's modulus E (kPa)")
ax.set_ylabel("force at 1 mm press (N)")
ax.set_title(f"Neo-Hookean block, nu = 0.45, {radius * 1e3:.0f} mm probe ({sim.backend})")
ax.legend()
ax.grid(alpha=0.3)
fig.savefig(a.output, dpi=120)
print(f"wrote {a.output}")
