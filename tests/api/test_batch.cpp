// The batch facade (tissue/batch.hpp) on every backend and precision this
// machine runs: a scene in a batch gives what the same scene gives alone in
// a Simulation (bit for bit on the cpu and in double on cuda, within a
// stated tolerance in float on cuda), with mixed meshes, mixed materials,
// tools in and out of contact, and one scene made to fail; the arrays'
// layouts, material changes and every misuse.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "backends/registry.hpp"
#include "core/box_mesh.hpp"
#include "session/scene_batch.hpp"
#include "tissue/batch.hpp"
#include "tissue/simulation.hpp"
#include "tests/api/api_test_support.hpp"

namespace {

using tissue::Batch;
using tissue::BatchScene;
using tissue::Field;
using tissue::Simulation;
using tissue::test::block;
using tissue::test::thrown;

/// A block finer than block(): another mesh.
tissue::MeshScene fine_block(double E) { return block(E, 1, 8); }

BatchScene mesh(const tissue::MeshScene& m) {
  return {"", {}, m};
}

/// The tip over the block's top centre, `depth` below its surface after `ticks` of a press starting at tick 0.
tissue::Vector3 press_pose(long tick, double depth, double x = 0.01) {
  const double s = std::min(1.0, double(tick) / 40.0);
  return {x, 0.01, 0.01 + 4e-3 - s * depth};
}

struct Config {
  std::string backend, precision;
};

std::string config_name(const testing::TestParamInfo<Config>& p) {
  return p.param.backend + "_" + p.param.precision;
}

std::vector<Config> configs() {
  std::vector<Config> out;
  for (const std::string& b : tissue::available_backends())
    for (const char* p : {"float", "double"}) out.push_back({b, p});
  return out;
}

class BatchEquals : public testing::TestWithParam<Config> {
 protected:
  tissue::SimulationOptions options() const { return {GetParam().backend, GetParam().precision, "all"}; }
  /// Bit for bit, except cuda in float: within 1e-6 of the largest magnitude (the stated tolerance,
  /// docs/batch.md).
  bool exact() const { return !(GetParam().backend == "cuda" && GetParam().precision == "float"); }

  void expect_same(const std::vector<double>& a, const std::vector<double>& b, const std::string& what) const {
    ASSERT_EQ(a.size(), b.size()) << what;
    double scale = 0;
    for (double v : b) scale = std::max(scale, std::abs(v));
    std::size_t differ = 0;
    double worst = 0;
    for (std::size_t k = 0; k < a.size(); ++k) {
      if (a[k] != b[k]) ++differ;
      worst = std::max(worst, std::abs(a[k] - b[k]));
    }
    if (exact())
      EXPECT_EQ(differ, 0u) << what << ": " << differ << " of " << a.size() << " values differ, worst by " << worst;
    else
      EXPECT_LE(worst, 1e-6 * scale) << what << ": worst difference " << worst << " against " << scale;
  }

