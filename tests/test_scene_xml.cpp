// The scene's file formats: XML scenes (round trip inline and with a mesh
// file, every material form, constraints resolved to the right nodes, the
// file:line of syntax errors), TetGen .node/.ele pairs and tool-path CSVs.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <regex>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "core/box_mesh.hpp"
#include "io/path_csv.hpp"
#include "io/scene_xml.hpp"
#include "io/tetgen_files.hpp"
#include "scene/text.hpp"
#include "scene/validate.hpp"
#include "tests/temp_dir.hpp"

namespace tissue {
namespace {

namespace fs = std::filesystem;
using testing_support::TempDir;
using io::format_scene;
using io::parse_scene;
using io::read_scene;
using io::write_scene;
using scene::Constraint;
using scene::Material;
using scene::Scene;
using scene::SceneError;


/// 1-based line of the first occurrence of `needle` in `text`.
int line_of(const std::string& text, const std::string& needle) {
  const size_t at = text.find(needle);
  EXPECT_NE(at, std::string::npos) << needle;
  return 1 + int(std::count(text.begin(), text.begin() + std::min(at, text.size()), '\n'));
}

/// Success when `f` throws an exception of type E whose message contains every part.
template <class E, class F>
testing::AssertionResult throws_with(F&& f, std::initializer_list<std::string> parts) {
  try {
    f();
  } catch (const E& e) {
    const std::string msg = e.what();
    for (const std::string& p : parts)
      if (msg.find(p) == std::string::npos)
        return testing::AssertionFailure() << "message \"" << msg << "\" lacks \"" << p << "\"";
    return testing::AssertionSuccess();
  } catch (const std::exception& e) {
    return testing::AssertionFailure() << "threw another type: " << e.what();
  }
  return testing::AssertionFailure() << "no error";
}

testing::AssertionResult xml_error(const std::string& xml, std::initializer_list<std::string> parts) {
  return throws_with<SceneError>([&] { (void)parse_scene(xml, "scene.xml", ""); }, parts);
}

/// Every field of two scenes except source lines, source and mesh_file.
void expect_same_scene(const Scene& a, const Scene& b) {
  EXPECT_EQ(a.nodes, b.nodes);
  EXPECT_EQ(a.tets, b.tets);
  ASSERT_EQ(a.materials.size(), b.materials.size());
  for (size_t k = 0; k < a.materials.size(); ++k) {
    const Material &x = a.materials[k], &y = b.materials[k];
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.form, y.form) << x.name;
    EXPECT_EQ(x.a, y.a) << x.name;
    EXPECT_EQ(x.b, y.b) << x.name;
    EXPECT_EQ(x.rho, y.rho) << x.name;
  }
  ASSERT_EQ(a.sets.size(), b.sets.size());
  for (size_t k = 0; k < a.sets.size(); ++k) {
    EXPECT_EQ(a.sets[k].name, b.sets[k].name);
    EXPECT_EQ(a.sets[k].material, b.sets[k].material);
    EXPECT_EQ(a.sets[k].all, b.sets[k].all);
    EXPECT_EQ(a.sets[k].elements, b.sets[k].elements);
  }
  ASSERT_EQ(a.constraints.size(), b.constraints.size());
  for (size_t k = 0; k < a.constraints.size(); ++k) {
    const Constraint &x = a.constraints[k], &y = b.constraints[k];
    EXPECT_EQ(x.kind, y.kind) << "constraint " << k;
    EXPECT_EQ(x.nodes, y.nodes) << "constraint " << k;
    if (x.kind == Constraint::Kind::Box)
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(x.lo[c], y.lo[c]);
        EXPECT_EQ(x.hi[c], y.hi[c]);
      }
    if (x.kind == Constraint::Kind::Plane)
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(x.point[c], y.point[c]);
        EXPECT_EQ(x.normal[c], y.normal[c]);
      }
  }
  ASSERT_EQ(a.tools.size(), b.tools.size());
  for (size_t k = 0; k < a.tools.size(); ++k) {
    const scene::Tool &x = a.tools[k], &y = b.tools[k];
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.kind, y.kind);
    EXPECT_EQ(x.cut_resistance, y.cut_resistance);
    EXPECT_EQ(x.cut_delay, y.cut_delay);
    EXPECT_EQ(x.radius, y.radius);
    EXPECT_EQ(x.shaft, y.shaft);
    EXPECT_EQ(x.friction, y.friction);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(x.direction[c], y.direction[c]);
    EXPECT_EQ(x.device, y.device);
    EXPECT_EQ(x.path_file, y.path_file);
    ASSERT_EQ(x.path.size(), y.path.size()) << x.name;
    for (size_t w = 0; w < x.path.size(); ++w) {
      EXPECT_EQ(x.path[w].t, y.path[w].t);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(x.path[w].p[c], y.path[w].p[c]);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(x.path[w].axis[c], y.path[w].axis[c]);
      EXPECT_EQ(x.path[w].grasp, y.path[w].grasp);
    }
  }
  const scene::Solver &u = a.solver, &v = b.solver;
  EXPECT_EQ(u.backend, v.backend);
  EXPECT_EQ(u.precision, v.precision);
  EXPECT_EQ(u.dt, v.dt);
  EXPECT_EQ(u.dt_safety, v.dt_safety);
  EXPECT_EQ(u.mass_scaling, v.mass_scaling);
  EXPECT_EQ(u.damping, v.damping);
  EXPECT_EQ(u.depth, v.depth);
  EXPECT_EQ(u.tick, v.tick);
  EXPECT_EQ(u.residual_tol, v.residual_tol);
  EXPECT_EQ(u.kinetic_tol, v.kinetic_tol);
  EXPECT_EQ(u.ianp, v.ianp);
  EXPECT_EQ(u.lip_contact, v.lip_contact);
  EXPECT_EQ(u.step_guard, v.step_guard);
}

/// A scene using every feature, on a 3 x 2 x 2 box of 0.03 x 0.02 x 0.017 m
/// (coordinates such as 0.017 / 2 that decimal text must carry exactly).
Scene rich_scene() {
  Scene s;
  s.source = "rich.xml";
  ModelInput in;
  box_mesh(in, 3, 2, 2, 0.03, 0.02, 0.017);
  s.nodes = in.nodes;
  s.tets = in.tets;
  s.materials.push_back({.name = "brain", .form = Material::Form::YoungPoisson, .a = 3000, .b = 0.45, .rho = 1000});
  s.materials.push_back({.name = "capsule", .form = Material::Form::ShearBulk, .a = 1234.5, .b = 6.7e4, .rho = 1040});
  s.materials.push_back({.name = "fat & vessel", .form = Material::Form::Lame, .a = 1.0 / 3, .b = 2e3, .rho = 950});
  const index_t ne = static_cast<index_t>(s.tets.size() / 4);
  scene::ElementSet a, b, c;
  a.name = "cortex", a.material = "brain";
  b.name = "rim", b.material = "capsule";
  c.name = "hilum", c.material = "fat & vessel";
  for (index_t e = 0; e < ne; ++e) (e % 3 == 0 ? a : e % 3 == 1 ? b : c).elements.push_back(e);
  s.sets = {a, b, c};
  Constraint nodes;
  nodes.nodes = {0, 5, 7};
  Constraint box;
  box.kind = Constraint::Kind::Box;
  box.lo[0] = -1e-3, box.lo[1] = -1e-3, box.lo[2] = -1e-3;
  box.hi[0] = 0.03, box.hi[1] = 0.0201, box.hi[2] = 1e-3;
  Constraint plane;
  plane.kind = Constraint::Kind::Plane;
  plane.point[0] = 0.03, plane.point[1] = 0.01, plane.point[2] = 0.0085;
  plane.normal[0] = 1, plane.normal[1] = 0.1, plane.normal[2] = 0;
  s.constraints = {nodes, box, plane};
  scene::Tool probe;
  probe.name = "probe";
  probe.radius = 1.5e-3;
  probe.shaft = 0.025;
  probe.friction = 0.35;
  probe.direction = {0.1, 0, 1};
  probe.path = press_path({0.015, 0.01, 0.017}, {0, 0, -1}, 3e-3, 1e-2);
  probe.path[2].grasp = true;
  probe.path[3].axis = {0, 0.6, 0.8};
  scene::Tool mouse;
  mouse.name = "hand";
  mouse.device = "mouse";
  mouse.radius = 2e-3;
  s.tools = {probe, mouse};
  s.solver.backend = "cuda";
  s.solver.precision = Precision::Double;
  s.solver.dt = 2.5e-5;
  s.solver.dt_safety = 0.4;
  s.solver.mass_scaling = 0.015;
  s.solver.damping = 12.5;
  s.solver.depth = kDepthAll;
  s.solver.tick = 5e-4;
  s.solver.residual_tol = 2e-4;
  s.solver.kinetic_tol = 3e-7;
  s.solver.ianp = false;
  s.solver.lip_contact = true;
  s.solver.step_guard = false;
  return s;
}

// ---- round trip ------------------------------------------------------------

TEST(SceneXml, RoundTripInlineMesh) {
  TempDir dir;
  const Scene s = rich_scene();
  write_scene(s, dir.file("rich.xml"), true);
  EXPECT_FALSE(fs::exists(dir.file("rich.node")));
  const Scene r = read_scene(dir.file("rich.xml"));
  EXPECT_EQ(r.source, dir.file("rich.xml"));
  EXPECT_TRUE(r.mesh_file.empty());
  expect_same_scene(s, r);
  EXPECT_NO_THROW(scene::validate(r));
  // writing what was read gives the same text
  EXPECT_EQ(format_scene(r, ""), format_scene(s, ""));
}

TEST(SceneXml, RoundTripWithMeshAndPathFiles) {
  TempDir dir;
  Scene s = rich_scene();
  s.tools[0].path_file = "probe.csv";
  write_scene(s, dir.file("rich.xml"), false);
  ASSERT_TRUE(fs::exists(dir.file("rich.node")));
  ASSERT_TRUE(fs::exists(dir.file("rich.ele")));
  ASSERT_TRUE(fs::exists(dir.file("probe.csv")));
  std::ifstream xml(dir.file("rich.xml"));
  const std::string text((std::istreambuf_iterator<char>(xml)), {});
  EXPECT_NE(text.find("<mesh file=\"rich.node\""), std::string::npos) << text;
  EXPECT_NE(text.find("path=\"probe.csv\""), std::string::npos) << text;
  EXPECT_EQ(text.find("<nodes>"), std::string::npos);
  EXPECT_EQ(text.find("<waypoint"), std::string::npos);

  // the mesh and path files resolve against the scene file's folder, not the working folder
  const Scene r = read_scene(dir.file("rich.xml"));
  EXPECT_EQ(r.mesh_file, "rich.node");
  expect_same_scene(s, r);
}

