// tissue info: the version and commit of this build, which backends it has
// and which can run here.
#include <fmt/format.h>

#include "apps/commands.hpp"
#include "backends/registry.hpp"

namespace tissue::app {

void add_info_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand(
      "info", "Print the version and commit; list the backends, whether they were built and can run here");
  cmd->callback([&rc] {
    fmt::print("{}\n", version_line());
    for (const BackendInfo& b : list_backends()) {
      fmt::print("{:6} {:10} {}\n", b.name, b.available ? "available" : (b.built ? "no device" : "not built"),
                 b.detail);
      if (b.built && b.float_math != "ieee")  // docs/cuda.md, "Float division and square root"
        fmt::print("{:6} {:10} float division and square root: {}, denormals flushed "
                   "(TISSUE_CUDA_FAST_FLOAT_MATH; double: ieee)\n",
                   "", "", b.float_math);
      if (!b.tuning.empty())  // the cpu's lane kernels by vendor
        fmt::print("{:6} {:10} lane kernels: {} tuning (TISSUE_CPU_TUNING=xeon|generic overrides)\n", "", "",
                   b.tuning);
    }
    rc = 0;
  });
}

}  // namespace tissue::app
