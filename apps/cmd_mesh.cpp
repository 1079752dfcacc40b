// tissue mesh: surface file(s) -> repair -> remesh -> TetGen -> quality
// report -> scene XML with one material per element set, a fixed base and a
// scripted tool pressing on the top. docs/meshing.md explains every step and
// the measurements behind the defaults.
//
// Defaults chosen for a first run of an unknown organ (document in README):
// - the nodes in the lowest 5% of the height (z) are fixed (the organ rests
//   on its support);
// - one scripted probe approaches the topmost surface point under the centre
//   of the bounding box from 1 cm above, presses min(5 mm, 10% of the
//   height), holds, and retracts;
// - an inclusion without its own material is ten times stiffer than the
//   tissue (a tumour), with the tissue's nu and rho.
//
// A built-in scene (@kidney, @kidney-visco, @kidney-fat) is written as built, its
// material's numbers from --E, --nu and --rho where given; the meshing
// options, which cannot apply to its built-in mesh, are refused by name.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>

#include "apps/commands.hpp"
#include "apps/interrupt.hpp"
#include "apps/options.hpp"
#include "core/tet.hpp"
#include "io/kidney.hpp"
#include "io/mesh_quality.hpp"
#include "io/organ_mesher.hpp"
#include "io/scene_xml.hpp"
#include "scene/checks.hpp"
#include "scene/text.hpp"
#include "scene/validate.hpp"