TEST(SceneXml, NamedMeshFileIsKept) {
  TempDir dir;
  Scene s = rich_scene();
  s.mesh_file = "organ.node";
  write_scene(s, dir.file("scene.xml"), false);
  EXPECT_TRUE(fs::exists(dir.file("organ.node")));
  EXPECT_TRUE(fs::exists(dir.file("organ.ele")));
  const Scene r = read_scene(dir.file("scene.xml"));
  EXPECT_EQ(r.mesh_file, "organ.node");
  expect_same_scene(s, r);
}

TEST(SceneXml, SourceLinesAreRecorded) {
  TempDir dir;
  write_scene(rich_scene(), dir.file("rich.xml"), true);
  std::ifstream in(dir.file("rich.xml"));
  const std::string text((std::istreambuf_iterator<char>(in)), {});
  const Scene r = read_scene(dir.file("rich.xml"));
  EXPECT_EQ(r.mesh_line, line_of(text, "<mesh>"));
  EXPECT_EQ(r.materials[1].line, line_of(text, "<material name=\"capsule\""));
  EXPECT_EQ(r.sets[2].line, line_of(text, "<element-set name=\"hilum\""));
  EXPECT_EQ(r.constraints[2].line, line_of(text, "<fixed plane-point"));
  EXPECT_EQ(r.tools[1].line, line_of(text, "<tool name=\"hand\""));
  EXPECT_EQ(r.solver.line, line_of(text, "<solver"));
}

// ---- materials and defaults ------------------------------------------------

const char* kTet = R"(<mesh>
    <nodes>0 0 0  1 0 0  0 1 0  0 0 1</nodes>
    <elements>0 1 2 3</elements>
  </mesh>)";

TEST(SceneXml, EachMaterialForm) {
  const std::string xml = fmt::format(R"(<tissue-scene version="1">
  {}
  <material name="yp" E="3000" nu="0.25" rho="1000"/>
  <material name="sb" mu="1200" K="2000" rho="1100"/>
  <material name="lame" lambda="1200" mu="1200" rho="1200"/>
  <element-set material="lame" elements="all"/>
</tissue-scene>)",
                                      kTet);
  const Scene s = parse_scene(xml, "m.xml", "");
  ASSERT_EQ(s.materials.size(), 3u);
  EXPECT_EQ(s.materials[0].form, Material::Form::YoungPoisson);
  EXPECT_EQ(s.materials[1].form, Material::Form::ShearBulk);
  EXPECT_EQ(s.materials[2].form, Material::Form::Lame);
  for (const Material& m : s.materials) {
    const MaterialParams p = m.params();
    EXPECT_DOUBLE_EQ(p.mu, 1200) << m.name;
    EXPECT_DOUBLE_EQ(p.K, 2000) << m.name;
  }
  EXPECT_EQ(s.materials[2].rho, 1200);
  EXPECT_EQ(s.sets[0].name, "lame");  // defaults to the material's name
  EXPECT_TRUE(s.sets[0].all);
  const ModelInput in = scene::to_model_input(s);
  EXPECT_EQ(in.elem_material, std::vector<index_t>{2});
}

TEST(SceneXml, SolverDefaultsAndKeywords) {
  const std::string xml = fmt::format(R"(<tissue-scene>{}
  <material name="m" E="3000" nu="0.45" rho="1000"/>
  <element-set material="m" elements="0"/>
  <solver dt="auto" damping="auto" depth="all" precision="double"/>
</tissue-scene>)",
                                      kTet);
  const Scene s = parse_scene(xml, "s.xml", "");
  const scene::Solver def;
  EXPECT_FALSE(s.solver.dt);
  EXPECT_FALSE(s.solver.damping);
  EXPECT_EQ(s.solver.depth, kDepthAll);
  EXPECT_EQ(s.solver.precision, Precision::Double);
  EXPECT_EQ(s.solver.backend, def.backend);
  EXPECT_EQ(s.solver.dt_safety, def.dt_safety);
  EXPECT_EQ(s.solver.tick, def.tick);
  EXPECT_TRUE(s.solver.ianp);
  EXPECT_FALSE(s.solver.lip_contact);
  EXPECT_TRUE(s.solver.step_guard);
  const Scene plain = parse_scene(fmt::format(R"(<tissue-scene>{}
  <solver depth="7" dt="1e-5" damping="0"/></tissue-scene>)",
                                              kTet),
                                  "s.xml", "");
  EXPECT_EQ(plain.solver.depth, 7);
  EXPECT_EQ(plain.solver.dt, 1e-5);
  EXPECT_EQ(plain.solver.damping, 0);
}

// The in-memory "auto" of dt, damping and depth is no number: the numbers
// that once stood for it (dt 0, damping -1, depth -1 / -2) are refused from
// a file with the rule, so a typo cannot silently mean "auto".
TEST(SceneXml, SentinelsAreNotAcceptedAsInput) {
  const auto scene_with = [&](const std::string& solver) {
    return fmt::format("<tissue-scene>{}\n<material name=\"m\" E=\"3000\" nu=\"0.45\" rho=\"1000\"/>\n"
                       "<element-set material=\"m\" elements=\"all\"/>\n<solver {}/></tissue-scene>",
                       kTet, solver);
  };
  const auto rule_error = [&](const std::string& solver, std::initializer_list<std::string> parts) {
    return throws_with<SceneError>([&] { validate(parse_scene(scene_with(solver), "scene.xml", "")); }, parts);
  };
  EXPECT_TRUE(rule_error(R"(damping="-1")", {"scene.xml:7: ", "damping = -1 1/s must be >= 0 (or \"auto\")"}));
  EXPECT_TRUE(rule_error(R"(dt="0")", {"scene.xml:7: ", "dt = 0 s must be > 0 (or \"auto\""}));
  EXPECT_TRUE(xml_error(scene_with(R"(depth="-1")"), {"scene.xml:7: ", "depth = -1 must be >= 0", "\"all\""}));
  EXPECT_TRUE(xml_error(scene_with(R"(depth="-2")"), {"scene.xml:7: ", "depth = -2 must be >= 0", "\"auto\""}));
  EXPECT_TRUE(xml_error(scene_with(R"(lip-contact="yes")"), {"scene.xml:7: ", "lip-contact = 'yes' must be true or false"}));
  EXPECT_TRUE(parse_scene(scene_with(R"(lip-contact="true")"), "scene.xml", "").solver.lip_contact);
  EXPECT_TRUE(xml_error(scene_with(R"(step-guard="1")"), {"scene.xml:7: ", "step-guard = '1' must be true or false"}));
  EXPECT_FALSE(parse_scene(scene_with(R"(step-guard="false")"), "scene.xml", "").solver.step_guard);
  const Scene s = parse_scene(scene_with(R"(damping="auto" dt="auto" depth="auto")"), "scene.xml", "");
  EXPECT_FALSE(s.solver.damping);
  EXPECT_FALSE(s.solver.dt);
  EXPECT_EQ(s.solver.depth, kDepthAuto);
  EXPECT_NO_THROW(validate(s));
}

// depth="auto" (the adaptive region, core/scheduler.hpp) reads as kDepthAuto,
// validates, reaches the Scheduler's settings and is written back as "auto".
TEST(SceneXml, AdaptiveDepth) {
  const std::string xml = fmt::format(R"(<tissue-scene>{}
  <material name="m" E="3000" nu="0.45" rho="1000"/>
  <element-set material="m" elements="0"/>
  <solver depth="auto"/>
</tissue-scene>)",
                                      kTet);
  const Scene s = parse_scene(xml, "s.xml", "");
  EXPECT_EQ(s.solver.depth, kDepthAuto);
  EXPECT_EQ(scene::scheduler_settings(s).depth, kDepthAuto);
  const Scene back = parse_scene(io::format_scene(s, ""), "back.xml", "");
  EXPECT_EQ(back.solver.depth, kDepthAuto);
}

// ---- constraints resolved on a box mesh ------------------------------------

TEST(SceneXml, ConstraintsSelectTheRightNodes) {
  // 3 x 2 x 2 cells on 0.3 x 0.2 x 0.2 m: grid coordinates like 0.3 * 3 / 3
  // carry rounding, which the selection tolerance absorbs.
  const int nx = 3, ny = 2, nz = 2;
  ModelInput box;
  box_mesh(box, nx, ny, nz, 0.3, 0.2, 0.2);
  std::string nodes, elems;
  for (size_t i = 0; i < box.nodes.size(); i += 3)
    nodes += fmt::format("      {} {} {}\n", box.nodes[i], box.nodes[i + 1], box.nodes[i + 2]);
  for (index_t v : box.tets) elems += fmt::format("{} ", v);
  const std::string xml = fmt::format(R"(<tissue-scene version="1">
  <mesh><nodes>
{}</nodes><elements>{}</elements></mesh>
  <material name="m" E="3000" nu="0.45" rho="1000"/>
  <element-set name="all" material="m" elements="all"/>
  <fixed nodes="{} {}"/>
  <fixed box-min="-1 -1 -1" box-max="1 1 0"/>
  <fixed plane-point="0.3 0 0" plane-normal="2 0 0"/>
</tissue-scene>)",
                                      nodes, elems, box_node(nx, ny, 1, 1, 2), box_node(nx, ny, 0, 2, 1));
  const Scene s = parse_scene(xml, "box.xml", "");
  ASSERT_EQ(s.constraints.size(), 3u);
  EXPECT_EQ(s.constraints[0].kind, Constraint::Kind::Nodes);
  EXPECT_EQ(s.constraints[1].kind, Constraint::Kind::Box);
  EXPECT_EQ(s.constraints[2].kind, Constraint::Kind::Plane);

  std::vector<std::uint8_t> expect((nx + 1) * (ny + 1) * (nz + 1), 0);
  expect[box_node(nx, ny, 1, 1, 2)] = expect[box_node(nx, ny, 0, 2, 1)] = 1;  // the id list
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) expect[box_node(nx, ny, i, j, 0)] = 1;  // the box: bottom face z = 0
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j) expect[box_node(nx, ny, nx, j, k)] = 1;  // the plane: face x = 0.3
  const ModelInput in = scene::to_model_input(s);
  EXPECT_EQ(in.fixed, expect);
  EXPECT_EQ(std::count(in.fixed.begin(), in.fixed.end(), 1), 2 + 12 + 9 - 3);  // the box and plane share 3
}

