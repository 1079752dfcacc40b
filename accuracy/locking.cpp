#include "accuracy/locking.hpp"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

#include "accuracy/reference.hpp"
#include "core/box_mesh.hpp"

namespace tissue::accuracy {
namespace {

constexpr double kSide = 0.04;   // m
constexpr double kE = 3000.0;    // Pa
constexpr double kRho = 1000.0;  // kg/m^3
constexpr double kPress = 0.02;  // top displacement / side

LockingCase solve(int cells, bool ianp, double nu) {
  ModelInput in;
  box_mesh(in, cells, cells, cells, kSide, kSide, kSide);
  in.materials = {{kE / (2 * (1 + nu)), kE / (3 * (1 - 2 * nu)), kRho}};
  in.ianp = ianp;
  in.source = fmt::format("locking box {}^3", cells);
  const index_t n = static_cast<index_t>(in.nodes.size() / 3);
  in.fixed.assign(n, 0);
  Drive top;
  for (int j = 0; j <= cells; ++j)
    for (int i = 0; i <= cells; ++i) {
      in.fixed[box_node(cells, cells, i, j, 0)] = 1;
      top.nodes.push_back(box_node(cells, cells, i, j, cells));
      top.u.insert(top.u.end(), {0.0, 0.0, -kPress * kSide});
    }
  const ReferenceSolution ref = reference_solution(build_model(in), top);
  LockingCase c;
  c.cells = cells;
  c.ianp = ianp;
  c.force = std::fabs(ref.reaction.z);
  c.residual = ref.relax.residual;
  c.steps = ref.relax.steps;
  c.wall = ref.relax.wall;
  return c;
}

}  // namespace

double richardson(double f4h, double f2h, double fh, double* rate) {
  *rate = 0;
  const double d1 = f4h - f2h, d2 = f2h - fh;
  if (!(d1 * d2 > 0) || !(std::fabs(d2) < std::fabs(d1))) return 0;
  *rate = std::log2(d1 / d2);
  return fh - d2 / (std::pow(2.0, *rate) - 1);
}

LockingStudy locking_study(double nu, const std::vector<int>& cells,
                           const std::function<void(const LockingCase&)>& done) {
  if (!(nu > -1 && nu < 0.5)) throw std::invalid_argument(fmt::format("locking study: nu = {} must be in (-1, 0.5)", nu));
  LockingStudy s;
  s.nu = nu;
  for (size_t k = 0; k < cells.size(); ++k) {  // every mesh checked before any is solved
    if (cells[k] < 1) throw std::invalid_argument(fmt::format("locking study: {} cells per side must be >= 1", cells[k]));
    if (k > 0 && cells[k] <= cells[k - 1])
      throw std::invalid_argument(fmt::format("locking study: cells {} after {}: the meshes must ascend (the last, "
                                              "finest one is the reference)",
                                              cells[k], cells[k - 1]));
  }
  for (int c : cells)
    for (bool ianp : {false, true}) {
      s.cases.push_back(solve(c, ianp, nu));
      if (done) done(s.cases.back());
    }
  const std::size_t m = cells.size();
  if (m >= 3 && cells[m - 1] == 2 * cells[m - 2] && cells[m - 2] == 2 * cells[m - 3]) {
    auto f = [&](std::size_t k, bool ianp) { return s.cases[2 * k + (ianp ? 1 : 0)].force; };
    s.extrapolated_plain = richardson(f(m - 3, false), f(m - 2, false), f(m - 1, false), &s.rate_plain);
    s.extrapolated_ianp = richardson(f(m - 3, true), f(m - 2, true), f(m - 1, true), &s.rate_ianp);
  }
  return s;
}

std::string locking_table(const LockingStudy& s) {
  const double ref = s.extrapolated_ianp > 0 ? s.extrapolated_ianp : s.cases.back().force;
  std::string out = fmt::format(
      "locking study: {:.0f} mm box, E = {:.0f} Pa, nu = {}, top pushed {:.0f}% (reference force {:.5g} N: {})\n",
      1e3 * kSide, kE, s.nu, 100 * kPress, ref,
      s.extrapolated_ianp > 0 ? fmt::format("IANP extrapolated, order {:.2f}", s.rate_ianp) : "finest IANP mesh");
  out += fmt::format("{:>6} {:>7} {:>6} {:>11} {:>9} {:>10} {:>8} {:>8}\n", "cells", "tets", "form", "force (N)",
                     "/ ref", "residual", "steps", "wall s");
  for (const LockingCase& c : s.cases)
    out += fmt::format("{:>6} {:>7} {:>6} {:>11.5g} {:>9.3f} {:>10.2g} {:>8} {:>8.1f}\n", c.cells,
                       6 * c.cells * c.cells * c.cells, c.ianp ? "IANP" : "plain", c.force, c.force / ref, c.residual,
                       c.steps, c.wall);
  if (s.extrapolated_plain > 0)
    out += fmt::format("plain extrapolated: {:.5g} N (order {:.2f}), {:.3f} x the reference\n", s.extrapolated_plain,
                       s.rate_plain, s.extrapolated_plain / ref);
  return out;
}

}  // namespace tissue::accuracy