  void expect_same_scene(Batch& batch, int i, Simulation& alone, const std::string& what) {
    ASSERT_EQ(batch.ticks(i), alone.ticks()) << what;
    for (int t = 0; t < alone.n_tools(); ++t) {
      const tissue::Vector3 fb = batch.last(i).tools[std::size_t(t)].force, fa = alone.force(t);
      expect_same({fb.begin(), fb.end()}, {fa.begin(), fa.end()}, what + " force of tool " + std::to_string(t));
      EXPECT_EQ(batch.last(i).tools[std::size_t(t)].contact_nodes, alone.last().tools[std::size_t(t)].contact_nodes)
          << what;
    }
    std::vector<double> u(batch.n_nodes(i) * 3);
    batch.read_field(i, Field::Displacement, u);
    expect_same(u, alone.field(Field::Displacement), what + " displacement");
  }
};

// Four scenes: the kidney on its scripted press, a block pressed by the host, a stiffer block on another mesh
// pressed elsewhere, and a block whose tool stays in the air (out of contact). Each equals its scene alone.
TEST_P(BatchEquals, MixedMeshesMaterialsAndToolsEqualEachSceneAlone) {
  std::vector<BatchScene> list = {{"@kidney", {}, {}}, mesh(block(3000)), mesh(fine_block(9000)), mesh(block(3000))};
  Batch batch = Batch::load(list, options());
  ASSERT_EQ(batch.size(), 4u);
  EXPECT_EQ(batch.backend(), GetParam().backend);
  EXPECT_EQ(batch.precision(), GetParam().precision);
  EXPECT_EQ(batch.distinct_models(), 3u);  // the two blocks of one mesh and material share their model
  if (GetParam().backend == "cpu") {
    EXPECT_GT(batch.scene_host_bytes(), 0);
  } else {
    EXPECT_GT(batch.scene_device_bytes(), 0);
  }

  std::vector<Simulation> alone;
  alone.push_back(Simulation::load("@kidney", options()));
  alone.push_back(Simulation::from_mesh(block(3000), options()));
  alone.push_back(Simulation::from_mesh(fine_block(9000), options()));
  alone.push_back(Simulation::from_mesh(block(3000), options()));

  const int ticks = 160;  // the kidney's scripted probe reaches the surface after 100
  for (long k = 1; k <= ticks; ++k) {
    batch.set_tool_pose(1, 0, press_pose(k, 2e-3));
    alone[1].set_tool_pose(0, press_pose(k, 2e-3));
    batch.set_tool_pose(2, 0, press_pose(k, 1.5e-3, 0.012));
    alone[2].set_tool_pose(0, press_pose(k, 1.5e-3, 0.012));
    batch.set_tool_pose(3, 0, {0.01, 0.01, 0.03});
    alone[3].set_tool_pose(0, {0.01, 0.01, 0.03});
    EXPECT_EQ(batch.step(), 4u);
    for (Simulation& s : alone) s.step();
  }
  EXPECT_GT(batch.last(0).tools[0].contact_nodes, 0) << "the kidney's probe touches";
  EXPECT_GT(batch.last(1).tools[0].contact_nodes, 0);
  EXPECT_GT(batch.last(2).tools[0].contact_nodes, 0);
  EXPECT_EQ(batch.last(3).tools[0].contact_nodes, 0) << "the fourth tool stays in the air";
  EXPECT_GT(std::abs(batch.last(2).tools[0].force[2]), std::abs(batch.last(1).tools[0].force[2]))
      << "the stiffer block presses back harder";
  for (int i = 0; i < 4; ++i) expect_same_scene(batch, i, alone[std::size_t(i)], "scene " + std::to_string(i));
  if (GetParam().backend == "cuda") {  // four meshes' fields are not one device array
    EXPECT_NE(thrown([&] { batch.device_field(Field::Displacement); }).find("does not lie one stride after"),
              std::string::npos);
  }
}

// A scene driven to blow up by a huge point load stops alone, named; the others go on equal to their scenes
// alone; reset brings it back, equal to a fresh scene.
TEST_P(BatchEquals, AFailingSceneStopsAloneAndResetsAlone) {
  Batch batch = Batch::load({mesh(block(3000)), mesh(block(3000)), mesh(block(5000))}, options());
  Simulation a = Simulation::from_mesh(block(3000), options());
  Simulation c = Simulation::from_mesh(block(5000), options());
  const int top = tissue::box_node(6, 6, 3, 3, 3);
  const std::vector<std::int32_t> node = {top};
  const std::vector<double> huge = {0, 0, -1e9};
  batch.set_loads(1, node, huge);
  for (long k = 1; k <= 30; ++k) {
    batch.set_tool_pose(0, 0, press_pose(k, 2e-3));
    a.set_tool_pose(0, press_pose(k, 2e-3));
    batch.set_tool_pose(2, 0, press_pose(k, 1e-3));
    c.set_tool_pose(0, press_pose(k, 1e-3));
    batch.step();
    a.step();
    c.step();
  }
  ASSERT_EQ(batch.failed_scenes(), std::vector<int>{1});
  EXPECT_TRUE(batch.failed(1));
  EXPECT_FALSE(batch.failed(0));
  const std::string why = batch.failure(1);
  EXPECT_TRUE(why.find("element") != std::string::npos || why.find("non-finite") != std::string::npos) << why;
  // the stop says where its element lies against the tool, and names the host's load as its likely cause:
  // 1e9 N over a 2 cm block is far beyond any strain
  EXPECT_NE(why.find("(its centroid at ("), std::string::npos) << why;
  EXPECT_NE(why.find("mm from tool 'tool0')"), std::string::npos) << why;  // the tool was not yet near
  EXPECT_NE(why.find("likely cause:\n    the loads set through the API (set_loads, on 1 node): their total force 1e+09 N"),
            std::string::npos)
      << why;
  EXPECT_LT(batch.ticks(1), 30) << "the failed scene stopped";
  expect_same_scene(batch, 0, a, "scene 0 beside a failure");
  expect_same_scene(batch, 2, c, "scene 2 beside a failure");

  // scene 1 again from rest, without the load: it equals a fresh block
  batch.set_loads(1, {}, {});
  batch.reset(1);
  EXPECT_FALSE(batch.failed(1));
  EXPECT_EQ(batch.ticks(1), 0);
  Simulation fresh = Simulation::from_mesh(block(3000), options());
  for (long k = 1; k <= 20; ++k) {
    batch.set_tool_pose(1, 0, press_pose(k, 2e-3));
    fresh.set_tool_pose(0, press_pose(k, 2e-3));
    EXPECT_EQ(batch.step(), 3u);
    fresh.step();
  }
  expect_same_scene(batch, 1, fresh, "scene 1 after its reset");
}

// Scenes of one mesh and one step but different materials (a sweep of E and rho): on cuda one group whose
// every scene reads its own moduli, masses and constants; each equals its scene alone. Two far stiffer scenes
// take a smaller step: a second group.
TEST_P(BatchEquals, ScenesOfOneMeshWithDifferentMaterialsRunTogetherAndEqualEachAlone) {
  const std::vector<double> E = {3000, 3150, 2900, 3050, 40000, 40500};
  std::vector<BatchScene> list;
  std::vector<Simulation> alone;
  for (std::size_t i = 0; i < E.size(); ++i) {
    tissue::MeshScene m = block(E[i]);
    m.density = 1000 + 10 * double(i);
    list.push_back(mesh(m));
    alone.push_back(Simulation::from_mesh(m, options()));
  }
  Batch batch = Batch::load(list, options());
  for (std::size_t i = 1; i < 4; ++i) ASSERT_EQ(batch.dt(int(i)), batch.dt(0)) << "the test wants one step for E ~ 3 kPa";
  ASSERT_EQ(batch.dt(5), batch.dt(4));
  ASSERT_NE(batch.dt(4), batch.dt(0)) << "the test wants a smaller step for E = 40 kPa";
  EXPECT_EQ(batch.distinct_models(), E.size());
  const int ticks = 50;
  for (long k = 1; k <= ticks; ++k) {
    for (std::size_t i = 0; i < E.size(); ++i) {
      batch.set_tool_pose(int(i), 0, press_pose(k, (1.0 + 0.2 * double(i)) * 1e-3));
      alone[i].set_tool_pose(0, press_pose(k, (1.0 + 0.2 * double(i)) * 1e-3));
    }
    EXPECT_EQ(batch.step(), E.size());
    for (Simulation& s : alone) s.step();
  }
  if (GetParam().backend == "cuda") {
    EXPECT_EQ(batch.groups(), 2u);
    EXPECT_EQ(batch.ticks_together(), std::int64_t(E.size()) * ticks) << "every tick of every scene ran in a group";
  }
  for (std::size_t i = 0; i < E.size(); ++i) expect_same_scene(batch, int(i), alone[i], "scene " + std::to_string(i));
  const auto mag = [](const tissue::Vector3& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); };
  EXPECT_GT(mag(batch.last(1).tools[0].force), mag(batch.last(0).tools[0].force)) << "stiffer, deeper";
}

