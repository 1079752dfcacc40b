// The built-in "@kidney-fat" (io/kidney.hpp; docs/kidney.md, "The kidney in
// its fat"): a fat layer lying on the kidney's lateral side, its surface
// closed and its inner side on the kidney's, its rim held; a palpation
// through the layer feels the kidney (the force at the deepest press is
// over twice what the layer gives alone, with the kidney's contact off)
// and is softer than pressing the bare kidney the same depth below its
// surface; nothing inverts and the layer sinks into the organ by at most
// the stated tolerance where the probe pinches it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <stdexcept>
#include <utility>

#include "backends/registry.hpp"
#include "core/device.hpp"
#include "core/scheduler.hpp"
#include "io/kidney.hpp"
#include "io/scene_xml.hpp"
#include "scene/validate.hpp"
#include "tests/backend_test_support.hpp"
#include "tests/temp_dir.hpp"

namespace tissue {
namespace {

using io::SurfaceMesh;

Vec3<double> unit(Vec3<double> v) {
  return (1.0 / norm(v)) * v;
}

Vec3<double> vtx(const SurfaceMesh& s, index_t i) {
  return {s.vertices[3 * i], s.vertices[3 * i + 1], s.vertices[3 * i + 2]};
}

const scene::Scene& fat_scene() {
  static const scene::Scene s = io::kidney_fat_scene();
  return s;
}

/// The scene run on the cpu in double up to the probe's deepest press (the
/// end of its press_path's press, 0.3 s): the force there (N) and the fields.
struct Press {
  double force = 0;
  Fields fields;
  TissueModel<double> model;
};

Press press(const scene::Scene& s, const std::string& backend = "cpu") {
  Press p;
  p.model = scene::load_model(s);
  auto b = create_backend(backend, Precision::Double);
  b->upload(p.model);
  Scheduler sched(*b, p.model, scene::scheduler_settings(s));
  ScriptedDevice dev(s.tools.at(0).path);
  const double deepest = s.tools[0].path.at(2).t;
  TickReport rep;
  while (sched.time() < deepest - 1e-9) rep = sched.tick(dev);
  p.force = norm(rep.force);
  p.fields = b->download();
  return p;
}

/// The distance from the kidney's centre to its surface along x. A ray
/// through a surface vertex or edge (the layer's rest nodes lie on them) can slip between the triangles by rounding: then it is turned by
/// 1e-9 rad, which moves the answer by less than 1e-10 m.
double kidney_radius_along(const SurfaceMesh& kidney, Vec3<double> x) {
  for (const Vec3<double> turn : {Vec3<double>{0, 0, 0}, Vec3<double>{1e-9, 2e-9, 3e-9}, Vec3<double>{-3e-9, 1e-9, -2e-9}})
    try {
      return norm(io::surface_point_along(kidney, unit(x) + turn));
    } catch (const std::runtime_error&) {
    }
  throw std::runtime_error("no ray near this direction meets the kidney");
}

/// How far a fat node lies inside the kidney's deformed surface, along the
/// ray from the kidney's centre (the surface stays star-shaped about it
/// under a press): m, <= 0 none. Measured apart from the contact's own
/// search, which takes the nearest triangle.
double deepest_inside(const scene::Scene& s, const Press& p) {
  const scene::Body& kidney = s.bodies.at(0);
  const scene::Body& fat = s.bodies.at(1);
  const index_t n = p.model.n_nodes, nt = p.model.n_tris;
  const auto at = [&](index_t a) {
    return Vec3<double>{p.model.X[a] + p.fields.u[a], p.model.X[n + a] + p.fields.u[n + a],
                        p.model.X[2 * n + a] + p.fields.u[2 * n + a]};
  };
  SurfaceMesh deformed;
  for (index_t a = 0; a < kidney.n_nodes; ++a) {
    const Vec3<double> x = at(a);
    deformed.vertices.insert(deformed.vertices.end(), {x.x, x.y, x.z});
  }
  for (index_t t = 0; t < nt; ++t)
    if (p.model.tris[t] < kidney.n_nodes)
      for (int k = 0; k < 3; ++k) deformed.triangles.push_back(p.model.tris[k * nt + t]);
  double worst = -1;
  for (index_t a = fat.first_node; a < fat.first_node + fat.n_nodes; ++a) {
    const Vec3<double> x = at(a);
    worst = std::max(worst, kidney_radius_along(deformed, x) - norm(x));
  }
  return worst;
}

TEST(KidneyFatSurface, ClosedAndOutwardWithItsInnerSideOnTheKidney) {
  const SurfaceMesh fat = io::kidney_fat_surface();
  const SurfaceMesh kidney = io::kidney_surface(io::KidneyScene::frequency);
  // every edge in exactly two triangles, once each way
  std::map<std::pair<index_t, index_t>, int> edges;
  for (index_t t = 0; t < fat.n_triangles(); ++t)
    for (int c = 0; c < 3; ++c) ++edges[{fat.triangles[3 * t + c], fat.triangles[3 * t + (c + 1) % 3]}];
  for (const auto& [e, k] : edges) {
    EXPECT_EQ(k, 1) << "edge " << e.first << "-" << e.second;
    EXPECT_EQ(edges.count({e.second, e.first}), 1u) << "edge " << e.first << "-" << e.second << " is open";
  }
  // outward: the enclosed volume is positive, about the patch's area times the thickness
  double volume = 0;
  for (index_t t = 0; t < fat.n_triangles(); ++t)
    volume += dot(vtx(fat, fat.triangles[3 * t]), cross(vtx(fat, fat.triangles[3 * t + 1]), vtx(fat, fat.triangles[3 * t + 2]))) / 6;
  EXPECT_GT(volume, 0.0);
  // each vertex is a kidney vertex (inner side) or one moved out `thickness` along its ray (outer side)
  int inner = 0, outer = 0;
  for (index_t i = 0; i < fat.n_vertices(); ++i) {
    const Vec3<double> x = vtx(fat, i);
    double nearest = 1;
    Vec3<double> k{};
    for (index_t j = 0; j < kidney.n_vertices(); ++j)
      if (const double d = norm(unit(vtx(kidney, j)) - unit(x)); d < nearest) {
        nearest = d;
        k = vtx(kidney, j);
      }
    ASSERT_LT(nearest, 1e-12) << "vertex " << i << " is on no kidney vertex's ray";
    const double out = norm(x) - norm(k);
    if (std::fabs(out) < 1e-15) ++inner;
    else if (std::fabs(out - io::KidneyFatScene::thickness) < 1e-12) ++outer;
    else ADD_FAILURE() << "vertex " << i << " is " << out << " m out from the kidney";
  }
  EXPECT_EQ(inner, outer);
  EXPECT_GT(inner, 20);
}

TEST(KidneyFatScene, TwoBodiesInContactWithTheLayersRimHeld) {
  const scene::Scene& s = fat_scene();
  ASSERT_EQ(s.bodies.size(), 2u);
  EXPECT_EQ(s.bodies[0].name, "kidney");
  EXPECT_EQ(s.bodies[1].name, "fat");
  ASSERT_EQ(s.contacts.size(), 1u);
  EXPECT_EQ(s.contacts[0].a, "kidney");
  EXPECT_EQ(s.contacts[0].b, "fat");
  EXPECT_NO_THROW(scene::validate(s));
  // the kidney is "@kidney"'s, node for node
  const scene::Scene bare = io::default_kidney_scene();
  ASSERT_EQ(s.bodies[0].n_nodes, index_t(bare.nodes.size() / 3));
  EXPECT_TRUE(std::equal(bare.nodes.begin(), bare.nodes.end(), s.nodes.begin()));
  // the layer's held nodes: its rim, a ring around the press axis, none near the probe
  const scene::Constraint& held = s.constraints.back();
  EXPECT_EQ(held.body, 1);
  ASSERT_GT(held.nodes.size(), 20u);
  const double cos_cap = std::cos(io::KidneyFatScene::cap_angle * std::numbers::pi / 180);
  for (index_t a : held.nodes) {
    ASSERT_GE(a, s.bodies[1].first_node);
    const Vec3<double> x{s.nodes[3 * a], s.nodes[3 * a + 1], s.nodes[3 * a + 2]};
    // on the unit sphere the rim lies at the cap's edge, one geodesic cell inside at most
    const Vec3<double> p = io::kidney_sphere_direction({}, x);
    EXPECT_LT(p.y, 0.5 * (1 + cos_cap)) << "held node " << a << " is inside the layer";
  }
}

TEST(KidneyFatScene, WrittenAndReadBackItIsTheSameScene) {
  testing_support::TempDir dir;
  io::write_scene(fat_scene(), dir.file("k.xml"), false);
  const scene::Scene back = io::read_scene(dir.file("k.xml"));
  EXPECT_EQ(back.nodes, fat_scene().nodes);
  EXPECT_EQ(back.tets, fat_scene().tets);
  ASSERT_EQ(back.bodies.size(), 2u);
  EXPECT_EQ(back.bodies[1].n_nodes, fat_scene().bodies[1].n_nodes);
  ASSERT_EQ(back.contacts.size(), 1u);
  EXPECT_EQ(back.contacts[0].b, "fat");
  EXPECT_EQ(back.constraints.back().nodes, fat_scene().constraints.back().nodes);
}

TEST(KidneyFatScene, APalpationThroughTheLayerFeelsTheKidney) {
  const scene::Scene& s = fat_scene();
  const Press through = press(s);
  scene::Scene apart = s;
  apart.contacts.clear();  // the layer alone: it passes through the kidney
  const Press alone = press(apart);
  const Press bare = press(io::default_kidney_scene());
  RecordProperty("force_through_layer_N", std::to_string(through.force));
  RecordProperty("force_layer_alone_N", std::to_string(alone.force));
  RecordProperty("force_bare_kidney_N", std::to_string(bare.force));
  RecordProperty("fat_inside_kidney_m", std::to_string(deepest_inside(s, through)));
  for (double J : through.fields.elem_J) ASSERT_GT(J, 0.0);
  // measured (cpu, double): 0.0853 N through the layer, 0.0255 N from the layer alone (3.3 times less),
  // 0.1003 N on the bare kidney the same depth below its surface
  EXPECT_GT(through.force, 2 * alone.force) << through.force << " N through the layer, " << alone.force << " alone";
  EXPECT_LT(through.force, bare.force) << through.force << " N through the layer, " << bare.force << " N bare";
  // the kidney under the probe moves: it is pressed through the layer
  const index_t n = through.model.n_nodes;
  double kidney_most = 0;
  for (index_t a = 0; a < s.bodies[0].n_nodes; ++a)
    kidney_most = std::max(kidney_most, std::hypot(through.fields.u[a], through.fields.u[n + a], through.fields.u[2 * n + a]));
  EXPECT_GT(kidney_most, 1e-3) << "the kidney moved " << kidney_most << " m";
  // Where the probe pinches the layer against the kidney, a fat node lies inside the kidney's deformed
  // surface: the tool's stage, after the bodies', pushes the layer in, and the next step's body stage
  // pushes it back out (measured 0.20 mm at the deepest press, 7 % of the 2.9 mm median surface edge;
  // docs/contact.md, section 7). Tolerance: a sixth of that edge.
  EXPECT_LT(deepest_inside(s, through), 0.5e-3) << deepest_inside(s, through) << " m inside";
  EXPECT_GT(deepest_inside(s, alone), 1e-3) << "without contact the layer should pass into the kidney";
}

// The cuda backend presses through the layer as the cpu does. The layer's
// inner nodes start exactly on the kidney's vertices and edges, ties that
// rounding may break the other way on the device (docs/contact.md, section
// 7), and the runs part: measured on an H200, the force 7.3e-4 and u 1.5e-3
// of its largest apart in double. Tolerances: 2e-3 and 5e-3.
TEST(KidneyFatScene, CudaPressesThroughTheLayerAsTheCpu) {
  SKIP_UNLESS_USABLE("cuda");
  const Press cpu = press(fat_scene()), cuda = press(fat_scene(), "cuda");
  RecordProperty("force_cpu_N", std::to_string(cpu.force));
  RecordProperty("force_cuda_N", std::to_string(cuda.force));
  EXPECT_NEAR(cuda.force, cpu.force, 2e-3 * cpu.force);
  double most = 0, diff = 0;
  for (std::size_t i = 0; i < cpu.fields.u.size(); ++i) {
    most = std::max(most, std::fabs(cpu.fields.u[i]));
    diff = std::max(diff, std::fabs(cuda.fields.u[i] - cpu.fields.u[i]));
  }
  RecordProperty("u_difference_of_max", std::to_string(diff / most));
  EXPECT_LT(diff, 5e-3 * most) << diff / most << " of max |u|";
}

}  // namespace
}  // namespace tissue
