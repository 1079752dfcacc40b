// The viewer's live material edits (apps/viewer/session.hpp): the scene's
// fibre and Prony terms read into LiveParams, applied back to every set,
// and bad edits refused with the scene file and the material's line.
#include <gtest/gtest.h>

#include <string>

#include "apps/viewer/session.hpp"
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

}  // namespace
}  // namespace tissue::viewer
