// tissue locking: the volumetric-locking study (accuracy/locking.hpp) --
// plain and IANP tets against a refined-mesh reference at a nearly
// incompressible Poisson ratio.
#include <fmt/format.h>

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
    fmt::print("{}", accuracy::locking_table(accuracy::locking_study(a->nu, a->cells)));
    rc = 0;
  });
}

}  // namespace tissue::app