// Blocks of one mesh whose tools have friction coefficients of their own (set live, per scene), pressed and then
// dragged sideways: on cuda one group whose reductions read each slot's coefficient; each equals its scene
// alone, and the drag's tangential force grows with the coefficient.
TEST_P(BatchEquals, ScenesWithTheirOwnFrictionRunTogetherAndEqualEachAlone) {
  const std::vector<double> mu = {0, 0.2, 0.5, 5};
  std::vector<BatchScene> list;
  std::vector<Simulation> alone;
  for (std::size_t i = 0; i < mu.size(); ++i) {
    list.push_back(mesh(block(3000)));
    alone.push_back(Simulation::from_mesh(block(3000), options()));
  }
  Batch batch = Batch::load(list, options());
  for (std::size_t i = 0; i < mu.size(); ++i) {
    batch.set_tool_friction(int(i), 0, mu[i]);
    alone[i].set_tool_friction(0, mu[i]);
    EXPECT_EQ(batch.tool_friction(int(i), 0), mu[i]);
  }
  const int ticks = 90;
  for (long k = 1; k <= ticks; ++k) {
    const double x = 0.01 + (k > 40 ? 2e-5 * double(k - 40) : 0.0);  // pressed 1 mm, then dragged 1 mm along x
    for (std::size_t i = 0; i < mu.size(); ++i) {
      batch.set_tool_pose(int(i), 0, press_pose(k, 1e-3, x));
      alone[i].set_tool_pose(0, press_pose(k, 1e-3, x));
    }
    EXPECT_EQ(batch.step(), mu.size());
    for (Simulation& s : alone) s.step();
  }
  if (GetParam().backend == "cuda") EXPECT_EQ(batch.ticks_together(), std::int64_t(mu.size()) * ticks);
  for (std::size_t i = 0; i < mu.size(); ++i) expect_same_scene(batch, int(i), alone[i], "scene " + std::to_string(i));
  for (std::size_t i = 1; i < mu.size(); ++i)
    EXPECT_LT(batch.last(int(i)).tools[0].force[0], batch.last(int(i - 1)).tools[0].force[0])
        << "the tissue holds a rougher tool back harder (scene " << i << ")";
  EXPECT_THROW(batch.set_tool_friction(0, 0, -1), std::invalid_argument);
  EXPECT_THROW(batch.set_tool_friction(9, 0, 0.1), std::invalid_argument);
}