TEST(SceneXml, ObliquePlaneFixesTheNodesOnItsNormalSide) {
  ModelInput box;
  box_mesh(box, 2, 2, 2, 1, 1, 1);
  Scene s;
  s.nodes = box.nodes;
  s.tets = box.tets;
  s.materials.push_back({.name = "m", .a = 3000, .b = 0.3});
  s.sets.push_back({.name = "all", .material = "m", .all = true, .elements = {}});
  Constraint c;
  c.kind = Constraint::Kind::Plane;
  c.point[0] = 0.5;  // x + y >= 0.5 + 0.5: on or above the diagonal plane through (0.5, 0.5, .)
  c.point[1] = 0.5;
  c.normal[0] = c.normal[1] = 1;
  c.normal[2] = 0;
  s.constraints.push_back(c);
  const ModelInput in = scene::to_model_input(s);
  for (int k = 0; k <= 2; ++k)
    for (int j = 0; j <= 2; ++j)
      for (int i = 0; i <= 2; ++i)
        EXPECT_EQ(in.fixed[box_node(2, 2, i, j, k)], i + j >= 2 ? 1 : 0) << i << " " << j << " " << k;
}

// ---- syntax errors ---------------------------------------------------------

TEST(SceneXml, MalformedXmlGivesParserMessageAndLine) {
  const std::string xml = R"(<?xml version="1.0"?>
<tissue-scene version="1">
  <mesh>
    <nodes>0 0 0 1 0 0 0 1 0 0 0 1</nodes>
    <elements>0 1 2 3</element>
  </mesh>
</tissue-scene>)";
  EXPECT_TRUE(xml_error(xml, {"scene.xml:5: ", "malformed XML", "mismatch"}));
  EXPECT_TRUE(xml_error("<tissue-scene>\n<mesh>\n<material name=\"a\" E=3000/>\n</mesh></tissue-scene>",
                        {"scene.xml:3: ", "malformed XML"}));
  EXPECT_TRUE(xml_error("", {"scene.xml", "No document element"}));
}

TEST(SceneXml, UnknownAttributeIsAnError) {
  const std::string xml = fmt::format(R"(<tissue-scene version="1">
  {}
  <material name="soft" E="3000" nu="0.45" rho="1000" colour="red"/>
</tissue-scene>)",
                                      kTet);
  EXPECT_TRUE(xml_error(xml, {fmt::format("scene.xml:{}: ", line_of(xml, "colour")), "<material>",
                              "unknown attribute 'colour'", "allowed: name, E, nu, mu, K, lambda, rho"}));
  const std::string solver = fmt::format("<tissue-scene>{}\n<solver dt_safety=\"0.3\"/></tissue-scene>", kTet);
  EXPECT_TRUE(xml_error(solver, {"scene.xml:5: ", "<solver>", "unknown attribute 'dt_safety'", "dt-safety"}));
}

// A blade: kind="blade" with its length, thickness and cutting resistance
// (a capsule of half the thickness and the length as shaft), its button
// cut="true"; it round-trips; a probe's attributes on a blade, a blade's on
// a probe, cut= on a probe and grasp= on a blade, and a blade without a
// length are refused naming the rule.
TEST(SceneXml, ABladeIsAnEdgeWhoseButtonCuts) {
  const auto scene_with = [](const std::string& tool) {
    return fmt::format("<tissue-scene>\n{}\n<material name=\"m\" E=\"3000\" nu=\"0.45\" rho=\"1000\"/>\n"
                       "<element-set name=\"all\" material=\"m\" elements=\"all\"/>\n<fixed nodes=\"0\"/>\n{}\n"
                       "</tissue-scene>",
                       kTet, tool);
  };
  const std::string blade = scene_with(
      R"(<tool name="scalpel" kind="blade" length="0.02" thickness="0.0005" cut-resistance="120" cut-delay="0.03" direction="0 1 0">
  <waypoint t="0" x="0.5" y="-0.5" z="1.5"/>
  <waypoint t="1" x="0.5" y="-0.5" z="0.5" cut="true"/>
</tool>)");
  const Scene s = parse_scene(blade, "b.xml", "");
  ASSERT_EQ(s.tools.size(), 1u);
  const scene::Tool& t = s.tools[0];
  EXPECT_EQ(t.kind, scene::Tool::Kind::Blade);
  EXPECT_DOUBLE_EQ(t.shaft, 0.02);
  EXPECT_DOUBLE_EQ(t.radius, 0.00025);
  EXPECT_DOUBLE_EQ(t.cut_resistance, 120);
  EXPECT_DOUBLE_EQ(t.cut_delay, 0.03);
  EXPECT_FALSE(t.path[0].grasp);
  EXPECT_TRUE(t.path[1].grasp) << "the cut button rides in the tool's button";
  EXPECT_EQ(scheduler_settings(s).tools[0].blade, true);
  const Scene again = parse_scene(format_scene(s, ""), "again.xml", "");
  expect_same_scene(s, again);
  EXPECT_NE(format_scene(s, "").find("cut=\"true\""), std::string::npos);
  const Scene defaults = parse_scene(scene_with(R"(<tool kind="blade" length="0.02"><waypoint t="0" x="0.5" y="0.5" z="2"/></tool>)"), "d.xml", "");
  EXPECT_DOUBLE_EQ(defaults.tools[0].radius, 0.5 * scene::kDefaultBladeThickness);
  EXPECT_DOUBLE_EQ(defaults.tools[0].cut_resistance, scene::kDefaultCutResistance);
  EXPECT_DOUBLE_EQ(defaults.tools[0].cut_delay, scene::kDefaultCutDelay);

  const std::string w = R"(<waypoint t="0" x="0.5" y="0.5" z="2"/>)";
  EXPECT_TRUE(xml_error(scene_with(R"(<tool kind="blade" length="0.02" radius="0.001">)" + w + "</tool>"),
                        {"radius= is a probe's", "length="}));
  EXPECT_TRUE(xml_error(scene_with(R"(<tool length="0.02">)" + w + "</tool>"), {"length= is a blade's"}));
  EXPECT_TRUE(xml_error(scene_with(R"(<tool kind="blade">)" + w + "</tool>"), {"a blade needs length="}));
  EXPECT_TRUE(xml_error(scene_with(R"(<tool kind="knife" length="0.02">)" + w + "</tool>"),
                        {"kind = 'knife' must be probe or blade"}));
  EXPECT_TRUE(xml_error(scene_with(R"(<tool><waypoint t="0" x="0.5" y="0.5" z="2" cut="true"/></tool>)"),
                        {"cut= is a blade's button"}));
  EXPECT_TRUE(xml_error(
      scene_with(R"(<tool kind="blade" length="0.02"><waypoint t="0" x="0.5" y="0.5" z="2" grasp="true"/></tool>)"),
      {"a blade does not grasp"}));
  // the rules of the scene (validate), with the tool's line
  const auto rule_error = [&](const std::string& tool, const std::string& part) {
    return throws_with<SceneError>([&] { scene::validate(parse_scene(scene_with(tool), "scene.xml", "")); },
                                   {"scene.xml:9", part});
  };
  EXPECT_TRUE(rule_error(R"(<tool kind="blade" length="0">)" + w + "</tool>",
                         "tool 'probe': length = 0 m: a blade is a straight edge of length > 0"));
  EXPECT_TRUE(rule_error(R"(<tool kind="blade" length="0.02" cut-resistance="-1">)" + w + "</tool>",
                         "cut-resistance = -1 N/m must be >= 0"));
  EXPECT_TRUE(rule_error(R"(<tool kind="blade" length="0.02" cut-delay="-0.01">)" + w + "</tool>",
                         "cut-delay = -0.01 s must be in [0, 1]"));
  EXPECT_TRUE(rule_error(R"(<tool kind="blade" length="0.02" cut-delay="5">)" + w + "</tool>",
                         "cut-delay = 5 s must be in [0, 1]"));
  EXPECT_TRUE(xml_error(scene_with(R"(<tool cut-delay="0.01">)" + w + "</tool>"), {"cut-delay= is a blade's"}));
}

// mass-scaling: a fraction, or "off"; anything else names the attribute and the line.
TEST(SceneXml, MassScalingIsAFractionOrOff) {
  auto solver = [](const std::string& attr) {
    return fmt::format("<tissue-scene>{}\n<solver mass-scaling=\"{}\"/></tissue-scene>", kTet, attr);
  };
  EXPECT_EQ(parse_scene(solver("0.01"), "scene.xml", "").solver.mass_scaling, 0.01);
  EXPECT_EQ(parse_scene(solver("off"), "scene.xml", "").solver.mass_scaling, 0.0);
  EXPECT_EQ(parse_scene(solver(" 2e-2 "), "scene.xml", "").solver.mass_scaling, 0.02);
  EXPECT_TRUE(xml_error(solver("lots"), {"scene.xml:5: ", "<solver>", "mass-scaling = 'lots'", "\"off\""}));
  EXPECT_TRUE(xml_error(solver("auto"), {"scene.xml:5: ", "mass-scaling = 'auto'"}));
}

TEST(SceneXml, UnknownElementIsAnError) {
  const std::string xml = fmt::format(R"(<tissue-scene version="1">
  {}
  <materail name="soft" E="3000" nu="0.45" rho="1000"/>
</tissue-scene>)",
                                      kTet);
  EXPECT_TRUE(xml_error(xml, {fmt::format("scene.xml:{}: ", line_of(xml, "materail")), "unknown element <materail>",
                              "in <tissue-scene>", "material"}));
  EXPECT_TRUE(xml_error("<scene/>", {"scene.xml:1: ", "root element is <scene>", "<tissue-scene>"}));
}