namespace tissue::app {
namespace {

struct MeshOptions {
  std::string surface, out, unit = "m";
  std::vector<std::string> inclusions;  ///< "file[:E=..,nu=..,rho=..]"
  bool no_repair = false;
  bool no_wrap = false;
  io::OrganMeshOptions pipeline;
  double E = 3000, nu = 0.45, rho = 1000;
  double fix_fraction = 0.05;
};

/// The corners of surface triangle t (m).
void corners(const io::SurfaceMesh& s, size_t t, Vec3<double> p[3]) {
  for (int k = 0; k < 3; ++k) {
    const index_t v = s.triangles[3 * t + k];
    p[k] = {s.vertices[3 * v], s.vertices[3 * v + 1], s.vertices[3 * v + 2]};
  }
}

/// Topmost surface point straight above or below (cx, cy), by a vertical
/// segment through the whole surface; throws if the vertical misses.
Vec3<double> top_point(const io::SurfaceMesh& s, double cx, double cy, double zlo, double zhi) {
  const Vec3<double> a{cx, cy, zhi + 1.0}, b{cx, cy, zlo - 1.0};
  double best = 2.0;
  for (size_t t = 0; t < s.triangles.size() / 3; ++t) {
    Vec3<double> p[3];
    corners(s, t, p);
    double bary[2];
    const double hit = segment_triangle(a, b, p[0], p[1], p[2], bary);
    if (hit >= 0 && hit < best) best = hit;
  }
  if (best > 1.0) throw std::runtime_error("the vertical through the bounding-box centre misses the surface");
  return a + best * (b - a);
}

/// "tumour.obj:E=30000,nu=0.45" -> file and material (defaults: ten times
/// the tissue's E, its nu and rho). Throws std::invalid_argument naming the
/// spec and the bad key or number.
std::pair<std::string, scene::Material> parse_inclusion(const std::string& spec, const MeshOptions& o, int k) {
  scene::Material m{.name = fmt::format("inclusion{}", k), .form = scene::Material::Form::YoungPoisson,
                    .a = 10 * o.E, .b = o.nu, .rho = o.rho};
  const size_t colon = spec.rfind(':');
  if (colon == std::string::npos || spec.find('=', colon) == std::string::npos) return {spec, m};
  const std::string file = spec.substr(0, colon);
  std::string rest = spec.substr(colon + 1);
  size_t start = 0;
  while (start <= rest.size()) {
    const size_t end = std::min(rest.find(',', start), rest.size());
    const std::string item = rest.substr(start, end - start);
    const size_t eq = item.find('=');
    if (eq == std::string::npos)
      throw std::invalid_argument(
          fmt::format("--inclusion {}: '{}' is not key=value (keys: E, nu, rho)", spec, item));
    const std::string key = item.substr(0, eq), value = item.substr(eq + 1);
    double v = 0;
    try {
      size_t used = 0;
      v = std::stod(value, &used);
      if (used != value.size()) throw std::invalid_argument(value);
    } catch (const std::exception&) {
      throw std::invalid_argument(fmt::format("--inclusion {}: {} = '{}' is not a number", spec, key, value));
    }
    if (key == "E") m.a = v;
    else if (key == "nu") m.b = v;
    else if (key == "rho") m.rho = v;
    else throw std::invalid_argument(fmt::format("--inclusion {}: unknown key '{}' (keys: E, nu, rho)", spec, key));
    start = end + 1;
  }
  return {file, m};
}

/// Refuses a surface given twice among the organ and its inclusions (the same
/// path, or two paths of one file): the second copy would be meshed as a body
/// overlapping the first, which the mesher reports as a self-intersecting
/// organ. Checked before any file is read.
void refuse_repeated_surfaces(const std::string& organ, const std::vector<std::string>& inclusion_files) {
  namespace fs = std::filesystem;
  const auto same = [](const std::string& a, const std::string& b) {
    if (a == b) return true;
    std::error_code ec, ec_a, ec_b;
    if (fs::equivalent(a, b, ec) && !ec) return true;
    const fs::path ca = fs::weakly_canonical(a, ec_a), cb = fs::weakly_canonical(b, ec_b);
    return !ec_a && !ec_b && ca == cb;  // two spellings of a path that does not exist (yet)
  };
  for (size_t k = 0; k < inclusion_files.size(); ++k) {
    const std::string& f = inclusion_files[k];
    if (same(f, organ))
      throw std::invalid_argument(fmt::format(
          "--inclusion {}: the file is the organ's surface ({}); an inclusion is a second, smaller body inside the "
          "organ: give a different file",
          f, organ));
    for (size_t j = 0; j < k; ++j)
      if (same(f, inclusion_files[j]))
        throw std::invalid_argument(fmt::format(
            "--inclusion {}: the file is given twice (inclusions {} and {}{}); two copies of one body overlap, "
            "which would be meshed as a self-intersecting organ: give each inclusion once",
            f, j + 1, k + 1, f == inclusion_files[j] ? "" : fmt::format(", as {}", inclusion_files[j])));
  }
}

std::string mm_text(const Vec3<double>& e) { return fmt::format("{:.1f} x {:.1f} x {:.1f} mm", 1e3 * e.x, 1e3 * e.y, 1e3 * e.z); }

/// The most triangles a --remesh-edge may ask of the organ's surface: the
/// tets a surface forces are a few times its triangle count
/// (io/tetgen_mesher.hpp), so 5e6 triangles already mean over 1e7 tets --
/// several GB for TetGen at io::kBytesPerTet and a model a thousand times
/// the built-in kidney's 8,400 tets, far beyond any interactive run.
constexpr double kMaxRemeshTriangles = 5e6;
/// The fewest triangles a --remesh-edge or --target-tets may leave: below
/// about 100 a surface keeps no shape (a cube's six faces alone take 12, a
/// sphere of 80 triangles is an icosahedron subdivided once), and the body
/// shrinks to the few tets that span it.
constexpr double kMinSurfaceCells = 100;

/// Area of a triangle mesh (m^2).
double surface_area(const io::SurfaceMesh& s) {
  double area = 0;
  for (size_t t = 0; t < s.triangles.size() / 3; ++t) {
    Vec3<double> p[3];
    corners(s, t, p);
    area += 0.5 * norm(cross(p[1] - p[0], p[2] - p[0]));
  }
  return area;
}

/// Refuses a --remesh-edge (> 0) whose triangle count on the organ's surface
/// -- its area over an equilateral triangle's, sqrt(3) / 4 edge^2 -- is
/// beyond kMaxRemeshTriangles (the memory and the model it would make) or
/// below kMinSurfaceCells (an edge as large as the body keeps no shape),
/// naming the estimate, the body's size and the edges that would be allowed.
void check_remesh_edge(const io::NamedSurface& organ, double edge) {
  if (!(edge > 0)) return;
  const double area = surface_area(organ.surface);
  const Vec3<double> e = io::surface_extents(organ.surface);
  const double per_triangle = std::sqrt(3.0) / 4, triangles = area / (per_triangle * edge * edge);
  if (triangles > kMaxRemeshTriangles)
    throw std::invalid_argument(fmt::format(
        "--remesh-edge {:g} m: the surface of {} ({:.4g} m^2) would be remeshed into about {:.3g} triangles, more "
        "than the {:.0e} allowed (the tets it forces would need more memory than a workstation has, and make a "
        "model far beyond an interactive run); use an edge of at least {:.3g} m",
        edge, organ.source, area, triangles, kMaxRemeshTriangles, std::sqrt(area / (per_triangle * kMaxRemeshTriangles))));
  if (triangles < kMinSurfaceCells)
    throw std::invalid_argument(fmt::format(
        "--remesh-edge {:g} m: the surface of {} ({:.4g} m^2, extent {}) would be remeshed into about {:.3g} "
        "triangles, fewer than the {:.0f} that represent a surface (an edge this long against the body keeps no "
        "shape); use an edge of at most {:.3g} m",
        edge, organ.source, area, mm_text(e), triangles, kMinSurfaceCells,
        std::sqrt(area / (per_triangle * kMinSurfaceCells))));
}

/// --remesh-edge: 0 (auto), -1 (never) or a length > 0; "" when `text` is one.
std::string remesh_edge_error(const std::string& text) {
  const auto v = scene::parse_real(text);
  if (!v) return fmt::format("'{}' is not a number", text);
  if (!std::isfinite(*v)) return fmt::format("{} is not a finite number", text);
  if (*v == 0 || *v == -1 || *v > 0) return "";
  return fmt::format("{} is not allowed: the edge is 0 (auto), -1 (never remesh) or a length > 0 m", text);
}

/// --target-tets: 0 (off) or a whole number of at least kMinSurfaceCells
/// (fewer tets cannot hold the surface's shape: the mesh shrinks to a few
/// tets spanning the body); "" when `text` is one.
std::string target_tets_error(const std::string& text) {
  constexpr long long most = std::numeric_limits<int>::max();
  const std::string allowed =
      fmt::format("--target-tets is 0 (off) or a whole number of tets in [{:.0f}, {}]", kMinSurfaceCells, most);
  if (std::string e = whole_number_error(text, 0, most); !e.empty()) return e + "; " + allowed;
  const long long n = *scene::parse_integer(text);
  if (n > 0 && n < kMinSurfaceCells)
    return fmt::format("{} tets are too few to represent a surface (the body would shrink to the few tets that span "
                       "it); {}",
                       n, allowed);
  return "";
}


/// The element sets of a meshed organ: one for the whole body, or one per TetGen region (the body and each
/// inclusion, in the order of s.materials), each reported with its volume and material. Returns each tet's
/// material index.
std::vector<index_t> element_sets(scene::Scene& s, const io::VolumeMesh& vol, const MeshOptions& o,
                                  const std::vector<std::string>& inclusion_files) {
  std::vector<index_t> tet_material(vol.n_tets(), 0);
  if (inclusion_files.empty()) {
    s.sets.push_back({.name = "all", .material = "tissue", .all = true, .elements = {}, .line = 0});
    return tet_material;
  }
  std::vector<scene::ElementSet> sets(inclusion_files.size() + 1);
  for (size_t k = 0; k < sets.size(); ++k) {
    sets[k].name = k == 0 ? "tissue" : s.materials[k].name;
    sets[k].material = s.materials[k].name;
  }
  for (index_t e = 0; e < vol.n_tets(); ++e) {
    const int r = vol.tet_region.at(e);
    if (r < 0 || size_t(r) >= sets.size())
      throw io::MeshError(fmt::format("{}: TetGen gave tet {} the unknown region {}", o.surface, e, r));
    sets[r].elements.push_back(e);
    tet_material[e] = r;
  }
  for (size_t k = 0; k < sets.size(); ++k) {
    if (sets[k].elements.empty())
      throw io::MeshError(fmt::format("{}: no tet landed in {} (is it thinner than the tets?)",
                                      k == 0 ? o.surface : inclusion_files[k - 1], sets[k].name));
    double v = 0;
    for (index_t e : sets[k].elements) {
      Vec3<double> X[4];
      for (int a = 0; a < 4; ++a) {
        const index_t c = vol.tets[4 * e + a];
        X[a] = {vol.nodes[3 * c], vol.nodes[3 * c + 1], vol.nodes[3 * c + 2]};
      }
      double dN[12];
      v += std::fabs(tet_shape_gradients(X, dN));
    }
    fmt::print("  element set '{}': {} tets, {:.4g} cm^3, material E = {:.4g} Pa, nu = {:.4g}, rho = {:.4g}\n",
               sets[k].name, sets[k].elements.size(), 1e6 * v, s.materials[k].a, s.materials[k].b, s.materials[k].rho);
  }
  s.sets = std::move(sets);
  return tet_material;
}

/// What the mesher did and the quality report, with a warning when the count is off its target.
void report_mesh(const io::OrganMesh& result, const MeshOptions& o, std::size_t n_inclusions,
                 const io::QualityReport& q) {
  const io::VolumeMesh& vol = result.mesh;
  if (result.mesher == io::Mesher::Mesh3)
    fmt::print("meshed: {} nodes, {} tets ({} Mesh_3 runs, sliver perturbation and exudation)\n", vol.n_nodes(),
               vol.n_tets(), vol.runs);
  else
    fmt::print("meshed: {} nodes, {} tets ({} TetGen runs, switches {})\n", vol.n_nodes(), vol.n_tets(), vol.runs,
               io::tetgen_switches([&] {
                 io::MeshingOptions m = o.pipeline.meshing;
                 m.max_volume = vol.max_volume;
                 m.regions.resize(n_inclusions);
                 return m;
               }(), o.surface));
  if (o.pipeline.meshing.target_tets > 0) {
    const double off = double(vol.n_tets()) / o.pipeline.meshing.target_tets - 1;
    std::fflush(stdout);
    if (std::fabs(off) > io::kTargetPromise)
      fmt::print(stderr, "tissue mesh: warning: {} tets is {:+.0f} % off the target {}\n", vol.n_tets(), 100 * off,
                 o.pipeline.meshing.target_tets);
  }
  fmt::print("quality:\n{}", q.summary());
}

/// The written scene's support (the nodes below fix_fraction of the height) and its probe, pressing the
/// top of the organ's surface above the middle of its footprint.
void support_and_probe(scene::Scene& s, const io::SurfaceMesh& organ, double fix_fraction) {
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (size_t i = 0; i < s.nodes.size(); ++i) {
    lo[i % 3] = std::min(lo[i % 3], s.nodes[i]);
    hi[i % 3] = std::max(hi[i % 3], s.nodes[i]);
  }
  scene::Constraint base;
  base.kind = scene::Constraint::Kind::Plane;
  base.point[2] = lo[2] + fix_fraction * (hi[2] - lo[2]);
  base.normal[2] = -1;  // fixes (x - point) . normal >= 0: the nodes below the plane
  s.constraints.push_back(base);
  const double height = hi[2] - lo[2];
  const Vec3<double> target = top_point(organ, 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2], hi[2]);
  scene::Tool tool;
  tool.radius = 2e-3;
  tool.path = press_path(target, {0, 0, -1}, std::min(5e-3, 0.1 * height), 1e-2);
  s.tools.push_back(tool);
  fmt::print("body: extent {}; fixed base below z = {:.4g} m; tool presses at ({:.4g}, {:.4g}, {:.4g}) m\n",
             mm_text({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]}), base.point[2], target.x, target.y, target.z);
}

