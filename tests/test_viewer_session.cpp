// The viewer's live material edits (apps/viewer/session.hpp): the scene's
// fibre and Prony terms read into LiveParams, applied back to every set,
// and bad edits refused with the scene file and the material's line; the
// scalpel, a blade the haptic loop cuts with, and the cut faces drawn.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>

#include "apps/viewer/session.hpp"
#include "apps/viewer/surface_rings.hpp"
#include "cut_scenes.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"

namespace tissue::viewer {
namespace {

TEST(ViewerSession, ReadsTheViscoelasticKidneysPronySeries) {
  const Session s = make_session(io::viscoelastic_kidney_scene(), "", "", "");
  ASSERT_EQ(s.params.prony_terms, 2);
  EXPECT_EQ(s.params.prony_g[0], io::kKidneyPronyG[0]);
  EXPECT_EQ(s.params.prony_tau[1], io::kKidneyPronyTau[1]);
  EXPECT_EQ(s.params.fibre_eta, 0);  // editable: none yet
}

TEST(ViewerSession, EditsMakeTheKidneyViscoelasticAndFibred) {
  const Session s = make_session(io::default_kidney_scene(), "", "", "");
  EXPECT_EQ(s.params.prony_terms, 0);
  LiveParams p = s.params;
  p.prony_terms = 1;
  p.prony_g[0] = 0.4;
  p.prony_tau[0] = 0.5;
  p.fibre_eta = 2000;
  const TissueModel<double> m = scene::load_model(with_params(s.scene, p));
  EXPECT_EQ(m.n_visco, m.n_elems);
  EXPECT_NEAR(m.prony_gain[0], 0.4 * (1 - std::exp(-m.dt / 0.5)), 1e-15);
  ASSERT_TRUE(m.has_fibre());
  EXPECT_EQ(m.fibre[0], 1.0);               // direction x
  EXPECT_EQ(m.fibre[3 * m.n_elems], 2000);  // eta
  // keeping the scene's terms (< 0) leaves them alone
  LiveParams keep = s.params;
  keep.prony_terms = -1;
  keep.fibre_eta = -1;
  EXPECT_FALSE(scene::load_model(with_params(s.scene, keep)).has_visco());
}

TEST(ViewerSession, FrictionEditsReachEveryToolAndRebuildsKeepThem) {
  const Session s = make_session(io::default_kidney_scene(), "", "", "");
  EXPECT_EQ(s.params.friction, 0.0);  // the kidney's probe is frictionless
  LiveParams p = s.params;
  p.friction = 0.4;
  for (const scene::Tool& t : with_params(s.scene, p).tools) EXPECT_EQ(t.friction, 0.4);
  p.friction = -1;  // the scene's
  for (const scene::Tool& t : with_params(s.scene, p).tools) EXPECT_EQ(t.friction, 0.0);
}

TEST(ViewerSession, BadEditsNameTheSceneAndTheMaterial) {
  const Session s = make_session(io::default_kidney_scene(), "", "", "");
  LiveParams p = s.params;
  p.prony_terms = 2;
  p.prony_g[0] = 0.6, p.prony_tau[0] = 1;
  p.prony_g[1] = 0.5, p.prony_tau[1] = 2;
  try {
    build_simulation(s.scene, p);
    ADD_FAILURE() << "no error for Prony moduli summing to 1.1";
  } catch (const std::exception& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("@kidney"), std::string::npos) << msg;
    EXPECT_NE(msg.find("sum to 1.1"), std::string::npos) << msg;
  }
}

/// The cutting tests' 8 x 8 x 4 block (tests/cut_scenes.hpp) with a probe
/// in the blade's place: pushed straight down through it at x = 11.2 mm with
/// its button held, its shaft along y, cut resistance 5 N/m.
scene::Scene block_with_probe() {
  scene::Scene s = test::blade_scene(true, 5);
  scene::Tool& probe = s.tools.front();
  probe.kind = scene::Tool::Kind::Probe;
  probe.name = "probe";
  probe.radius = 2e-3;
  probe.shaft = 0;
  return s;
}

// The scalpel: the first tool becomes a blade of the scalpel's size (its
// path, direction and cut resistance kept), the factory then builds a
// Session, and the haptic loop's ticks make its cuts: the snapshot counts
// them and a new mesh, whose cut faces are the twins of each other. Off
// again, the probe presses the uncut block.
TEST(ViewerSession, TheScalpelCutsInTheHapticLoopAndOffAgainTheProbePresses) {
  const Session s = make_session(block_with_probe(), "", "", "");
  EXPECT_FALSE(s.params.scalpel);
  LiveParams p = s.params;
  p.scalpel = true;
  const scene::Tool blade = with_params(s.scene, p).tools.front();
  EXPECT_EQ(blade.kind, scene::Tool::Kind::Blade);
  EXPECT_EQ(blade.radius, 0.5 * kScalpelThickness);
  EXPECT_EQ(blade.shaft, kScalpelLength);
  EXPECT_EQ(blade.cut_resistance, 5);
  EXPECT_EQ(blade.direction.y, 1);

  ScriptedDevice device(s.scene.tools.front().path);
  HapticLoop loop(device, s.factory(), p);
  const index_t n0 = index_t(s.scene.nodes.size() / 3);
  loop.run_ticks(1000);
  const HapticSnapshot cut = loop.snapshot();
  EXPECT_TRUE(loop.status().empty()) << loop.status();
  EXPECT_GT(cut.cuts, 0) << "the scalpel pushed through the block with its button held";
  EXPECT_EQ(cut.mesh_version, 1 + cut.cuts);
  index_t nodes = 0;
  std::vector<std::uint8_t> faces;
  loop.post([&](Engine& e) {
        nodes = e.model->n_nodes;
        faces = cut_faces(*e.model);
      }).get();
  EXPECT_GT(nodes, n0);
  const long twins = std::count(faces.begin(), faces.end(), std::uint8_t(1));
  EXPECT_GT(twins, 0);
  EXPECT_EQ(twins % 2, 0) << "each cut face has its twin";

  p.scalpel = false;  // a rebuild: the probe again, on the uncut block at rest
  loop.request_params(p);
  const HapticSnapshot probe = loop.snapshot();
  EXPECT_EQ(probe.mesh_version, cut.mesh_version + 1);
  EXPECT_EQ(probe.cuts, 0);
  loop.run_ticks(300);
  EXPECT_EQ(loop.snapshot().cuts, 0) << "a probe's button grasps";
  loop.post([&](Engine& e) {
        nodes = e.model->n_nodes;
        faces = cut_faces(*e.model);
      }).get();
  EXPECT_EQ(nodes, n0);
  EXPECT_EQ(std::count(faces.begin(), faces.end(), std::uint8_t(1)), 0) << "an uncut mesh has no cut faces";
}

}  // namespace
}  // namespace tissue::viewer