// Blocks of one model, two of them under loads of their own set by the host: on cuda one group (the loaded and
// the unloaded scenes in graphs of their own kind), every tick run in it; each equals its scene alone.
TEST_P(BatchEquals, LoadedScenesRunInTheirGroupAndEqualEachAlone) {
  const int n = 4, ticks = 60;
  Batch batch = Batch::load(std::vector<BatchScene>(n, mesh(block(3000))), options());
  std::vector<Simulation> alone;
  for (int i = 0; i < n; ++i) alone.push_back(Simulation::from_mesh(block(3000), options()));
  const std::vector<std::int32_t> corner = {tissue::box_node(6, 6, 6, 6, 3)}, edge = {tissue::box_node(6, 6, 0, 3, 3)};
  const std::vector<double> up = {0, 0, 2e-3}, side = {1e-3, 0, 0};
  batch.set_loads(1, corner, up);
  alone[1].set_loads(corner, up);
  batch.set_loads(3, edge, side);
  alone[3].set_loads(edge, side);
  for (long k = 1; k <= ticks; ++k) {
    for (int i = 0; i < n; ++i) {
      batch.set_tool_pose(i, 0, press_pose(k, (1.0 + 0.25 * i) * 1e-3));
      alone[std::size_t(i)].set_tool_pose(0, press_pose(k, (1.0 + 0.25 * i) * 1e-3));
    }
    EXPECT_EQ(batch.step(), std::size_t(n));
    for (Simulation& s : alone) s.step();
  }
  if (GetParam().backend == "cuda") {
    EXPECT_EQ(batch.groups(), 1u);
    EXPECT_EQ(batch.ticks_together(), std::int64_t(n) * ticks) << "the loaded scenes' ticks ran in the group too";
  }
  for (int i = 0; i < n; ++i) expect_same_scene(batch, i, alone[std::size_t(i)], "scene " + std::to_string(i));
  std::vector<double> u1(batch.n_nodes(1) * 3), u0(u1.size());
  batch.read_field(1, Field::Displacement, u1);
  batch.read_field(0, Field::Displacement, u0);
  EXPECT_NE(u1, u0) << "the load moves its scene";
}