scene::Scene make_scene(MeshOptions& o) {
  const auto start = std::chrono::steady_clock::now();
  o.pipeline.meshing.progress = [start](const std::string& line) {
    fmt::print("  [{:6.1f} s] {}\n", std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
               line);
    std::fflush(stdout);
  };
  o.pipeline.repair = !o.no_repair;
  o.pipeline.wrap = !o.no_wrap;
  // materials first: refuse bad numbers before any work
  scene::Scene s;
  s.source = "tissue mesh";
  s.materials.push_back({.name = "tissue", .form = scene::Material::Form::YoungPoisson, .a = o.E, .b = o.nu, .rho = o.rho});
  std::vector<std::string> inclusion_files;
  for (size_t k = 0; k < o.inclusions.size(); ++k) {
    auto [file, m] = parse_inclusion(o.inclusions[k], o, int(k + 1));
    inclusion_files.push_back(file);
    s.materials.push_back(m);
  }
  for (const scene::Material& m : s.materials) scene::validate_material(s, m);
  refuse_repeated_surfaces(o.surface, inclusion_files);

  const double unit = io::parse_unit(o.unit);
  auto read = [&](const std::string& file) {
    fmt::print("reading {} (unit: {}, {} m per file unit)\n", file, o.unit, unit);
    index_t merged = 0;
    io::NamedSurface n{io::load_surface(file, unit, &merged), file};
    const Vec3<double> e = io::surface_extents(n.surface);
    fmt::print("  {} vertices ({} duplicates welded), {} triangles; extent {}\n", n.surface.n_vertices(), merged,
               n.surface.n_triangles(), mm_text(e));
    std::fflush(stdout);
    if (const std::string w = io::unit_warning(std::max({e.x, e.y, e.z}), o.unit); !w.empty())
      fmt::print(stderr, "tissue mesh: {}: {}\n", file, w);
    return n;
  };
  io::NamedSurface organ = read(o.surface);
  check_remesh_edge(organ, o.pipeline.remesh_edge);  // before any remeshing
  std::vector<io::NamedSurface> inclusions;
  for (const std::string& f : inclusion_files) inclusions.push_back(read(f));
  const io::OrganMesh result = io::mesh_organ(organ, inclusions, o.pipeline);

  s.source = o.out;
  s.nodes = result.mesh.nodes;
  s.tets = result.mesh.tets;
  const std::vector<index_t> tet_material = element_sets(s, result.mesh, o, inclusion_files);
  std::vector<MaterialParams> params;
  for (const scene::Material& m : s.materials) params.push_back(m.params());
  const scene::Solver solver;
  report_mesh(result, o, inclusions.size(),
              io::mesh_quality(result.mesh, params, tet_material, solver.tick, solver.dt_safety, solver.mass_scaling));
  support_and_probe(s, organ.surface, o.fix_fraction);
  return s;
}