TEST(SceneXml, BadNumbersNameTheAttribute) {
  const auto material = [](const std::string& attrs) {
    return fmt::format("<tissue-scene>{}\n<material name=\"m\" {}/></tissue-scene>", kTet, attrs);
  };
  EXPECT_TRUE(xml_error(material("E=\"3e\" nu=\"0.45\" rho=\"1000\""),
                        {"scene.xml:5: ", "<material>", "attribute E = '3e' is not a number"}));
  EXPECT_TRUE(xml_error(material("E=\"3000\" nu=\"0.45\" rho=\"abc\""), {"attribute rho = 'abc' is not a number"}));
  EXPECT_TRUE(xml_error(material("E=\"3000 Pa\" nu=\"0.45\" rho=\"1000\""), {"attribute E = '3000 Pa'"}));
  EXPECT_TRUE(xml_error(material("E=\"\" nu=\"0.45\" rho=\"1000\""), {"attribute E = '' is not a number"}));
  const std::string fixed =
      fmt::format("<tissue-scene>{}\n<fixed box-min=\"0 0\" box-max=\"1 1 1\"/></tissue-scene>", kTet);
  EXPECT_TRUE(xml_error(fixed, {"scene.xml:5: ", "<fixed>", "box-min", "three numbers"}));
  const std::string set = fmt::format(
      "<tissue-scene>{}\n<element-set material=\"m\" elements=\"0 1.5\"/>"
      "</tissue-scene>",
      kTet);
  EXPECT_TRUE(xml_error(set, {"scene.xml:5: ", "<element-set>", "elements: '1.5' is not a whole number"}));
  const std::string depth = fmt::format("<tissue-scene>{}\n<solver depth=\"five\"/></tissue-scene>", kTet);
  EXPECT_TRUE(xml_error(depth, {"scene.xml:5: ", "<solver>", "depth = 'five'", "\"all\""}));
  const std::string damping = fmt::format("<tissue-scene>{}\n<solver damping=\"none\"/></tissue-scene>", kTet);
  EXPECT_TRUE(xml_error(damping, {"scene.xml:5: ", "damping = 'none' is neither a number nor \"auto\""}));
}

TEST(SceneXml, BadNumberInMeshTextGivesItsOwnLine) {
  const std::string xml = R"(<tissue-scene>
  <mesh>
    <nodes>
      0 0 0
      1 0 0
      0 1x 0
      0 0 1
    </nodes>
    <elements>0 1 2 3</elements>
  </mesh>
</tissue-scene>)";
  EXPECT_TRUE(xml_error(xml, {"scene.xml:6: ", "node 2 coordinate y = '1x' is not a number"}));
  const std::string elems = R"(<tissue-scene>
  <mesh>
    <nodes>0 0 0 1 0 0 0 1 0 0 0 1</nodes>
    <elements>
      0 1 2
    </elements>
  </mesh>
</tissue-scene>)";
  EXPECT_TRUE(xml_error(elems, {"scene.xml:4: ", "3 node ids is not a multiple of 4"}));
}

TEST(SceneXml, StructureErrors) {
  EXPECT_TRUE(xml_error("<tissue-scene>\n<material name=\"m\" E=\"1\" nu=\"0.3\" rho=\"1\"/>\n</tissue-scene>",
                        {"scene.xml:1: ", "no <mesh>"}));
  EXPECT_TRUE(
      xml_error(fmt::format("<tissue-scene>{}\n{}</tissue-scene>", kTet, kTet), {"scene.xml:5: ", "a second <mesh>"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>{}\n<material name=\"m\" E=\"1\" nu=\"0.3\"/></tissue-scene>", kTet),
                        {"scene.xml:5: ", "missing required attribute 'rho'"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>{}\n<material name=\"m\" E=\"1\" K=\"3\" rho=\"1\"/>"
                                    "</tissue-scene>",
                                    kTet),
                        {"scene.xml:5: ", "material 'm' must give exactly one pair", "E and nu, mu and K"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>{}\n<fixed nodes=\"1\" box-min=\"0 0 0\" box-max=\"1 1 1\"/>"
                                    "</tissue-scene>",
                                    kTet),
                        {"scene.xml:5: ", "<fixed>", "exactly one kind"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>{}\n<tool path=\"p.csv\"><waypoint t=\"0\" x=\"0\" y=\"0\" "
                                    "z=\"0\"/></tool></tissue-scene>",
                                    kTet),
                        {"scene.xml:5: ", "<tool>", "not both"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>{}\n<solver/>\n<solver/></tissue-scene>", kTet),
                        {"scene.xml:6: ", "a second <solver>"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene version=\"2\">{}</tissue-scene>", kTet),
                        {"scene.xml:1: ", "version = '2' is not supported"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>{}\n<material name=\"m\" E=\"1\" nu=\"0.3\" rho=\"1\">soft"
                                    "</material></tissue-scene>",
                                    kTet),
                        {"scene.xml:5: ", "unexpected text 'soft'"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>{}\n<solver precision=\"half\"/></tissue-scene>", kTet),
                        {"scene.xml:5: ", "precision = 'half' must be float or double"}));
}

TEST(SceneXml, RuleErrorsFromValidationCiteTheXmlLine) {
  const std::string xml = fmt::format(R"(<tissue-scene version="1">
  {}
  <material name="soft" E="3000" nu="0.5" rho="1000"/>
  <element-set material="soft" elements="all"/>
</tissue-scene>)",
                                      kTet);
  const Scene s = parse_scene(xml, "scene.xml", "");
  EXPECT_TRUE(throws_with<SceneError>(
      [&] { (void)scene::to_model_input(s); },
      {fmt::format("scene.xml:{}: ", line_of(xml, "<material")), "material 'soft'", "nu = 0.5"}));
}

// A folder given where a file belongs is named as such, not as malformed XML
// or an empty file.
TEST(SceneXml, DirectoriesAreNamed) {
  TempDir dir;
  fs::create_directories(dir.file("scene.xml"));
  EXPECT_TRUE(throws_with<SceneError>([&] { (void)read_scene(dir.file("scene.xml")); },
                                      {dir.file("scene.xml"), "is a directory, not a scene file"}));
  fs::create_directories(dir.file("m.node"));
  EXPECT_TRUE(throws_with<io::TetgenFileError>([&] { (void)io::read_tetgen(dir.file("m.node")); },
                                               {dir.file("m.node"), "is a directory"}));
  fs::create_directories(dir.file("p.csv"));
  EXPECT_TRUE(throws_with<io::PathCsvError>([&] { (void)io::read_path_csv(dir.file("p.csv")); },
                                            {dir.file("p.csv"), "is a directory"}));
  // a device would be read forever
  EXPECT_TRUE(throws_with<io::PathCsvError>([&] { (void)io::read_path_csv("/dev/zero"); },
                                            {"/dev/zero: is a device or socket, not a path CSV file"}));
  EXPECT_TRUE(throws_with<SceneError>([&] { (void)read_scene("/dev/zero"); }, {"/dev/zero: is a device"}));
  EXPECT_TRUE(throws_with<SceneError>([&] { (void)read_scene(""); }, {"the scene file's name is empty"}));
}

TEST(SceneXml, MissingFilesAreNamed) {
  TempDir dir;
  dir.write("scene.xml", "<tissue-scene>\n  <mesh file=\"nope.node\"/>\n</tissue-scene>\n");
  EXPECT_TRUE(throws_with<SceneError>([&] { (void)read_scene(dir.file("scene.xml")); },
                                      {"scene.xml:2: ", "<mesh>", "mesh file 'nope.node'", "cannot open"}));
  dir.write("tool.xml", fmt::format("<tissue-scene>{}\n<tool path=\"gone.csv\"/></tissue-scene>\n", kTet));
  EXPECT_TRUE(throws_with<SceneError>([&] { (void)read_scene(dir.file("tool.xml")); },
                                      {"tool.xml:5: ", "tool 'probe' path file 'gone.csv'", "cannot open"}));
  EXPECT_TRUE(
      throws_with<SceneError>([&] { (void)read_scene(dir.file("absent.xml")); }, {"absent.xml", "cannot open"}));
}

// ---- per-element fibre directions ------------------------------------------

TEST(SceneXml, FibreFieldAndFileRoundTrip) {
  TempDir dir;
  Scene s = rich_scene();
  Material& brain = s.materials[0];
  brain.fibre_eta = 20000;
  brain.fibre_field = Material::FibreField::Circumferential;
  brain.fibre_axis = {0, 0.1, 1};
  brain.fibre_origin = {0.015, 0.01, 1.0 / 3};
  Material& capsule = s.materials[1];
  capsule.fibre_eta = 5000;
  capsule.fibre_field = Material::FibreField::File;
  capsule.fibre_dir = {0, 0, 1};
  capsule.fibre_file = "capsule-fibres.csv";
  for (index_t e = 1; e < 20; e += 3) capsule.fibre_rows.push_back({e, {1.0 / 3, -0.25, e * 1e-3}, 0});
  Material& fat = s.materials[2];
  fat.fibre_eta = 100;
  fat.fibre_field = Material::FibreField::Radial;
  fat.fibre_axis = {1, 0, 0};
  fat.fibre_origin = {0, 0.01, 0.0085};  // through the box's middle, along x
  write_scene(s, dir.file("rich.xml"), true);
  ASSERT_TRUE(fs::exists(dir.file("capsule-fibres.csv")));
  const std::string text = testing_support::slurp(dir.file("rich.xml"));
  EXPECT_NE(text.find("field=\"circumferential\" axis=\"0 0.1 1\" origin=\"0.015 0.01 0.3333333333333333\""),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("<fibre stiffness=\"5000\" file=\"capsule-fibres.csv\" direction=\"0 0 1\""), std::string::npos)
      << text;
  EXPECT_NE(text.find("field=\"radial\""), std::string::npos) << text;

  // read from another working folder: the CSV resolves against the scene's folder
  const Scene r = read_scene(dir.file("rich.xml"));
  expect_same_scene(s, r);
  for (size_t k = 0; k < 3; ++k) {
    const Material &x = s.materials[k], &y = r.materials[k];
    SCOPED_TRACE(x.name);
    EXPECT_EQ(y.fibre_eta, x.fibre_eta);
    EXPECT_EQ(y.fibre_field, x.fibre_field);
    EXPECT_GT(y.fibre_line, 0);
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(y.fibre_dir[c], x.fibre_dir[c]);
      if (x.fibre_field != Material::FibreField::File) {
        EXPECT_EQ(y.fibre_axis[c], x.fibre_axis[c]);
        EXPECT_EQ(y.fibre_origin[c], x.fibre_origin[c]);
      }
    }
    EXPECT_EQ(y.fibre_file, x.fibre_file);
    ASSERT_EQ(y.fibre_rows.size(), x.fibre_rows.size());
    for (size_t i = 0; i < x.fibre_rows.size(); ++i) {
      EXPECT_EQ(y.fibre_rows[i].element, x.fibre_rows[i].element);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(y.fibre_rows[i].dir[c], x.fibre_rows[i].dir[c]);
      EXPECT_EQ(y.fibre_rows[i].line, int(i) + 2);  // after the header
    }
  }
  EXPECT_EQ(r.materials[1].fibre_file_path, dir.file("capsule-fibres.csv"));
  EXPECT_EQ(format_scene(r, ""), format_scene(s, ""));
  // and the directions reach the model input: the file's rows in the capsule's listed elements
  const ModelInput in = scene::to_model_input(r);
  ASSERT_EQ(in.fibre_dirs.size(), 3 * r.tets.size() / 4);
  EXPECT_EQ(in.fibre_dirs[3 * 4 + 1], -0.25);    // element 4: a row
  EXPECT_EQ(in.fibre_dirs[3 * 22 + 2], 1.0);     // element 22 (capsule), not listed: direction=
}

