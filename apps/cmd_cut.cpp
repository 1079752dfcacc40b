// tissue cut: cuts a scene's mesh along the surface a blade sweeps
// (scene/cut_scene.hpp, core/cut.hpp) and measures what the cut costs the
// solver: nodes and elements made, pieces, volume, the critical step and
// the worst dihedral angle before and after, and the time of the cut and of
// the model's rebuild. `--method all` compares the methods (docs/cutting.md).
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "apps/commands.hpp"
#include "apps/options.hpp"
#include "core/cut.hpp"
#include "io/mesh_quality.hpp"
#include "io/scene_xml.hpp"
#include "scene/checks.hpp"
#include "scene/cut_scene.hpp"
#include "scene/validate.hpp"

namespace tissue::app {
namespace {

struct CutArgs {
  std::string scene, method = "snap-split", out, json;
  std::vector<double> origin, edge, sweep;
  CutOptions defaults;
  double snap = defaults.snap, touch = defaults.touch, keep = defaults.keep;
};

/// What a mesh is to the solver, for the before-and-after rows.
struct MeshFacts {
  index_t nodes = 0, elements = 0, pieces = 0;
  double volume = 0, dt_crit = 0, min_dihedral = 0;
};

MeshFacts facts(const scene::Scene& s, const TissueModel<double>& m) {
  MeshFacts f;
  f.nodes = m.n_nodes;
  f.elements = m.n_elems;
  f.dt_crit = m.dt_crit_physical;
  f.min_dihedral = 180;
  for (std::size_t e = 0; e < s.tets.size() / 4; ++e) {
    Vec3<double> X[4];
    for (int c = 0; c < 4; ++c) {
      const index_t v = s.tets[4 * e + c];
      X[c] = {s.nodes[3 * v], s.nodes[3 * v + 1], s.nodes[3 * v + 2]};
    }
    f.volume += dot(cross(X[1] - X[0], X[2] - X[0]), X[3] - X[0]) / 6;
    double a[6];
    io::tet_dihedral_angles(X, a);
    for (double v : a) f.min_dihedral = std::min(f.min_dihedral, v * 180 / 3.14159265358979323846);
  }
  std::vector<index_t> piece;
  f.pieces = scene::mesh_pieces(m, piece);
  return f;
}

CutMethod method_of(const std::string& name) {
  if (name == "snap") return CutMethod::Snap;
  if (name == "split") return CutMethod::Split;
  if (name == "snap-split") return CutMethod::SnapSplit;
  throw std::invalid_argument(fmt::format("--method '{}': expected snap, split, snap-split or all", name));
}

Vec3<double> vec(const std::vector<double>& v, const char* option) {
  if (v.size() != 3) throw std::invalid_argument(fmt::format("{} takes three numbers x,y,z (m)", option));
  return {v[0], v[1], v[2]};
}

int run_cut(const CutArgs& a) {
  const CutSurface cut{vec(a.origin, "--origin"), vec(a.edge, "--edge"), vec(a.sweep, "--sweep")};
  const std::vector<std::string> methods =
      a.method == "all" ? std::vector<std::string>{"snap", "split", "snap-split"} : std::vector<std::string>{a.method};
  for (const std::string& m : methods) (void)method_of(m);
  if (a.method == "all" && !a.out.empty())
    throw std::invalid_argument("-o writes one cut scene: give one --method with it, not all");
  const scene::Scene s = load_scene_arg(a.scene);
  set_activity(fmt::format("building the model of {}", s.source));
  const TissueModel<double> before_model = scene::load_model(s);
  const MeshFacts before = facts(s, before_model);
  fmt::print("{}: {} nodes, {} elements, {} piece(s); dt_crit {:.4g} s, smallest dihedral {:.2f} degrees\n", s.source,
             before.nodes, before.elements, before.pieces, before.dt_crit, before.min_dihedral);
  fmt::print("{:<11} {:>7} {:>6} {:>7} {:>6} {:>6} {:>6} {:>10} {:>6} {:>12} {:>9} {:>9} {:>9} {:>10}\n", "method",
             "+elems", "split", "snapped", "+edge", "copies", "faces", "unresolved", "pieces", "volume", "dt ratio",
             "dihedral", "cut ms", "rebuild ms");
  std::vector<std::string> rows;
  for (std::size_t k = 0; k < methods.size(); ++k) {
    set_activity(fmt::format("cutting {} ({})", s.source, methods[k]));
    CutResult r;
    const auto t0 = std::chrono::steady_clock::now();
    const scene::Scene cut_s = scene::cut_scene(s, cut, {.method = method_of(methods[k]), .snap = a.snap, .keep = a.keep, .touch = a.touch}, &r);
    const auto t1 = std::chrono::steady_clock::now();
    const TissueModel<double> after_model = scene::load_model(cut_s);
    const auto t2 = std::chrono::steady_clock::now();
    const MeshFacts after = facts(cut_s, after_model);
    const double cut_ms = 1e3 * std::chrono::duration<double>(t1 - t0).count();
    const double rebuild_ms = 1e3 * std::chrono::duration<double>(t2 - t1).count();
    const double volume = after.volume / before.volume - 1, ratio = after.dt_crit / before.dt_crit;
    fmt::print("{:<11} {:>7} {:>6} {:>7} {:>6} {:>6} {:>6} {:>10} {:>6} {:>+12.2e} {:>9.3f} {:>9.2f} {:>9.2f} {:>10.2f}\n",
               methods[k], after.elements - before.elements, r.split, r.snapped, r.edge_nodes, r.copies, r.cut_faces,
               r.unresolved, after.pieces, volume, ratio, after.min_dihedral, cut_ms, rebuild_ms);
    rows.push_back(fmt::format(
        "{{\"bench\": \"cut\", \"scene\": \"{}\", \"method\": \"{}\", \"snap\": {}, \"touch\": {}, \"keep\": {}, \"nodes\": {}, \"elements\": "
        "{}, \"new_elements\": {}, \"split\": {}, \"snapped\": {}, \"edge_nodes\": {}, \"copies\": {}, \"cut_faces\": "
        "{}, \"unresolved\": {}, \"pieces\": {}, \"volume_change\": {:.3e}, \"dt_crit_before\": {:.6g}, "
        "\"dt_crit_after\": {:.6g}, \"dt_ratio\": {:.4f}, \"min_dihedral_before\": {:.3f}, \"min_dihedral_after\": "
        "{:.3f}, \"cut_ms\": {:.3f}, \"rebuild_ms\": {:.3f}}}",
        s.source, methods[k], a.snap, a.touch, a.keep, after.nodes, after.elements, after.elements - before.elements,
        r.split, r.snapped, r.edge_nodes, r.copies, r.cut_faces, r.unresolved, after.pieces, volume, before.dt_crit,
        after.dt_crit, ratio, before.min_dihedral, after.min_dihedral, cut_ms, rebuild_ms));
    if (!a.out.empty()) {
      io::write_scene(cut_s, a.out, true);
      fmt::print("wrote {}\n", a.out);
    }
  }
  write_json_output(a.json, json_array(rows) + "\n");
  return 0;
}

}  // namespace

void add_cut_command(CLI::App& app, int& rc) {
  auto a = std::make_shared<CutArgs>();
  auto* cmd = app.add_subcommand(
      "cut", "Cut a scene's mesh along the surface a blade sweeps (origin + s edge + t sweep) and measure the cut");
  cmd->add_option("scene", a->scene, "Scene XML file, or @kidney")->required();
  cmd->add_option("--origin", a->origin, "A corner of the swept surface x,y,z (m)")->delimiter(',')->required();
  cmd->add_option("--edge", a->edge, "The blade's edge x,y,z (m)")->delimiter(',')->required();
  cmd->add_option("--sweep", a->sweep, "The blade's motion while it cuts x,y,z (m)")->delimiter(',')->required();
  cmd->add_option("--method", a->method, "snap | split | snap-split | all (compare the three)")
      ->default_val("snap-split");
  cmd->add_option("--snap", a->snap, "Snap distance, a fraction of a node's shortest edge")
      ->default_val(a->snap)
      ->check(real_number(0, 0.5));
  cmd->add_option("--touch", a->touch, "Closer than this fraction of its shortest edge, a node counts as on the cut")
      ->default_val(a->touch)
      ->check(real_number(0, 0.5));
  cmd->add_option("--keep", a->keep, "A snap leaves each element at least this fraction of its volume")
      ->default_val(a->keep)
      ->check(real_number(0, 1, true, true));
  cmd->add_option("-o,--out", a->out, "Write the cut scene here (mesh inline)")->check(output_file());
  cmd->add_option("--json", a->json, "Write the rows as JSON")->check(output_file());
  cmd->callback([a, &rc] { rc = run_cut(*a); });
}

}  // namespace tissue::app