/// Whether an option of tissue mesh applies to a built-in scene: its mesh,
/// fixed nodes and tool are built in (docs/kidney.md); only the output and
/// its material's numbers can be chosen.
bool applies_to_builtin(const std::string& option) {
  return option == "surface" || option == "--output" || option == "--E" || option == "--nu" || option == "--rho";
}

/// `tissue mesh @kidney`: the built-in scene with the material options given
/// (--E, --nu, --rho; for @kidney-visco the instantaneous moduli) in place of
/// its material's, checked as a surface's material is. Every other option
/// given (--unit, --quality, --inclusion, ...) would be ignored: refused by
/// name before the scene is built.
scene::Scene builtin_mesh_scene(const CLI::App& cmd, const MeshOptions& o) {
  std::string ignored;
  int n_ignored = 0;
  for (const CLI::Option* opt : cmd.get_options()) {
    if (opt->count() == 0 || applies_to_builtin(opt->get_name())) continue;
    ignored += (n_ignored++ > 0 ? ", " : "") + opt->get_name();
  }
  if (n_ignored > 0)
    throw std::invalid_argument(fmt::format(
        "{}: {} {} to meshing a surface file, not to a built-in scene, whose mesh is built in (docs/kidney.md); "
        "of the options only -o, --E, --nu and --rho apply to it (the last three set its material)",
        o.surface, ignored, n_ignored == 1 ? "applies" : "apply"));
  scene::Scene s = *io::builtin_scene(o.surface);
  if (s.materials.size() > 1)
    for (const char* opt : {"--E", "--nu", "--rho"})
      if (cmd.get_option(opt)->count() > 0)
        throw std::invalid_argument(fmt::format(
            "{}: {} sets the material of a built-in scene of one; {} has {} (edit their numbers in the scene "
            "XML that -o writes)",
            o.surface, opt, o.surface, s.materials.size()));
  for (scene::Material& m : s.materials) {  // the built-in materials are given as E and nu
    if (cmd.get_option("--E")->count() > 0) m.a = o.E;
    if (cmd.get_option("--nu")->count() > 0) m.b = o.nu;
    if (cmd.get_option("--rho")->count() > 0) m.rho = o.rho;
    scene::validate_material(s, m);
    fmt::print("material '{}': E = {:.4g} Pa, nu = {:.4g}, rho = {:.4g} kg/m^3\n", m.name, m.a, m.b, m.rho);
  }
  return s;
}

}  // namespace

