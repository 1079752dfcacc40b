// tissue locking: the volumetric-locking study (accuracy/locking.hpp) --
// plain and IANP tets against a refined-mesh reference at a nearly
// incompressible Poisson ratio.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include "accuracy/locking.hpp"
#include "apps/commands.hpp"
#include "apps/options.hpp"

namespace tissue::app {

void add_locking_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand(
      "locking", "Plain vs IANP tets against a refined-mesh reference on a compressed box (nearly incompressible)");
  struct Args {
    double nu = 0.499;
    std::vector<int> cells = {4, 8, 16};
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--nu", a->nu, "Poisson ratio")->default_val(0.499)->check(real_number(-1, 0.5, true, true));
  cmd->add_option("--cells", a->cells, "Cells per side of each mesh, ascending (ratio 2 for extrapolation)")
      ->delimiter(',')
      ->default_str("4,8,16")
      ->check(whole_number(1, 64));
  cmd->callback([a, &rc] {
    // The work of a mesh of n cells per side is its 6 n^3 tets times the
    // relaxation's steps, which grow as n (the waves cross n cells): n^4.
    // The plan and each case's time go to stderr as they come, with the next
    // mesh's time forecast from the last one by that power, so that a fine
    // mesh (64 cells: 4096 times the work of 8) is seen to be long at once.
    std::string plan;
    for (int c : a->cells) plan += fmt::format("{}{} ({} tets)", plan.empty() ? "" : ", ", c, 6L * c * c * c);
    fmt::print(stderr,
               "locking: meshes of {} cells per side, each solved plain and IANP; the work grows as cells^4 "
               "(tets x relaxation steps)\n",
               plan);
    const auto done = [&](const accuracy::LockingCase& k) {
      fmt::print(stderr, "locking: {} cells ({} tets), {}: {} steps, {:.1f} s", k.cells, 6L * k.cells * k.cells * k.cells,
                 k.ianp ? "IANP" : "plain", k.steps, k.wall);
      const auto next = std::upper_bound(a->cells.begin(), a->cells.end(), k.cells);
      if (k.ianp && next != a->cells.end())
        fmt::print(stderr, "; next: {} cells, about {:.3g} s per form (x {:.3g}, cells^4)", *next,
                   k.wall * std::pow(double(*next) / k.cells, 4), std::pow(double(*next) / k.cells, 4));
      fmt::print(stderr, "\n");
      std::fflush(stderr);
    };
    fmt::print("{}", accuracy::locking_table(accuracy::locking_study(a->nu, a->cells, done)));
    rc = 0;
  });
}

}  // namespace tissue::app
