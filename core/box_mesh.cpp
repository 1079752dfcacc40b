#include "core/box_mesh.hpp"

#include <stdexcept>

namespace tissue {

void box_mesh(ModelInput& in, int nx, int ny, int nz, double lx, double ly, double lz) {
  if (nx < 1 || ny < 1 || nz < 1) throw std::invalid_argument("box_mesh: cell counts must be >= 1");
  in.nodes.clear();
  in.tets.clear();
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        in.nodes.push_back(lx * i / nx);
        in.nodes.push_back(ly * j / ny);
        in.nodes.push_back(lz * k / nz);
      }
  // Kuhn subdivision: the 6 paths from corner 000 to corner 111 along the
  // axes; each path gives one tet (v0, v0+e_a, v0+e_a+e_b, v111).
  static constexpr int kPerm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (const auto& p : kPerm) {
          int c[3] = {i, j, k};
          index_t v[4];
          v[0] = box_node(nx, ny, c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[p[s]];
            v[s + 1] = box_node(nx, ny, c[0], c[1], c[2]);
          }
          // even permutations are positively oriented; swap for odd ones
          const bool odd = (p[0] == 0 && p[1] == 2) || (p[0] == 1 && p[1] == 0) || (p[0] == 2 && p[1] == 1);
          if (odd) std::swap(v[1], v[2]);
          in.tets.insert(in.tets.end(), v, v + 4);
        }
}

}  // namespace tissue