// Viscoelastic kidneys of one mesh with different Prony terms (and one stiffer): on cuda one group whose every
// scene reads its own law arrays and Prony state; each equals its scene alone (a batch of one scene).
TEST_P(BatchEquals, ViscoelasticScenesOfOneMeshRunTogetherAndEqualEachAlone) {
  using tissue::MaterialChange;
  using tissue::PronyChange;
  const std::vector<MaterialChange> changes = {
      MaterialChange{},
      MaterialChange{"", {}, {}, {}, {}, {PronyChange{1, 0.3, 0.05}}},
      MaterialChange{"", {}, {}, 1100.0, {}, {PronyChange{2, {}, 2.0}}},
      MaterialChange{"", {}, {}, {}, {}, {PronyChange{1, 0.1, {}}, PronyChange{2, 0.05, 0.4}}}};
  std::vector<BatchScene> list;
  for (const MaterialChange& c : changes) list.push_back({"@kidney-visco", {c}, {}});
  Batch batch = Batch::load(list, options());
  std::vector<Batch> alone;
  for (const BatchScene& b : list) alone.push_back(Batch::load({b}, options()));
  for (std::size_t i = 1; i < list.size(); ++i) ASSERT_EQ(batch.dt(int(i)), batch.dt(0)) << "one step for all";
  const int ticks = 130;  // the scripted probe reaches the surface after 100
  for (int k = 0; k < ticks; ++k) {
    EXPECT_EQ(batch.step(), list.size());
    for (Batch& a : alone) a.step();
  }
  if (GetParam().backend == "cuda") {
    EXPECT_EQ(batch.groups(), 1u);
    EXPECT_EQ(batch.ticks_together(), std::int64_t(list.size()) * ticks) << "every tick of every scene ran in the group";
  }
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string what = "visco scene " + std::to_string(i);
    const tissue::Vector3 fb = batch.last(int(i)).tools[0].force, fa = alone[i].last(0).tools[0].force;
    EXPECT_GT(std::abs(fa[2]), 0.0) << what << " presses";
    expect_same({fb.begin(), fb.end()}, {fa.begin(), fa.end()}, what + " force");
    std::vector<double> ub(batch.n_nodes(int(i)) * 3), ua(ub.size());
    batch.read_field(int(i), Field::Displacement, ub);
    alone[i].read_field(0, Field::Displacement, ua);
    expect_same(ub, ua, what + " displacement");
  }
  EXPECT_NE(batch.last(1).tools[0].force[2], batch.last(0).tools[0].force[2]) << "the Prony terms matter";
}