/// A one-tet scene whose material 'm' (line 6) has the <fibre> (line 7) `fibre`.
std::string fibre_xml(const std::string& fibre) {
  return fmt::format(R"(<tissue-scene version="1">
  <mesh>
    <nodes>0 0 0  1 0 0  0 1 0  0 0 1</nodes>
    <elements>0 1 2 3</elements>
  </mesh>
  <material name="m" E="3000" nu="0.45" rho="1000">
    {}
  </material>
  <element-set material="m" elements="all"/>
</tissue-scene>
)",
                     fibre);
}

TEST(SceneXml, FibreAttributeErrorsNameTheLine) {
  EXPECT_TRUE(xml_error(fibre_xml(R"(<fibre stiffness="1" field="spiral" axis="0 0 1"/>)"),
                        {"scene.xml:7: ", "<fibre>: field = 'spiral' is unknown; expected circumferential or radial"}));
  EXPECT_TRUE(xml_error(fibre_xml(R"(<fibre stiffness="1" field="radial" axis="0 0 1" file="d.csv"/>)"),
                        {"scene.xml:7: ", "give either field= (a direction field) or file=", "not both"}));
  EXPECT_TRUE(xml_error(fibre_xml(R"(<fibre stiffness="1" direction="1 0 0" axis="0 0 1"/>)"),
                        {"scene.xml:7: ", "axis= and origin= belong to a direction field"}));
  EXPECT_TRUE(xml_error(fibre_xml(R"(<fibre stiffness="1" file="d.csv" origin="0 0 1"/>)"),
                        {"scene.xml:7: ", "axis= and origin= belong to a direction field"}));
  EXPECT_TRUE(xml_error(fibre_xml(R"(<fibre stiffness="1" field="radial" axis="0 0 1" direction="1 0 0"/>)"),
                        {"scene.xml:7: ", "direction= is not used with field="}));
  EXPECT_TRUE(xml_error(fibre_xml(R"(<fibre stiffness="1" field="radial"/>)"),
                        {"scene.xml:7: ", "<fibre>: missing required attribute 'axis'"}));
  EXPECT_TRUE(xml_error(fibre_xml(R"(<fibre stiffness="1" field="circumferential" axis="0 0 z"/>)"),
                        {"scene.xml:7: ", "attribute axis: z = 'z' is not a number"}));
  EXPECT_TRUE(xml_error(fibre_xml(R"(<fibre stiffness="1" field="circumferential" axis="0 0 1" origin="1 2"/>)"),
                        {"scene.xml:7: ", "attribute origin = '1 2' must be three numbers"}));
  EXPECT_TRUE(xml_error(fibre_xml(R"(<fibre stiffness="1" fiel="radial"/>)"),
                        {"scene.xml:7: ", "unknown attribute 'fiel'"}));
  // rules checked by validation, at the <fibre>'s line
  const auto rule = [](const std::string& fibre, std::initializer_list<std::string> parts) {
    return throws_with<SceneError>([&] { scene::validate(parse_scene(fibre_xml(fibre), "scene.xml", "")); }, parts);
  };
  EXPECT_TRUE(rule(R"(<fibre stiffness="1" field="radial" axis="0 0 0"/>)",
                   {"scene.xml:7: ", "material 'm': fibre field radial: axis (0, 0, 0) must be non-zero"}));
  EXPECT_TRUE(rule(R"(<fibre stiffness="1" field="radial" axis="0 0 nan"/>)",
                   {"scene.xml:7: ", "fibre field radial: axis z = nan is not a finite number"}));
  // the one tet's centroid is (0.25, 0.25, 0.25)
  EXPECT_TRUE(rule(R"(<fibre stiffness="1" field="circumferential" axis="1 1 1" origin="0 0 0"/>)",
                   {"scene.xml:7: ", "element 0's centroid (0.25, 0.25, 0.25) m lies on the axis",
                    "the circumferential direction is undefined there"}));
}

TEST(SceneXml, FibreFileErrorsNameTheCsvLine) {
  TempDir dir;
  const auto scene_error = [&](const std::string& csv, std::initializer_list<std::string> parts) {
    dir.write("dirs.csv", csv);
    dir.write("s.xml", fibre_xml(R"(<fibre stiffness="1" file="dirs.csv" direction="1 0 0"/>)"));
    return throws_with<SceneError>([&] { scene::validate(read_scene(dir.file("s.xml"))); }, parts);
  };
  const std::string csv = dir.file("dirs.csv");
  // syntax, by the reader: the scene's line, then the CSV's file:line
  EXPECT_TRUE(scene_error("element,ax,ay,az\n0,abc,0,0\n",
                          {"s.xml:7: ", "<fibre>: material 'm' fibre file 'dirs.csv': ", csv + ":2: ",
                           "ax 'abc' is not a number"}));
  EXPECT_TRUE(scene_error("# fibres\n\n0,1,0,inf\n", {"s.xml:7: ", csv + ":3: ", "az = inf is not a finite number"}));
  EXPECT_TRUE(scene_error("0,1,0\n", {csv + ":1: ", "3 fields; a row is element,ax,ay,az"}));
  EXPECT_TRUE(scene_error("0.5,1,0,0\n", {csv + ":1: ", "element '0.5' is not an element id"}));
  EXPECT_TRUE(scene_error("elem,x,y,z\n0,1,0,0\n", {csv + ":1: ", "header is 'elem,x,y,z'; expected 'element,ax,ay,az'"}));
  EXPECT_TRUE(scene_error("element,ax,ay,az\n", {csv + ":1: ", "no rows"}));
  // rules, by validation: the CSV's file:line and the <fibre>'s
  EXPECT_TRUE(scene_error("element,ax,ay,az\n5,1,0,0\n",
                          {csv + ":2: ", "material 'm', fibre file 'dirs.csv' (<fibre> at " + dir.file("s.xml") + ":7)",
                           "element 5 is out of range (the mesh has 1 elements, ids 0..0"}));
  EXPECT_TRUE(scene_error("0,1,0,0\n0,0,1,0\n", {csv + ":2: ", "element 0 is listed twice (first at line 1)"}));
  EXPECT_TRUE(scene_error("0,0,0,0\n", {csv + ":1: ", "element 0: fibre direction (0, 0, 0) must be finite and "
                                                       "non-zero"}));
  // a binary file: named as such at its line, its bytes escaped (a NUL cut the message where it stood)
  const std::string binary("element,ax,ay,az\n0,1\0\x01\xff,0,0\nPK\x03\x04\0\0\n", 35);
  EXPECT_TRUE(scene_error(binary, {"s.xml:7: ", csv + ":2: ", "is binary, not text: line 2 holds byte 0x00 at column 4",
                                   "('0,1\\x00\\x01\\xff,0,0')", "a fibre file is a text CSV"}));
  // a missing file
  dir.write("t.xml", fibre_xml(R"(<fibre stiffness="1" file="gone.csv"/>)"));
  EXPECT_TRUE(throws_with<SceneError>([&] { (void)read_scene(dir.file("t.xml")); },
                                      {"t.xml:7: ", "fibre file 'gone.csv'", "cannot open"}));
  // a good file: direction= is optional with file= (default 1 0 0)
  dir.write("dirs.csv", "element, ax, ay, az\n 0 , 0, -2, 0 \n");
  dir.write("u.xml", fibre_xml(R"(<fibre stiffness="1" file="dirs.csv"/>)"));
  const TissueModel<double> m = scene::load_model(read_scene(dir.file("u.xml")));
  EXPECT_EQ(m.fibre[1], -1.0);  // a_y of element 0, normalised
}

// ---- TetGen .node/.ele -----------------------------------------------------

// ---- bodies ----------------------------------------------------------------

/// Two bodies: "a" one tetrahedron held at nodes 0 and 1; "b" two tetrahedra
/// sharing a face, 3 m along x, in two sets, its base held by a box that
/// spans a's base too, and a point load on its node 4.
std::string bodies_xml(const std::string& a_extra = "", const std::string& b_sets =
                           R"(<element-set name="first" material="m" elements="0"/>
    <element-set name="second" material="m" elements="1"/>)",
                       const std::string& b_elements = "0 1 2 3  1 2 3 4") {
  return fmt::format(R"(<tissue-scene>
  <material name="m" E="3000" nu="0.45" rho="1000"/>
  <body name="a">
    <mesh><nodes>0 0 0  1 0 0  0 1 0  0 0 1</nodes><elements>0 1 2 3</elements></mesh>
    <element-set material="m" elements="all"/>
    <fixed nodes="0 1"/>{}
  </body>
  <body name="b">
    <mesh><nodes>3 0 0  4 0 0  3 1 0  3 0 1  4 1 1</nodes><elements>{}</elements></mesh>
    {}
    <fixed box-min="-10 -10 -0.1" box-max="10 10 0.1"/>
    <load nodes="4" force="0 0 1" distribute="each"/>
  </body>
  <tool radius="0.2"><waypoint t="0" x="0.2" y="0.2" z="2"/></tool>
</tissue-scene>)",
                     a_extra, b_elements, b_sets);
}

