// tissue reference: the reference solution of a scene (accuracy/reference.hpp):
// the scene's scripted tool held at its indentation, the whole mesh in double
// precision, dynamic relaxation to a relative residual of 1e-9 (or --tol).
#include <fmt/format.h>

#include <filesystem>
#include <fstream>
#include <memory>

#include "accuracy/reference.hpp"
#include "apps/commands.hpp"
#include "io/vtu_writer.hpp"
#include "scene/validate.hpp"

namespace tissue::app {
namespace {

struct ReferenceArgs {
  std::string scene, backend = "cpu", json, out;
  double tol = 1e-9, safety = 0.9;
};

int run_reference(const ReferenceArgs& a) {
  const scene::Scene s = load_scene_arg(a.scene);
  if (s.tools.empty() || s.tools.front().path.empty())
    throw std::runtime_error(s.source + ": the scene has no scripted tool path to hold");
  const std::vector<Waypoint>& path = s.tools.front().path;
  const TissueModel<double> model = scene::load_model(s);
  const double t_hold = accuracy::hold_start(path);
  const ToolSetting tool = scene::scheduler_settings(s).tools.front();
  const accuracy::HeldTool held = accuracy::held_tool(model, tool, path, s.solver.tick, t_hold);
  accuracy::ReferenceOptions o;
  o.backend = a.backend;
  o.dt_safety = a.safety;
  o.relax.residual_tol = a.tol;
  fmt::print("reference for {}: {} nodes, {} tets; tool '{}' (radius {:.4g} mm, shaft {:.4g} mm) touches at t = {:.3f} "
             "s, held from t = {:.3f} s at ({:.6g}, {:.6g}, {:.6g}) m\n",
             s.source, model.n_nodes, model.n_elems, tool.shape.name, 1e3 * tool.shape.radius, 1e3 * tool.shape.shaft,
             held.t_touch, t_hold, held.held.tip.x, held.held.tip.y, held.held.tip.z);
  const accuracy::ReferenceSolution ref = accuracy::reference_solution(model, {}, o, &held);
  const Vec3<double> force = ref.tool_force;
  fmt::print(
      "  dynamic relaxation  {} steps of dt = {:.4g} s in {:.2f} s, damping {:.4g} 1/s ({} re-estimates)\n"
      "  residual reached    {:.3g} (relative free-node residual; wanted <= {:.3g}{}), relative kinetic {:.3g}\n"
      "  force on the tool   ({:.6g}, {:.6g}, {:.6g}) N, |F| = {:.6g} N, {} nodes in contact\n"
      "  max displacement    {:.6g} mm\n"
      "  strain energy       {:.6g} J\n",
      ref.relax.steps, ref.dt, ref.relax.wall, ref.relax.damping, ref.relax.restarts, ref.relax.residual, a.tol,
      ref.relax.at_contact_floor ? "; stopped at the contact's floor, a zero-force node going in and out" : "",
      ref.relax.kinetic, force.x, force.y, force.z, norm(force), ref.contact_nodes, 1e3 * ref.max_disp,
      ref.strain_energy);
  if (!a.json.empty()) {
    std::ofstream f(a.json);
    if (!f) throw std::runtime_error("cannot write " + a.json);
    f << fmt::format(
        "{{\"scene\": \"{}\", \"nodes\": {}, \"tets\": {}, \"contact_nodes\": {}, \"t_hold\": {}, \"steps\": {}, "
        "\"dt\": {}, \"wall_s\": {}, \"residual\": {}, \"kinetic\": {}, \"damping\": {}, "
        "\"force\": [{}, {}, {}], \"max_disp\": {}, \"strain_energy\": {}}}\n",
        s.source, model.n_nodes, model.n_elems, ref.contact_nodes, t_hold, ref.relax.steps, ref.dt, ref.relax.wall,
        ref.relax.residual, ref.relax.kinetic, ref.relax.damping, force.x, force.y, force.z, ref.max_disp,
        ref.strain_energy);
    fmt::print("wrote {}\n", a.json);
  }
  if (!a.out.empty()) {
    std::filesystem::create_directories(a.out);
    const std::string path_vtu = a.out + "/reference.vtu";
    io::write_vtu(path_vtu, model, ref.fields);
    fmt::print("wrote {}\n", path_vtu);
  }
  return 0;
}

}  // namespace

void add_reference_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand(
      "reference", "Reference solution: tool held at its indentation, whole mesh, double, relaxed to residual 1e-9");
  auto a = std::make_shared<ReferenceArgs>();
  cmd->add_option("scene", a->scene, "Scene XML file, or @kidney for the built-in kidney")->required();
  cmd->add_option("--backend", a->backend, "cpu | cuda (always double precision)")->default_val("cpu");
  cmd->add_option("--tol", a->tol, "Relative residual to reach")->default_val(1e-9);
  cmd->add_option("--safety", a->safety, "dt as a fraction of dt_crit")->default_val(0.9);
  cmd->add_option("--json", a->json, "Write the result as JSON");
  cmd->add_option("--out", a->out, "Write reference.vtu here");
  cmd->callback([a, &rc] { rc = run_reference(*a); });
}

}  // namespace tissue::app