// Scenes of one model: on cuda one group, each pass of a tick one launch over them all (docs/batch.md, "One
// launch per pass"), with tools pressing at different depths and places, one in the air and one grasping;
// each scene equals its scene alone.
TEST_P(BatchEquals, ScenesOfOneModelRunTogetherAndEqualEachAlone) {
  const int n = 5, ticks = 60;
  Batch batch = Batch::load(std::vector<BatchScene>(n, mesh(block(3000))), options());
  std::vector<Simulation> alone;
  for (int i = 0; i < n; ++i) alone.push_back(Simulation::from_mesh(block(3000), options()));
  const auto pose = [](int i, long k) {
    return i == 4 ? tissue::Vector3{0.01, 0.01, 0.03} : press_pose(k, (1.0 + 0.3 * i) * 1e-3, 0.008 + 0.001 * i);
  };
  for (long k = 1; k <= ticks; ++k) {
    for (int i = 0; i < n; ++i) {
      batch.set_tool_pose(i, 0, pose(i, k));
      alone[std::size_t(i)].set_tool_pose(0, pose(i, k));
    }
    if (k == 45) {  // scene 2 grasps what its tool touches
      batch.set_grasp(2, 0, true);
      alone[2].set_grasp(0, true);
    }
    EXPECT_EQ(batch.step(), std::size_t(n));
    for (Simulation& s : alone) s.step();
  }
  if (GetParam().backend == "cuda") {
    EXPECT_EQ(batch.groups(), 1u);
    EXPECT_EQ(batch.ticks_together(), std::int64_t(n) * ticks) << "every tick of every scene ran in the group";
  } else {
    EXPECT_EQ(batch.groups(), 0u);
    EXPECT_EQ(batch.ticks_together(), 0);
  }
  EXPECT_EQ(batch.last(4).tools[0].contact_nodes, 0) << "the fifth tool stays in the air";
  EXPECT_GT(batch.last(2).tools[0].grasped_nodes, 0) << "the third scene grasps";
  for (int i = 0; i < n; ++i) expect_same_scene(batch, i, alone[std::size_t(i)], "scene " + std::to_string(i));

  // the fields where they lie: every scene's one stride apart, equal to what read_field copies out
  if (GetParam().backend != "cuda") {
    EXPECT_NE(thrown([&] { batch.device_field(Field::Displacement); }).find("keeps its fields on the host"),
              std::string::npos);
    return;
  }
  for (Field f : {Field::Displacement, Field::InternalForce}) {
    const Batch::DeviceView all = batch.device_field(f);
    const std::int64_t nodes = std::int64_t(batch.n_nodes(0));
    ASSERT_EQ(all.shape, (std::vector<std::int64_t>{n, nodes, 3}));
    ASSERT_EQ(all.strides.size(), 3u);
    for (int i = 0; i < n; ++i) {
      const Batch::DeviceView one = batch.device_field(i, f);
      EXPECT_EQ(one.data, all.data + std::uintptr_t(i * all.strides[0])) << "scene " << i;
      std::vector<unsigned char> raw(std::size_t(nodes * one.strides[0]));
      tissue::copy_from_device(reinterpret_cast<const void*>(one.data), raw.data(), raw.size());
      std::vector<double> host(std::size_t(nodes) * 3), device(host.size());
      batch.read_field(i, f, host);
      for (std::int64_t a = 0; a < nodes; ++a)
        for (int c = 0; c < 3; ++c) {
          const unsigned char* p = raw.data() + a * one.strides[0] + c * one.strides[1];
          double v = 0;
          if (one.scalar_bytes == 4) {
            float x;
            std::memcpy(&x, p, 4);
            v = x;
          } else {
            std::memcpy(&v, p, 8);
          }
          device[std::size_t(3 * a + c)] = v;
        }
      EXPECT_EQ(device, host) << "scene " << i << " field " << int(f);
    }
  }
  EXPECT_NE(thrown([&] { batch.device_field(Field::Pressure); }).find("only the displacement and the internal force"),
            std::string::npos);
}

// A material change, given at load or later, equals the scene built with that material.
TEST_P(BatchEquals, MaterialChangesEqualTheSceneWithThatMaterial) {
  BatchScene changed = mesh(block(3000));
  changed.materials.push_back({"", 6000.0, std::nullopt, std::nullopt});
  Batch batch = Batch::load({changed, mesh(block(3000))}, options());
  batch.set_material(1, {"tissue", 4500.0, 0.45, std::nullopt});
  Simulation six = Simulation::from_mesh(block(6000), options());
  tissue::MeshScene m = block(4500);
  m.poisson_ratio = 0.45;
  Simulation other = Simulation::from_mesh(m, options());
  for (long k = 1; k <= 40; ++k) {
    for (int i = 0; i < 2; ++i) batch.set_tool_pose(i, 0, press_pose(k, 1.5e-3));
    six.set_tool_pose(0, press_pose(k, 1.5e-3));
    other.set_tool_pose(0, press_pose(k, 1.5e-3));
    batch.step();
    six.step();
    other.step();
  }
  expect_same_scene(batch, 0, six, "E changed at load");
  expect_same_scene(batch, 1, other, "E and nu changed later");
}

INSTANTIATE_TEST_SUITE_P(Backends, BatchEquals, testing::ValuesIn(configs()), config_name);