void expect_same_bodies(const Scene& x, const Scene& y) {
  ASSERT_EQ(x.bodies.size(), y.bodies.size());
  for (size_t k = 0; k < x.bodies.size(); ++k) {
    const scene::Body &a = x.bodies[k], &b = y.bodies[k];
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.first_node, b.first_node);
    EXPECT_EQ(a.n_nodes, b.n_nodes);
    EXPECT_EQ(a.first_element, b.first_element);
    EXPECT_EQ(a.n_elements, b.n_elements);
  }
  for (size_t k = 0; k < x.sets.size(); ++k) EXPECT_EQ(x.sets[k].body, y.sets[k].body);
  for (size_t k = 0; k < x.constraints.size(); ++k) EXPECT_EQ(x.constraints[k].body, y.constraints[k].body);
  ASSERT_EQ(x.loads.size(), y.loads.size());
  for (size_t k = 0; k < x.loads.size(); ++k) {
    EXPECT_EQ(x.loads[k].where.body, y.loads[k].where.body);
    EXPECT_EQ(x.loads[k].where.nodes, y.loads[k].where.nodes);
  }
}

// The bodies become one mesh, each body's ids shifted by the counts before
// it; a body's box selects its own nodes only; "all" is the body's elements.
TEST(SceneXml, BodiesAreOneMeshWithTheirOwnIdsShifted) {
  const Scene s = parse_scene(bodies_xml(), "two.xml", "");
  ASSERT_EQ(s.bodies.size(), 2u);
  EXPECT_EQ(s.bodies[0].name, "a");
  EXPECT_EQ(s.bodies[1].name, "b");
  EXPECT_EQ(s.bodies[1].first_node, 4);
  EXPECT_EQ(s.bodies[1].n_nodes, 5);
  EXPECT_EQ(s.bodies[1].first_element, 1);
  EXPECT_EQ(s.bodies[1].n_elements, 2);
  EXPECT_EQ(s.nodes.size(), 27u);
  EXPECT_EQ(s.tets, (std::vector<index_t>{0, 1, 2, 3, 4, 5, 6, 7, 5, 6, 7, 8}));
  ASSERT_EQ(s.sets.size(), 3u);
  EXPECT_TRUE(s.sets[0].all);
  EXPECT_EQ(s.sets[0].body, 0);
  EXPECT_EQ(s.sets[1].elements, std::vector<index_t>{1});
  EXPECT_EQ(s.sets[2].elements, std::vector<index_t>{2});
  EXPECT_EQ(s.sets[2].body, 1);
  EXPECT_EQ(s.constraints[0].nodes, (std::vector<index_t>{0, 1}));
  EXPECT_EQ(s.constraints[1].body, 1);
  EXPECT_EQ(s.loads.at(0).where.nodes, std::vector<index_t>{8});
  const ModelInput in = scene::to_model_input(s);
  // a's nodes 0 1 by id; of b, the box catches the three at z = 0 -- not a's node 2, also at z = 0
  EXPECT_EQ(in.fixed, (std::vector<std::uint8_t>{1, 1, 0, 0, 1, 1, 1, 0, 0}));
  EXPECT_EQ(in.elem_material, (std::vector<index_t>{0, 0, 0}));
  const TissueModel<double> m = scene::load_model(s);
  const scene::SceneLoads loads = scene::resolve_loads(s, m);
  EXPECT_EQ(loads.nodes, std::vector<index_t>{8});
}

TEST(SceneXml, BodiesRoundTripInlineAndInTheirOwnMeshFiles) {
  const Scene s = parse_scene(bodies_xml(), "two.xml", "");
  const Scene back = parse_scene(format_scene(s, ""), "back.xml", "");
  expect_same_scene(s, back);
  expect_same_bodies(s, back);
  EXPECT_EQ(format_scene(back, ""), format_scene(s, ""));
  // the written ids are each body's own again
  EXPECT_NE(format_scene(s, "").find("<fixed nodes=\"0 1\""), std::string::npos) << format_scene(s, "");
  EXPECT_NE(format_scene(s, "").find("<load force=\"0 0 1\" distribute=\"each\" nodes=\"4\""), std::string::npos)
      << format_scene(s, "");

  TempDir dir;
  write_scene(s, dir.file("two.xml"), false);
  EXPECT_TRUE(fs::exists(dir.file("two-a.node")));
  EXPECT_TRUE(fs::exists(dir.file("two-b.ele")));
  const Scene r = read_scene(dir.file("two.xml"));
  EXPECT_EQ(r.bodies.at(1).mesh_file, "two-b.node");
  expect_same_scene(s, r);
  expect_same_bodies(s, r);
  EXPECT_NO_THROW(scene::validate(r));
}

