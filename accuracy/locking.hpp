// The volumetric-locking study of docs/accuracy.md: tests/test_locking.cpp's
// box (side 40 mm, E = 3 kPa, bottom fixed, top face pushed down by 2% of
// the side with its lateral motion held) at a near-incompressible nu, solved
// to equilibrium (reference_solution: whole mesh, double, residual 1e-9) with
// plain and IANP tets on successively refined meshes. The finest mesh's
// answers and their extrapolation are the refined-mesh reference the two
// formulations are compared against.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace tissue::accuracy {

/// One formulation on one mesh.
struct LockingCase {
  int cells = 0;          ///< cells per side (6 cells^3 tets)
  bool ianp = true;
  double force = 0;       ///< |z reaction| on the top face at equilibrium (N)
  double residual = 0;    ///< relative residual the relaxation reached
  long steps = 0;
  double wall = 0;        ///< s
};

struct LockingStudy {
  double nu = 0.499;
  std::vector<LockingCase> cases;  ///< for each mesh: plain, then IANP
  /// Richardson estimates of the converged force (N) from each formulation's
  /// three finest meshes (cells in ratio 2), with the observed order p:
  /// F = F_h - (F_2h - F_h) / (2^p - 1), p = log2((F_4h - F_2h) / (F_2h - F_h));
  /// 0 when fewer than three meshes or the sequence is not monotone.
  double extrapolated_ianp = 0, rate_ianp = 0;
  double extrapolated_plain = 0, rate_plain = 0;
};

/// Richardson extrapolation of f(h) from three values at h = 4h0, 2h0, h0;
/// writes the observed order to *rate. Returns 0 (and rate 0) unless the
/// differences shrink monotonically.
double richardson(double f4h, double f2h, double fh, double* rate);

/// Runs the study at Poisson ratio nu on boxes of cells^3 cells (ascending);
/// `done`, when set, is called with each case as soon as it is solved (the
/// command line's progress: a fine mesh takes minutes to hours).
LockingStudy locking_study(double nu, const std::vector<int>& cells,
                           const std::function<void(const LockingCase&)>& done = {});

/// The study as a text table with forces relative to the reference.
std::string locking_table(const LockingStudy& study);

}  // namespace tissue::accuracy
