// tissue reference: the reference solution of a scene (accuracy/reference.hpp):
// the scene's scripted tool held at its indentation, the whole mesh in double
// precision, dynamic relaxation to a relative residual of 1e-9 (or --tol).
// SIGINT / SIGTERM end the relaxation at its next convergence check: the
// state reached is printed and written (JSON "converged": false), exit 130 / 143.
#include <fmt/format.h>

#include <memory>
#include <optional>

#include "accuracy/reference.hpp"
#include "apps/commands.hpp"
#include "apps/interrupt.hpp"
#include "apps/options.hpp"
#include "io/output_dir.hpp"
#include "io/vtu_writer.hpp"
#include "scene/checks.hpp"
#include "scene/validate.hpp"

namespace tissue::app {
namespace {

struct ReferenceArgs {
  std::string scene, backend = "cpu", json, out;
  double tol = 1e-9, safety = 0.9;
  bool overwrite = false;
};

int run_reference(const ReferenceArgs& a) {
  InterruptGuard interrupt;
  const scene::Scene s = load_scene_arg(a.scene);
  refuse_loads(s, "reference");
  if (s.tools.empty() || s.tools.front().path.empty())
    throw std::runtime_error(s.source + ": the scene has no scripted tool path to hold");
  const std::vector<Waypoint>& path = s.tools.front().path;
  set_activity(fmt::format("building the model of {}", s.source));
  const TissueModel<double> model = scene::load_model(s);
  if (scene::supported_nodes(model) == 0)
    throw std::runtime_error(fmt::format(
        "{}: no node is fixed, so there is no static equilibrium to relax to: the held tool pushes the whole body "
        "away as a rigid body, and the free-node residual can never fall to {:.3g}; add a <fixed> constraint (the "
        "support)",
        s.source, a.tol));
  std::optional<io::OutputFolder> folder;
  if (!a.out.empty()) folder.emplace(a.out, std::vector<std::string>{"reference.vtu"}, a.overwrite);
  const double t_hold = accuracy::hold_start(path);
  const ToolSetting tool = scene::scheduler_settings(s).tools.front();
  const accuracy::HeldTool held = accuracy::held_tool(model, tool, path, s.solver.tick, t_hold);
  accuracy::ReferenceOptions o;
  o.backend = a.backend;
  o.dt_safety = a.safety;
  o.relax.residual_tol = a.tol;
  o.relax.stop = [] { return InterruptGuard::requested(); };
  set_activity(fmt::format("relaxing {}", s.source));
  fmt::print("reference for {}: {} nodes, {} tets; tool '{}' (radius {:.4g} mm, shaft {:.4g} mm) touches at t = {:.3f} "
             "s, held from t = {:.3f} s at ({:.6g}, {:.6g}, {:.6g}) m\n",
             s.source, model.n_nodes, model.n_elems, tool.shape.name, 1e3 * tool.shape.radius, 1e3 * tool.shape.shaft,
             held.t_touch, t_hold, held.held.tip.x, held.held.tip.y, held.held.tip.z);
  const accuracy::ReferenceSolution ref = accuracy::reference_solution(model, {}, o, &held);
  const Vec3<double> force = ref.tool_force;
  if (ref.relax.interrupted)
    fmt::print("  stopped by {} before converging: the figures below are the state reached\n",
               InterruptGuard::signal_name());
  fmt::print(
      "  dynamic relaxation  {} steps of dt = {:.4g} s in {:.2f} s, damping {:.4g} 1/s ({} re-estimates)\n"
      "  stopped because     it {}\n"
      "  residual reached    {:.3g} (relative free-node residual; wanted <= {:.3g}{}), relative kinetic {:.3g}\n"
      "  force on the tool   ({:.6g}, {:.6g}, {:.6g}) N, |F| = {:.6g} N, {} nodes in contact\n"
      "  max displacement    {:.6g} mm\n"
      "  strain energy       {}\n",
      ref.relax.steps, ref.dt, ref.relax.wall, ref.relax.damping, ref.relax.restarts, ref.relax.why,
      ref.relax.residual, a.tol,
      ref.relax.at_contact_floor ? "; stopped at the contact's floor, a zero-force node going in and out" : "",
      ref.relax.kinetic, force.x, force.y, force.z, norm(force), ref.contact_nodes, 1e3 * ref.max_disp,
      ref.strain_energy >= 0 ? fmt::format("{:.6g} J", ref.strain_energy)
                             : std::string("not measured (the run stopped before the relaxation measured it)"));
  if (!a.json.empty()) {
    write_json_output(
        a.json,
        fmt::format(
            "{{\"scene\": \"{}\", \"nodes\": {}, \"tets\": {}, \"contact_nodes\": {}, \"t_hold\": {}, \"steps\": {}, "
            "\"dt\": {}, \"wall_s\": {}, \"residual\": {}, \"kinetic\": {}, \"damping\": {}, "
            "\"force\": [{}, {}, {}], \"max_disp\": {}, \"strain_energy\": {}, \"converged\": {}}}\n",
            s.source, model.n_nodes, model.n_elems, ref.contact_nodes, t_hold, ref.relax.steps, ref.dt, ref.relax.wall,
            ref.relax.residual, ref.relax.kinetic, ref.relax.damping, force.x, force.y, force.z, ref.max_disp,
            ref.strain_energy >= 0 ? fmt::format("{}", ref.strain_energy) : std::string("null"), ref.relax.converged));
  }
  if (folder) {
    const std::string path_vtu = folder->file("reference.vtu");
    io::write_vtu(path_vtu, model, ref.fields, s.bodies);
    fmt::print("wrote {}\n", path_vtu);
  }
  return ref.relax.interrupted ? InterruptGuard::exit_code() : 0;
}

}  // namespace

void add_reference_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand(
      "reference", "Reference solution: tool held at its indentation, whole mesh, double, relaxed to residual 1e-9");
  auto a = std::make_shared<ReferenceArgs>();
  cmd->add_option("scene", a->scene, "Scene XML file, or @kidney for the built-in kidney")->required();
  cmd->add_option("--backend", a->backend, "cpu | cuda (always double precision)")->default_val("cpu");
  cmd->add_option("--tol", a->tol, "Relative residual to reach")->default_val(1e-9)->check(real_number(0, 1, true, true));
  cmd->add_option("--safety", a->safety, "dt as a fraction of dt_crit")
      ->default_val(0.9)
      ->check(real_number(0, 1, true, true));
  cmd->add_option("--json", a->json, "Write the result as JSON")->check(output_file());
  cmd->add_option("--out", a->out, "Write reference.vtu into this folder")->check(output_folder());
  cmd->add_flag("--overwrite", a->overwrite, "Replace a previous reference.vtu in the --out folder");
  cmd->callback([a, &rc] { rc = run_reference(*a); });
}

}  // namespace tissue::app