TEST(SceneXml, BodyErrorsNameTheBodyItsOwnIdsAndTheLine) {
  const std::string xml = bodies_xml();
  const int b_line = line_of(xml, "<body name=\"b\"");
  EXPECT_TRUE(xml_error(bodies_xml("", R"(<element-set material="m" elements="0 2"/>)"),
                        {fmt::format("scene.xml:{}: ", b_line + 2), "body 'b': element 2 is out of range",
                         "its mesh has 2 elements"}));
  EXPECT_TRUE(xml_error(bodies_xml("\n    <fixed nodes=\"4\"/>"),
                        {"body 'a': node 4 is out of range", "its mesh has 4 nodes, ids 0..3"}));
  EXPECT_TRUE(xml_error(bodies_xml("", "", "0 1 2 3  1 2 3 5"),
                        {fmt::format("scene.xml:{}: ", b_line + 1),
                         "body 'b': element 1 corner 3 refers to node 5, out of range (its mesh has 5 nodes"}));
  EXPECT_TRUE(xml_error(bodies_xml("\n    <load box-min=\"0 0 0\" box-max=\"1 1 1\" force=\"1 0 0\" bogus=\"1\"/>"),
                        {"<load>: unknown attribute 'bogus'"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>{}<body name=\"x\">{}</body></tissue-scene>", kTet, kTet),
                        {"a <mesh> beside <body> elements"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene><body name=\"x\">{}</body>\n<fixed nodes=\"0\"/></tissue-scene>",
                                    kTet),
                        {"scene.xml:5: ", "<fixed> outside a <body>"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene><body name=\"x\">{}</body>\n<body name=\"x\">{}</body>"
                                    "</tissue-scene>",
                                    kTet, kTet),
                        {"scene.xml:5: ", "body 'x' is defined twice (first at line 1)"}));
  EXPECT_TRUE(xml_error("<tissue-scene>\n<body name=\"x\"/></tissue-scene>",
                        {"scene.xml:2: ", "body 'x' has no <mesh>"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>\n<body>{}</body></tissue-scene>", kTet),
                        {"scene.xml:2: ", "<body>: missing required attribute 'name'"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene><body name=\"x\">{}<tool/></body></tissue-scene>", kTet),
                        {"unknown element <tool> in <body>"}));
  // validation: an element left out of every set names the body and its own ids; a box of a body
  // that holds none of its nodes says whose
  const Scene unset = parse_scene(bodies_xml("", R"(<element-set material="m" elements="1"/>)"), "scene.xml", "");
  EXPECT_TRUE(throws_with<SceneError>([&] { scene::validate(unset); },
                                      {"body 'b': element 0 (nodes 0 1 2 3) is in no element-set"}));
  const Scene far = parse_scene(bodies_xml("\n    <fixed box-min=\"3 -1 -1\" box-max=\"5 2 2\"/>"), "scene.xml", "");
  EXPECT_TRUE(throws_with<SceneError>([&] { scene::validate(far); }, {"selects no node of the body 'a'"}));
}

// A scene of bodies built in code is held to the same rules: the ranges
// tile the mesh in order, and a body's elements use its own nodes.
// ---- bodies that touch -------------------------------------------------------

std::string with(const std::string& xml, const std::string& extra) {
  std::string s = xml;
  s.insert(s.rfind("</tissue-scene>"), extra + "\n");
  return s;
}

TEST(SceneXml, AContactPairsTwoBodiesAndTheWholeMeshRuns) {
  const Scene s = parse_scene(with(bodies_xml(), R"(  <contact bodies="a b" friction="0.2"/>)"), "two.xml", "");
  ASSERT_EQ(s.contacts.size(), 1u);
  EXPECT_EQ(s.contacts[0].a, "a");
  EXPECT_EQ(s.contacts[0].b, "b");
  EXPECT_EQ(s.contacts[0].friction, 0.2);
  const SchedulerSettings st = scene::scheduler_settings(s);
  EXPECT_EQ(st.depth, kDepthAll);  // auto, in a scene whose bodies touch
  EXPECT_EQ(st.body_contact.first_node, (std::vector<index_t>{0, 4, 9}));
  ASSERT_EQ(st.body_contact.pairs.size(), 1u);
  EXPECT_EQ(st.body_contact.pairs[0].a, 0);
  EXPECT_EQ(st.body_contact.pairs[0].b, 1);
  EXPECT_EQ(st.body_contact.pairs[0].friction, 0.2);
  // written and read back
  const Scene back = parse_scene(format_scene(s, ""), "back.xml", "");
  ASSERT_EQ(back.contacts.size(), 1u);
  EXPECT_EQ(back.contacts[0].b, "b");
  EXPECT_EQ(back.contacts[0].friction, 0.2);
}

TEST(SceneXml, ContactErrorsNameTheBodiesAndTheRule) {
  const std::string xml = bodies_xml();
  const auto invalid = [](const std::string& text, std::initializer_list<std::string> parts) {
    return throws_with<SceneError>([&] { scene::validate(parse_scene(text, "scene.xml", "")); }, parts);
  };
  EXPECT_NO_THROW(scene::validate(parse_scene(with(xml, R"(<contact bodies="a b"/>)"), "scene.xml", "")));
  EXPECT_TRUE(invalid(with(xml, R"(<contact bodies="a c"/>)"), {"contact: no body 'c'", "the bodies are a, b"}));
  EXPECT_TRUE(invalid(with(xml, R"(<contact bodies="a a"/>)"), {"names one body twice", "not modelled"}));
  EXPECT_TRUE(xml_error(with(xml, R"(<contact bodies="a"/>)"), {"names 1 bodies; it names two"}));
  EXPECT_TRUE(invalid(with(xml, R"(<contact bodies="a b" friction="-1"/>)"), {"friction = -1 must be >= 0"}));
  EXPECT_TRUE(invalid(with(xml, "<contact bodies=\"a b\"/>\n<contact bodies=\"b a\"/>"), {"already paired"}));
  EXPECT_TRUE(xml_error(with(xml, R"(<contact bodies="a b" mu="1"/>)"), {"unknown attribute 'mu'"}));
  EXPECT_TRUE(invalid(with(xml, "<contact bodies=\"a b\"/>\n<solver depth=\"3\"/>"),
                        {"depth = 3", "computes the whole mesh"}));
  EXPECT_TRUE(xml_error(fmt::format("<tissue-scene>{}<contact bodies=\"a b\"/></tissue-scene>", kTet),
                        {"a scene of one <mesh> has none"}));
}

TEST(SceneValidate, BodiesBuiltInCodeMustTileTheMesh) {
  const Scene good = parse_scene(bodies_xml(), "two.xml", "");
  EXPECT_NO_THROW(scene::validate(good));
  Scene gap = good;
  gap.bodies[1].first_node = 5;
  EXPECT_TRUE(throws_with<SceneError>([&] { scene::validate(gap); }, {"body 'b'", "do not follow the bodies before it"}));
  Scene short_ = good;
  short_.bodies[1].n_nodes = 4;
  EXPECT_TRUE(throws_with<SceneError>([&] { scene::validate(short_); }, {"the bodies hold 8 nodes", "9"}));
  Scene crossing = good;
  crossing.tets[4] = 3;  // b's first element uses a's node 3
  EXPECT_TRUE(throws_with<SceneError>([&] { scene::validate(crossing); },
                                      {"body 'b': element 0 corner 0 is node 3 of the scene, outside the body's "
                                       "nodes 4..8"}));
  Scene named = good;
  named.bodies[1].name = "a";
  EXPECT_TRUE(throws_with<SceneError>([&] { scene::validate(named); }, {"body 'a' is defined twice"}));
  Scene stray = good;
  stray.constraints[0].body = 2;
  EXPECT_TRUE(throws_with<SceneError>([&] { scene::validate(stray); }, {"belongs to body 2, which does not exist"}));
  stray.constraints[0].body = -1;  // the writer writes each body's own: one of none would be lost
  EXPECT_TRUE(throws_with<SceneError>([&] { scene::validate(stray); }, {"a <fixed> belongs to no body"}));
  Scene outside = good;
  outside.constraints[0].nodes = {0, 5};  // a's selection naming b's node
  EXPECT_TRUE(throws_with<SceneError>([&] { scene::validate(outside); },
                                      {"body 'a': fixed nodes: node 5 is out of range (the body has 4 nodes"}));
}

TEST(TetgenFiles, ReadsOneBasedFilesWithCommentsAttributesAndMarkers) {
  TempDir dir;
  dir.write("organ.node", R"(# a unit tet and its mirror
5 3 1 1   # points, dim, attributes, markers
1  0 0 0   7.5  1
2  1 0 0   7.5  1
# interior comment
3  0 1 0   7.5  0

4  0 0 1   7.5  1
5  0 0 -1  7.5  1
)");
  dir.write("organ.ele", R"(2 4 1
1  1 2 3 4  3
2  1 3 2 5  3
# Generated by tetgen
)");
  const io::TetgenFiles m = io::read_tetgen(dir.file("organ.node"));
  EXPECT_EQ(m.first_index, 1);
  EXPECT_EQ(m.nodes, (std::vector<double>{0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1}));
  EXPECT_EQ(m.tets, (std::vector<index_t>{0, 1, 2, 3, 0, 2, 1, 4}));

  dir.write("scene.xml", R"(<tissue-scene>
  <mesh file="organ.node"/>
  <material name="m" E="3000" nu="0.45" rho="1000"/>
  <element-set material="m" elements="all"/>
</tissue-scene>)");
  const Scene s = read_scene(dir.file("scene.xml"));
  EXPECT_EQ(s.nodes, m.nodes);
  EXPECT_EQ(s.tets, m.tets);
  const TissueModel<double> model = scene::load_model(s);
  EXPECT_EQ(model.n_elems, 2);
  EXPECT_EQ(model.reoriented, 0);
}

TEST(TetgenFiles, WriteThenReadIsExact) {
  TempDir dir;
  ModelInput box;
  box_mesh(box, 2, 3, 1, 0.1, 0.07, 0.013);
  io::write_tetgen(dir.file("box.node"), box.nodes, box.tets);
  const io::TetgenFiles m = io::read_tetgen(dir.file("box.node"));
  EXPECT_EQ(m.first_index, 0);
  EXPECT_EQ(m.nodes, box.nodes);
  EXPECT_EQ(m.tets, box.tets);
}

testing::AssertionResult node_error(const std::string& text, std::initializer_list<std::string> parts) {
  return throws_with<io::TetgenFileError>(
      [&] {
        std::istringstream in(text);
        int first = -1;
        (void)io::parse_tetgen_node(in, "m.node", first);
      },
      parts);
}

testing::AssertionResult ele_error(const std::string& text, std::initializer_list<std::string> parts) {
  return throws_with<io::TetgenFileError>(
      [&] {
        std::istringstream in(text);
        (void)io::parse_tetgen_ele(in, "m.ele", 4, 0);
      },
      parts);
}

TEST(TetgenFiles, ErrorsNameFileAndLine) {
  EXPECT_TRUE(node_error("", {"m.node:0: ", "empty"}));
  EXPECT_TRUE(node_error("2 3 0 0\n0 0 0 0\n1 0 abc 0\n", {"m.node:3: ", "y coordinate 'abc' is not a number"}));
  EXPECT_TRUE(node_error("2 3 0 0\n0 0 0 0\n1 0 3e 0\n", {"m.node:3: ", "'3e'"}));
  EXPECT_TRUE(node_error("2 2 0 0\n", {"m.node:1: ", "dimension is 2"}));
  EXPECT_TRUE(node_error("2 3 0\n", {"m.node:1: ", "header has 3 fields"}));
  EXPECT_TRUE(node_error("3 3 0 0\n0 0 0 0\n1 1 0 0\n", {"m.node:3: ", "ends after 2 of the 3 points"}));
  EXPECT_TRUE(node_error("1 3 0 0\n0 0 0 0\n1 1 0 0\n", {"m.node:3: ", "more points than the 1"}));
  EXPECT_TRUE(
      node_error("2 3 0 0\n0 0 0 0\n2 1 0 0\n", {"m.node:3: ", "point id 2 breaks the numbering", "expected 1"}));
  EXPECT_TRUE(node_error("1 3 0 0\n5 0 0 0\n", {"m.node:2: ", "first point id is 5", "0 or 1"}));
  EXPECT_TRUE(node_error("1 3 1 0\n0 0 0 0\n", {"m.node:2: ", "4 fields; expected 5"}));

  EXPECT_TRUE(ele_error("1 4 0\n0 0 1 2 4\n", {"m.ele:2: ", "corner 3 refers to point 4", "numbered 0..3"}));
  EXPECT_TRUE(ele_error("1 10 0\n", {"m.ele:1: ", "10 nodes per tetrahedron", "linear 4-node"}));
  EXPECT_TRUE(ele_error("1 4 0\n0 0 1 x 3\n", {"m.ele:2: ", "corner 2 'x' is not a whole number"}));
  EXPECT_TRUE(ele_error("2 4 0\n0 0 1 2 3\n", {"m.ele:2: ", "ends after 1 of the 2 tetrahedra"}));
  // headers that claim more than the file holds are refused before anything is allocated for them
  EXPECT_TRUE(node_error("3000000000 3 0 0\n0 0 0 0\n", {"m.node:1: ", "3000000000 points", "32-bit ids"}));
  EXPECT_TRUE(node_error("2000000000 3 0 0\n0 0 0 0\n1 1 0 0\n",
                         {"m.node:1: ", "2000000000 points", "only 16 characters", "at most 2 lines of 4 fields"}));
  EXPECT_TRUE(node_error("4 3 99999999999 0\n0 0 0 0\n",
                         {"m.node:1: ", "100000000003 fields per point line", "only 8 characters"}));
  EXPECT_TRUE(node_error("4 3 9223372036854775807 1\n0 0 0 0\n", {"m.node:1: ", "header field 3", "beyond any"}));
  EXPECT_TRUE(ele_error("999999999 4 0\n0 0 1 2 3\n", {"m.ele:1: ", "999999999 tetrahedra", "at most 1 lines"}));
  EXPECT_TRUE(node_error("1 3 99 0\n0 0 0 0\n", {"m.node:2: ", "4 fields; expected 103"}));  // a plain count
  // the last line may lack its newline
  std::istringstream one("1 3 0 0\n0 0 0 0");
  int first = -1;
  EXPECT_EQ(io::parse_tetgen_node(one, "m.node", first).size(), 3u);
  EXPECT_TRUE(throws_with<io::TetgenFileError>([] { (void)io::ele_path_for("organ.stl"); }, {"organ.stl", ".node"}));
}

// ---- tool path CSV ---------------------------------------------------------

TEST(PathCsv, ReadsWaypoints) {
  std::istringstream in("# press path\nt, x, y, z\n0,0,0,0.02\n\n0.1, 0.001, -2e-3, 0.01\n");
  const std::vector<Waypoint> p = io::parse_path_csv(in, "p.csv");
  ASSERT_EQ(p.size(), 2u);
  EXPECT_EQ(p[1].t, 0.1);
  EXPECT_EQ(p[1].p.x, 0.001);
  EXPECT_EQ(p[1].p.y, -2e-3);
  EXPECT_EQ(p[1].p.z, 0.01);
}

TEST(PathCsv, WriteThenReadIsExact) {
  TempDir dir;
  const std::vector<Waypoint> path = press_path({0.1 / 3, 0.02, 0.017}, {0, 0, -1}, 3e-3, 1e-2);
  io::write_path_csv(dir.file("p.csv"), path);
  const std::vector<Waypoint> r = io::read_path_csv(dir.file("p.csv"));
  ASSERT_EQ(r.size(), path.size());
  for (size_t k = 0; k < r.size(); ++k) {
    EXPECT_EQ(r[k].t, path[k].t);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(r[k].p[c], path[k].p[c]);
  }
}

testing::AssertionResult csv_error(const std::string& text, std::initializer_list<std::string> parts) {
  return throws_with<io::PathCsvError>(
      [&] {
        std::istringstream in(text);
        (void)io::parse_path_csv(in, "p.csv");
      },
      parts);
}

TEST(PathCsv, ErrorsNameFileAndLine) {
  EXPECT_TRUE(csv_error("time,x,y,z\n0,0,0,0\n", {"p.csv:1: ", "header is 'time,x,y,z'", "t,x,y,z"}));
  EXPECT_TRUE(csv_error("t,x,y,z\n0,0,0,0\n0.1,0,0\n", {"p.csv:3: ", "3 fields; the header has 4"}));
  EXPECT_TRUE(csv_error("t,x,y,z\n0,0,0,0\n0.1s,0,0,0\n", {"p.csv:3: ", "t '0.1s' is not a number"}));
  EXPECT_TRUE(csv_error("t,x,y,z\n0,0,0,0\n0.2,0,0,0\n0.2,0,0,1\n",
                        {"p.csv:4: ", "t = 0.2 s is not after", "times must increase"}));
  EXPECT_TRUE(csv_error("t,x,y,z\n0,nan,0,0\n", {"p.csv:2: ", "x = nan is not a finite number"}));
  EXPECT_TRUE(csv_error("t,x,y,z\n", {"p.csv:1: ", "no waypoints"}));
  EXPECT_TRUE(csv_error("", {"p.csv:0: ", "empty"}));
  // the grasp button and the shaft axis columns
  EXPECT_TRUE(csv_error("t,x,y,z,force\n", {"p.csv:1: ", "unknown column 'force'"}));
  EXPECT_TRUE(csv_error("t,x,y,z,ax,ay\n", {"p.csv:1: ", "all three axis columns"}));
  EXPECT_TRUE(csv_error("t,x,y,z,grasp,grasp\n", {"p.csv:1: ", "'grasp' appears twice"}));
  EXPECT_TRUE(csv_error("t,x,y,z,grasp\n0,0,0,0,2\n", {"p.csv:2: ", "grasp '2' must be 0 or 1"}));
  EXPECT_TRUE(csv_error("t,x,y,z,ax,ay,az\n0,0,0,0,0,nan,0\n", {"p.csv:2: ", "ay = nan is not a finite number"}));
  // a binary file: named as such, its bytes escaped
  EXPECT_TRUE(csv_error(std::string("t,x,y,z\n0,0\0\x7f,0,0\n", 18),
                        {"p.csv:2: ", "is binary, not text: line 2 holds byte 0x00 at column 4 ('0,0\\x00\\x7f,0,0')",
                         "a tool path is a text CSV"}));
}

TEST(PathCsv, GraspAndAxisColumnsRoundTrip) {
  std::istringstream in("t,x,y,z,grasp,ax,ay,az\n0,0,0,0.01,0,0,0,1\n0.5,0,0,0.005,1,0,1,0\n");
  const std::vector<Waypoint> w = io::parse_path_csv(in, "p.csv");
  ASSERT_EQ(w.size(), 2u);
  EXPECT_FALSE(w[0].grasp);
  EXPECT_TRUE(w[1].grasp);
  EXPECT_EQ(w[1].axis.y, 1.0);
  const std::string file = (std::filesystem::temp_directory_path() / "tissue_grasp_path.csv").string();
  io::write_path_csv(file, w);
  EXPECT_FALSE(std::filesystem::exists(file + ".part"));  // written whole, then renamed
  EXPECT_EQ(testing_support::slurp(file).substr(0, 23), "t,x,y,z,grasp,ax,ay,az\n");
  const std::vector<Waypoint> r = io::read_path_csv(file);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[1].grasp, true);
  EXPECT_EQ(r[0].axis.z, 1.0);
  // the scripted device replays them: the button from its waypoint on, the axis interpolated
  ScriptedDevice d(r);
  EXPECT_FALSE(d.read(0.25).grasp);
  EXPECT_TRUE(d.read(0.5).grasp);
  const Vec3<double> mid = d.read(0.25).axis;
  EXPECT_NEAR(norm(mid), 1.0, 1e-12);
  EXPECT_NEAR(mid.y, mid.z, 1e-12);  // halfway between z and y
}