// Forces are scenes x the most tools x 3, zero past a scene's own tools; fields are scenes x nodes x 3.
TEST(Batch, ArraysHaveTheBatchLayout) {
  Batch batch = Batch::load({mesh(block(3000, 2)), mesh(block(3000, 1))}, {"cpu", "double", "all"});
  ASSERT_EQ(batch.max_tools(), 2);
  // every tool pressed at once from one array; scene 1's second row is ignored
  std::vector<double> tips(2 * 2 * 3);
  for (long k = 1; k <= 30; ++k) {
    const tissue::Vector3 a = press_pose(k, 1e-3, 0.006), b = press_pose(k, 1e-3, 0.014);
    std::copy(a.begin(), a.end(), tips.begin());
    std::copy(b.begin(), b.end(), tips.begin() + 3);
    std::copy(a.begin(), a.end(), tips.begin() + 6);
    std::copy(b.begin(), b.end(), tips.begin() + 9);
    batch.set_tool_poses(tips);
    batch.step();
  }
  const std::vector<double> f = batch.forces();
  ASSERT_EQ(f.size(), 12u);
  EXPECT_GT(f[2], 0) << "scene 0 tool 0 is pushed up";
  EXPECT_GT(f[5], 0) << "scene 0 tool 1 is pushed up";
  EXPECT_GT(f[8], 0) << "scene 1 tool 0 is pushed up";
  EXPECT_EQ(f[9], 0);
  EXPECT_EQ(f[10], 0);
  EXPECT_EQ(f[11], 0) << "scene 1 has no tool 1";
  EXPECT_EQ(f[8], batch.last(1).tools[0].force[2]);
  const std::vector<double> u = batch.fields(Field::Displacement);
  ASSERT_EQ(u.size(), 2 * batch.n_nodes(0) * 3);
  std::vector<double> u1(batch.n_nodes(1) * 3);
  batch.read_field(1, Field::Displacement, u1);
  EXPECT_TRUE(std::equal(u1.begin(), u1.end(), u.begin() + std::ptrdiff_t(u1.size())));
  const std::vector<double> J = batch.fields(Field::Jacobian);
  EXPECT_EQ(J.size(), 2 * batch.n_elements(0));
}

// A scene of touching bodies in a batch, beside a scene without them:
// its body contacts are the Simulation's, the other scene has none.
TEST(Batch, BodyContactsOfASceneAreTheSimulations) {
  Batch batch = Batch::load({BatchScene{"@kidney-fat", {}, {}}, BatchScene{"@kidney", {}, {}}}, {"cpu", "", ""});
  Simulation sim = Simulation::load("@kidney-fat", {"cpu", "", ""});
  const tissue::ToolResult first = sim.step().tools[0];
  batch.step();
  for (int k = 1; k <= 24; ++k) {
    sim.set_tool_pose(0, tissue::test::fat_press_tip(first, k));
    sim.step();
    batch.set_tool_pose(0, 0, tissue::test::fat_press_tip(first, k));
    batch.step();
  }
  const std::vector<tissue::BodyContact> alone = sim.body_contacts(), in_batch = batch.body_contacts(0);
  ASSERT_FALSE(alone.empty());
  ASSERT_EQ(in_batch.size(), alone.size());
  for (std::size_t i = 0; i < alone.size(); ++i) {
    EXPECT_EQ(in_batch[i].node, alone[i].node) << i;
    EXPECT_EQ(in_batch[i].triangle, alone[i].triangle) << i;
    EXPECT_EQ(in_batch[i].body, alone[i].body) << i;
    EXPECT_EQ(in_batch[i].other_body, alone[i].other_body) << i;
    EXPECT_EQ(in_batch[i].depth, alone[i].depth) << i;
  }
  EXPECT_TRUE(batch.body_contacts(1).empty());
  EXPECT_NE(thrown([&] { batch.body_contacts(2); }).find("scene 2 does not exist"), std::string::npos);
}

