// Fuzzes the XML scene reader (io/scene_xml) and what a scene goes through
// after it: validation into a ModelInput, build_model, the scene checks, and
// the writer. Properties beyond "no crash, leak or UB": only SceneError /
// ModelError escape; a scene that validates is written and read back to the
// same solver settings and mesh.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "core/model.hpp"
#include "io/scene_xml.hpp"
#include "scene/checks.hpp"
#include "scene/validate.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tissue;
  const std::string_view xml(reinterpret_cast<const char*>(data), size);
  scene::Scene s;
  try {
    // references to mesh and path files resolve in a folder that holds none
    s = io::parse_scene(xml, "fuzz.xml", "/nonexistent-tissue-fuzz");
  } catch (const scene::SceneError&) {
    return 0;
  }
  ModelInput in;
  try {
    in = scene::to_model_input(s);
  } catch (const scene::SceneError&) {
    return 0;
  }
  const scene::Scene back = io::parse_scene(io::format_scene(s, ""), "back.xml", "");
  if (back.nodes != s.nodes || back.tets != s.tets || back.solver.dt != s.solver.dt ||
      back.solver.damping != s.solver.damping || back.solver.depth != s.solver.depth ||
      back.materials.size() != s.materials.size())
    __builtin_trap();
  if (in.tets.size() > 4 * 2000) return 0;  // keep each run short
  try {
    const TissueModel<double> m = scene::load_model(s);
    (void)scene::scene_warnings(s, m);
  } catch (const ModelError&) {
  } catch (const scene::SceneError&) {
  }
  return 0;
}