// ----------------------------------------------- the format's documentation

/// The string literals of every `call(node, {"a", "b", ...})` in `source`,
/// one list per call: the names the reader accepts at that call.
std::vector<std::vector<std::string>> name_lists(const std::string& source, const std::string& call) {
  const std::regex call_re(call + R"(\(\s*\w+\s*,\s*\{([^}]*)\}\))");
  const std::regex literal(R"re("([^"]*)")re");
  std::vector<std::vector<std::string>> lists;
  for (auto c = std::sregex_iterator(source.begin(), source.end(), call_re); c != std::sregex_iterator(); ++c) {
    const std::string body = (*c)[1];
    std::vector<std::string>& names = lists.emplace_back();
    for (auto l = std::sregex_iterator(body.begin(), body.end(), literal); l != std::sregex_iterator(); ++l)
      names.push_back((*l)[1]);
  }
  return lists;
}

/// docs/scene-format.md in parts: each "###" section of "## Elements and
/// attributes" (one per element, heading first) and the text of "## Tool
/// path CSV". Headings inside code blocks do not count.
struct FormatDoc {
  std::vector<std::string> element_sections;
  std::string path_csv;
};

FormatDoc read_format_doc() {
  std::istringstream in(testing_support::slurp(std::string(TISSUE_SOURCE_DIR) + "/docs/scene-format.md"));
  FormatDoc d;
  std::string line, part;
  bool code = false, in_element = false;
  while (std::getline(in, line)) {
    if (line.starts_with("```")) {
      code = !code;
    } else if (!code && line.starts_with("## ")) {
      part = line.substr(3);
      in_element = false;
    } else if (!code && line.starts_with("### ")) {
      in_element = part == "Elements and attributes";
      if (in_element) d.element_sections.emplace_back();
    }
    if (in_element) d.element_sections.back() += line + "\n";
    if (part == "Tool path CSV") d.path_csv += line + "\n";
  }
  return d;
}

/// Whether a section documents the attribute: `name` or name= (not as the
/// tail of a longer name: box-min= does not document min).
bool documents(const std::string& section, const std::string& attribute) {
  return section.find("`" + attribute + "`") != std::string::npos ||
         std::regex_search(section, std::regex("(^|[^A-Za-z0-9_-])" + attribute + "="));
}

std::string joined(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

// Every attribute the reader accepts (its check_attributes lists, read from
// io/scene_xml.cpp now) is documented in docs/scene-format.md, all of one
// element's in one element's section; every child element it accepts (its
// check_children lists) is named there as <name.
TEST(SceneFormatDoc, DocumentsEveryElementAndAttributeTheReaderAccepts) {
  const std::string source = testing_support::slurp(std::string(TISSUE_SOURCE_DIR) + "/io/scene_xml.cpp");
  const auto attribute_lists = name_lists(source, "check_attributes");
  const auto child_lists = name_lists(source, "check_children");
  // the extraction finds the reader's lists (else a reformatted reader would pass unchecked)
  ASSERT_GE(attribute_lists.size(), 10u) << "io/scene_xml.cpp: check_attributes(node, {...}) calls not found";
  ASSERT_GE(child_lists.size(), 4u) << "io/scene_xml.cpp: check_children(node, {...}) calls not found";
  const FormatDoc doc = read_format_doc();
  ASSERT_GE(doc.element_sections.size(), 8u) << "docs/scene-format.md: no '### `<element>`' sections found";

  for (const std::vector<std::string>& attributes : attribute_lists) {
    if (attributes.empty()) continue;
    std::vector<std::string> fewest_missing = attributes;
    std::string closest = "none";
    for (const std::string& section : doc.element_sections) {
      std::vector<std::string> missing;
      for (const std::string& a : attributes)
        if (!documents(section, a)) missing.push_back(a);
      if (missing.size() < fewest_missing.size()) {
        fewest_missing = missing;
        closest = section.substr(0, section.find('\n'));
      }
    }
    EXPECT_TRUE(fewest_missing.empty()) << "no section of docs/scene-format.md documents every attribute the reader "
                                        << "accepts on one element (" << joined(attributes) << "); the closest, '"
                                        << closest << "', lacks " << joined(fewest_missing);
  }
  std::string elements;
  for (const std::string& section : doc.element_sections) elements += section;
  for (const std::vector<std::string>& children : child_lists)
    for (const std::string& c : children)
      EXPECT_NE(elements.find("<" + c), std::string::npos)
          << "docs/scene-format.md, \"Elements and attributes\", does not describe the element <" << c << ">";
}

// Every column the path reader accepts (io/path_csv.cpp's header names,
// read now) is documented in docs/scene-format.md's "Tool path CSV": as
// `name`, or as a field of a header shown there.
TEST(SceneFormatDoc, DocumentsEveryPathColumnTheReaderAccepts) {
  const std::string source = testing_support::slurp(std::string(TISSUE_SOURCE_DIR) + "/io/path_csv.cpp");
  const std::regex column(R"re(f\[(?:k|\d+)\]\s*[!=]=\s*"(\w+)")re");
  std::vector<std::string> columns;
  for (auto c = std::sregex_iterator(source.begin(), source.end(), column); c != std::sregex_iterator(); ++c)
    columns.push_back((*c)[1]);
  ASSERT_GE(columns.size(), 8u) << "io/path_csv.cpp: the header's column names (f[k] == \"...\") not found";
  const std::string section = read_format_doc().path_csv;
  ASSERT_FALSE(section.empty()) << "docs/scene-format.md has no '## Tool path CSV'";
  for (const std::string& c : columns) {
    bool found = section.find("`" + c + "`") != std::string::npos;
    std::istringstream lines(section);
    for (std::string line; !found && std::getline(lines, line);)
      if (line.find(',') != std::string::npos)
        for (std::string_view field : scene::split_commas(line)) found = found || field == c;
    EXPECT_TRUE(found) << "docs/scene-format.md, \"Tool path CSV\", does not document the column '" << c << "'";
  }
}

}  // namespace
}  // namespace tissue