TEST(Batch, MisuseIsAClearError) {
  Batch batch = Batch::load({mesh(block(3000)), mesh(fine_block(3000))}, {"cpu", "float", "all"});
  EXPECT_NE(thrown([&] { batch.set_tool_pose(2, 0, {0, 0, 0}); }).find("scene 2 does not exist"), std::string::npos);
  EXPECT_NE(thrown([&] { batch.set_tool_pose(0, 1, {0, 0, 0}); }).find("tool 1 does not exist"), std::string::npos);
  EXPECT_NE(thrown([&] { batch.set_tool_pose(0, 0, {0, NAN, 0}); }).find("not finite"), std::string::npos);
  EXPECT_NE(thrown([&] { batch.set_tool_poses(std::vector<double>(5)); }).find("needs 6"), std::string::npos);
  std::vector<double> tips(6, 0.0);
  tips[4] = INFINITY;
  const std::string inf = thrown([&] { batch.set_tool_poses(tips); });
  EXPECT_NE(inf.find("set_tool_poses: scene 1: "), std::string::npos) << inf;
  EXPECT_NE(inf.find("tool 0 pose"), std::string::npos) << inf;
  tips[4] = 1e300;  // farther than a scene's waypoints may be
  EXPECT_NE(thrown([&] { batch.set_tool_poses(tips); }).find("from the mesh, more than 1000 x its size"),
            std::string::npos);
  EXPECT_NE(thrown([&] { batch.set_tool_pose(0, 0, {0, 0, 1e300}); }).find("coordinates are metres"),
            std::string::npos);
  EXPECT_NE(thrown([&] { batch.fields(Field::Displacement); }).find("scenes 0"), std::string::npos)
      << "scenes of different meshes have no (N, nodes, 3) field";
  EXPECT_NE(thrown([&] { batch.step(0); }).find("must be >= 1"), std::string::npos);
  const std::string bad_E = thrown([&] { batch.set_material(0, {"tissue", -5.0, std::nullopt, std::nullopt}); });
  EXPECT_NE(bad_E.find("batch scene 0"), std::string::npos) << bad_E;
  EXPECT_NE(bad_E.find("tissue"), std::string::npos) << bad_E;
  const std::string unknown = thrown([&] { batch.set_material(1, {"liver", 5000.0, std::nullopt, std::nullopt}); });
  EXPECT_NE(unknown.find("no material 'liver'"), std::string::npos) << unknown;
  EXPECT_NE(thrown([] { Batch::load("@kidney", 0); }).find("copies = 0"), std::string::npos);
  EXPECT_NE(thrown([] { Batch::load(std::vector<BatchScene>{}); }).find("no scenes"), std::string::npos);
  EXPECT_NE(thrown([] { Batch::load({{"/nonexistent/scene.xml", {}, {}}}); }).find("scene.xml"), std::string::npos);
  // a refused material change leaves the scene as it was
  EXPECT_FALSE(batch.failed(0));
  EXPECT_EQ(batch.step(), 2u);
}

// The memory rule: the first scene's measured size times the count against what the machine has.
TEST(Batch, RefusesABatchBeyondMemoryNamingTheSizes) {
  tissue::BatchMemory m;
  m.per_scene_host = 2ll << 20;
  m.host_available = 1ll << 30;
  EXPECT_NO_THROW(tissue::check_batch_memory(400, m, "cpu"));
  const std::string host = thrown([&] { tissue::check_batch_memory(1000, m, "cpu"); });
  EXPECT_NE(host.find("1000 scenes"), std::string::npos) << host;
  EXPECT_NE(host.find("host memory"), std::string::npos) << host;
  m.per_scene_device = 64ll << 20;
  m.device_free = 1ll << 30;
  const std::string device = thrown([&] { tissue::check_batch_memory(100, m, "NVIDIA H200"); });
  EXPECT_NE(device.find("device memory"), std::string::npos) << device;
  EXPECT_NE(device.find("NVIDIA H200"), std::string::npos) << device;
}

// A hundred million copies are refused at once, before a list of that many is made (it ran for minutes).
TEST(Batch, RefusesAHugeCopyCountBeforeBuildingAnything) {
  // (the message is check_batch_size's, made before any scene is read)
  const std::string why = thrown([] { Batch::load("@kidney", 100000000, {"cpu"}); });
  EXPECT_NE(why.find("a batch of 100000000 scenes needs at least"), std::string::npos) << why;
}

}  // namespace
