// Fuzzes the TetGen .node/.ele reader (io/tetgen_files). The input is the
// .node text, a NUL byte, then the .ele text. Only TetgenFileError may
// escape the readers (no std::bad_alloc from a header's counts); a pair that
// reads has every corner in range, and goes on through build_model.
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>

#include "core/model.hpp"
#include "io/tetgen_files.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tissue;
  const std::string text(reinterpret_cast<const char*>(data), size);
  const size_t nul = text.find('\0');
  std::istringstream node_in(text.substr(0, nul));
  std::vector<double> nodes;
  int first = -1;
  try {
    nodes = io::parse_tetgen_node(node_in, "fuzz.node", first);
  } catch (const io::TetgenFileError&) {
    return 0;
  }
  if (nodes.size() % 3 != 0 || (first != 0 && first != 1)) __builtin_trap();
  if (nul == std::string::npos) return 0;
  std::istringstream ele_in(text.substr(nul + 1));
  std::vector<index_t> tets;
  const index_t n = static_cast<index_t>(nodes.size() / 3);
  try {
    tets = io::parse_tetgen_ele(ele_in, "fuzz.ele", n, first);
  } catch (const io::TetgenFileError&) {
    return 0;
  }
  for (index_t c : tets)
    if (c < 0 || c >= n) __builtin_trap();
  if (tets.size() > 4 * 2000) return 0;
  ModelInput in;
  in.nodes = std::move(nodes);
  in.tets = std::move(tets);
  in.materials = {{1000.0, 10000.0, 1000.0}};
  in.tick = 1e-3;
  in.dt_safety = 0.9;
  try {
    (void)build_model(in);
  } catch (const ModelError&) {
  }
  return 0;
}
