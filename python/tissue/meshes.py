"""Structured meshes for experiments and tests (NumPy only)."""
import numpy as np

# The six tetrahedra of a cube around its diagonal from corner 0 to corner 6
# (corners 0-3 the bottom face counter-clockwise, 4-7 the top face above
# them); the same split in every cell makes the mesh conforming.
_KUHN = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]])


def box_mesh(nx, ny, nz, size):
    """A box [0, lx] x [0, ly] x [0, lz] (size = (lx, ly, lz), m) of
    nx x ny x nz cells, six tetrahedra each.

    Returns (nodes, tets): (n_nodes, 3) float64 and (6 nx ny nz, 4) int32;
    node (i, j, k) of the grid has id i + (nx + 1) (j + (ny + 1) k)."""
    if min(nx, ny, nz) < 1:
        raise ValueError(f"box_mesh: {nx} x {ny} x {nz} cells; each count must be >= 1")
    lx, ly, lz = size
    i, j, k = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij")
    nodes = np.stack([i.T.ravel() * lx / nx, j.T.ravel() * ly / ny, k.T.ravel() * lz / nz], axis=1)

    def node(a, b, c):
        return a + (nx + 1) * (b + (ny + 1) * c)

    ci, cj, ck = (g.T.ravel() for g in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    corners = np.stack([node(ci, cj, ck), node(ci + 1, cj, ck), node(ci + 1, cj + 1, ck), node(ci, cj + 1, ck),
                        node(ci, cj, ck + 1), node(ci + 1, cj, ck + 1), node(ci + 1, cj + 1, ck + 1),
                        node(ci, cj + 1, ck + 1)], axis=1)
    tets = corners[:, _KUHN].reshape(-1, 4).astype(np.int32)
    return nodes, tets


def box_node(nx, ny, i, j, k):
    """Id of grid node (i, j, k) of box_mesh(nx, ny, ...)."""
    return i + (nx + 1) * (j + (ny + 1) * k)
