"""Tissue: interactive nonlinear soft-tissue deformation (docs/python.md).

    import tissue
    sim = tissue.Simulation.load("@kidney", backend="cpu")
    sim.set_tool_pose(0, [0.0, 0.0, 0.03])
    result = sim.step(100)
    print(result.tools[0].force)      # N, the force on the tool

Fields (displacement, positions, pressure, internal_force, jacobian) are
NumPy arrays; the reference mesh (rest_positions, tetrahedra,
surface_triangles) is read-only, the same arrays until a cut changes the
mesh (sim.cut(origin, edge, sweep): docs/cutting.md).
Many scenes at once: tissue.Batch("@kidney", 64) steps 64 kidneys together;
forces() is (N, tools, 3) and displacement() (N, nodes, 3) (docs/batch.md).

Errors raise ValueError (a bad argument) or RuntimeError (a scene that does
not validate, a backend that cannot run, an unstable simulation), with a
message naming the file, element, node or value.
"""
from ._tissue import (Batch, Body, CutMesh, CutStats, DeviceArray, MaterialChange, Simulation, TickResult, ToolResult, VolumeMesh,
                      __version__, available_backends, cut_mesh, fields, mesh_surface)
from .meshes import box_mesh, box_node

__all__ = ["Batch", "Body", "CutMesh", "CutStats", "DeviceArray", "MaterialChange", "Simulation", "TickResult", "ToolResult",
           "VolumeMesh", "available_backends", "cut_mesh", "fields", "mesh_surface", "box_mesh", "box_node", "__version__"]