void add_mesh_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand("mesh", "Repair, remesh and tetrahedralise a surface (OBJ, STL, PLY, OFF, 3DS, ...) into a scene");
  auto o = std::make_shared<MeshOptions>();
  io::MeshingOptions& m = o->pipeline.meshing;
  m.min_dihedral = io::kDefaultMinDihedral;
  m.optimise = io::kDefaultOptimise;
  cmd->add_option("surface", o->surface,
                  "Surface file, or @kidney / @kidney-visco / @kidney-fat to write a built-in kidney scene (with -o, "
                  "--E, --nu and --rho only; @kidney-fat takes -o alone)")
      ->required();
  cmd->add_option("-o,--output", o->out, "Scene XML to write")->required()->check(output_file());  // before the meshing
  cmd->add_option("--unit", o->unit, "Length unit of the surface file(s): m, cm or mm")->default_val("m");
  cmd->add_option("--inclusion", o->inclusions,
                  "Closed surface inside the organ meshed as its own element set: FILE[:E=..,nu=..,rho=..] "
                  "(default: 10 x the tissue's E); repeatable");
  cmd->add_option("--mesher", o->pipeline.mesher,
                  "Volume mesher: cgal (Mesh_3 with sliver perturbation and exudation), tetgen (quality bounds; "
                  "inclusions), auto (cgal for a body alone with a size, else tetgen)")
      ->transform(CLI::CheckedTransformer(std::map<std::string, io::Mesher>{
          {"auto", io::Mesher::Auto}, {"tetgen", io::Mesher::TetGen}, {"cgal", io::Mesher::Mesh3}}))
      ->default_str("auto");
  cmd->add_flag("--no-repair", o->no_repair, "Refuse damaged surfaces instead of repairing them");
  cmd->add_flag("--no-wrap", o->no_wrap,
                "Mesh_3: mesh the repaired surface as it is, not its alpha wrap at half the target edge (grooves and "
                "folds narrower than the elements then force smaller ones)");
  cmd->add_option("--remesh-edge", o->pipeline.remesh_edge,
                  "Remesh the surfaces to this edge length (m); 0 = auto (when finer than the target needs), -1 = never")
      ->default_val(0)
      ->check(CLI::Validator([](std::string& t) { return remesh_edge_error(t); }, "0 | -1 | EDGE > 0"));
  cmd->add_option("--quality", m.quality, "TetGen radius-edge ratio bound (q; >= 1, or 0 for none)")->default_val(1.414);
  cmd->add_option("--min-dihedral", m.min_dihedral, "TetGen minimum dihedral angle bound (degrees, q/..)")
      ->default_val(io::kDefaultMinDihedral);
  cmd->add_option("--optimise", m.optimise, "TetGen optimisation level (O, 0..10)")->default_val(io::kDefaultOptimise);
  cmd->add_option("--max-volume", m.max_volume, "Largest tet volume (m^3; 0 = no bound)")->default_val(0);
  cmd->add_option("--target-tets", m.target_tets, "Aim at about this many tets, within 15 % (0 = off)")
      ->default_val(0)
      ->check(CLI::Validator([](std::string& t) { return target_tets_error(t); }, "0 | TETS >= 100"));
  cmd->add_option("--E", o->E, "Young's modulus (Pa; a built-in scene's too)")->default_val(3000);
  cmd->add_option("--nu", o->nu, "Poisson's ratio (a built-in scene's too)")->default_val(0.45);
  cmd->add_option("--rho", o->rho, "Density (kg/m^3; a built-in scene's too)")->default_val(1000);
  cmd->callback([o, cmd, &rc] {
    // Ctrl-C or SIGTERM: TetGen's run stops at once (io::MeshInterrupted, 128 + the signal); an in-process
    // stage (remeshing, Mesh_3) ends first, and then nothing is written
    InterruptGuard interrupt;
    if (o->pipeline.meshing.quality == 0 && !io::is_builtin_scene(o->surface))
      fmt::print(stderr, "tissue mesh: warning: --quality 0: TetGen meshes with no radius-edge ratio bound "
                         "(poorly shaped tets, and a smaller stable step, are then possible)\n");
    scene::Scene s = io::is_builtin_scene(o->surface) ? builtin_mesh_scene(*cmd, *o) : make_scene(*o);
    if (InterruptGuard::requested())
      throw io::MeshInterrupted(InterruptGuard::signal(),
                                fmt::format("{}: meshing stopped by {}; {} was not written", o->surface,
                                            InterruptGuard::signal_name(), o->out));
    io::write_scene(s, o->out, true);
    fmt::print("wrote {} ({} tets)\n", o->out, s.tets.size() / 4);
    rc = 0;
  });
}

}  // namespace tissue::app
