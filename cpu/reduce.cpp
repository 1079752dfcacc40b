#include "cpu/reduce.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>

namespace tissue::cpu {
namespace {

/// Partial sums of one chunk (all double).
struct Partial {
  double reaction[3] = {0, 0, 0};
  double internal[3] = {0, 0, 0};
  double free2 = 0, held2 = 0, kinetic = 0, max_disp = 0;
  bool finite = true;
};

Partial combine(Partial a, const Partial& b) {
  for (int c = 0; c < 3; ++c) {
    a.reaction[c] += b.reaction[c];
    a.internal[c] += b.internal[c];
  }
  a.free2 += b.free2;
  a.held2 += b.held2;
  a.kinetic += b.kinetic;
  a.max_disp = std::max(a.max_disp, b.max_disp);
  a.finite = a.finite && b.finite;
  return a;
}

}  // namespace

template <class T>
Reductions reduce_region(const TissueModel<T>& m, const TissueState<T>& s, std::span<const index_t> nodes) {
  const index_t n = m.n_nodes;
  const double inv_dt = 1.0 / m.dt;
  const Partial total = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<std::size_t>(0, nodes.size(), kReduceGrain), Partial{},
      [&](const tbb::blocked_range<std::size_t>& r, Partial p) {
        for (std::size_t k = r.begin(); k != r.end(); ++k) {
          const index_t a = nodes[k];
          double f[3], u2 = 0, v2 = 0;
          for (int c = 0; c < 3; ++c) {
            f[c] = double(s.f[c * n + a]);
            const double u = double(s.u[c * n + a]);
            const double v = (u - double(s.u_prev[c * n + a])) * inv_dt;
            u2 += u * u;
            v2 += v * v;
          }
          const double f2 = f[0] * f[0] + f[1] * f[1] + f[2] * f[2];
          p.finite = p.finite && std::isfinite(f2) && std::isfinite(u2) && std::isfinite(v2);
          p.kinetic += 0.5 * double(m.mass[a]) * v2;
          p.max_disp = std::max(p.max_disp, std::sqrt(u2));
          if (s.driven[a])
            for (int c = 0; c < 3; ++c) p.reaction[c] += f[c];
          if (s.region.role[a] != kInner) continue;
          for (int c = 0; c < 3; ++c) p.internal[c] += f[c];
          (s.held[a] ? p.held2 : p.free2) += f2;
        }
        return p;
      },
      combine);
  Reductions out;
  out.reaction = {total.reaction[0], total.reaction[1], total.reaction[2]};
  out.internal = {total.internal[0], total.internal[1], total.internal[2]};
  out.free_force2 = total.free2;
  out.held_force2 = total.held2;
  out.kinetic = total.kinetic;
  out.max_disp = total.max_disp;
  out.finite = total.finite && std::isfinite(total.free2 + total.held2 + total.kinetic) &&
               std::isfinite(total.reaction[0] + total.reaction[1] + total.reaction[2]);
  return out;
}

template Reductions reduce_region(const TissueModel<float>&, const TissueState<float>&, std::span<const index_t>);
template Reductions reduce_region(const TissueModel<double>&, const TissueState<double>&, std::span<const index_t>);

}  // namespace tissue::cpu
