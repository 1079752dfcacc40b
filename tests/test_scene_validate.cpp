// Scene validation: one test per rule (each checks that the message gives the
// file and line, names the offending material / set / element / node / tool /
// setting, and states the rule), the resolution of a valid scene into a
// ModelInput, and load_model's reports on bad mesh geometry.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <string>

#include "core/box_mesh.hpp"
#include "scene/fibre_field.hpp"
#include "scene/validate.hpp"

namespace tissue::scene {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

/// A valid scene on a 2 x 1 x 1 box (0.02 x 0.01 x 0.01 m, 12 tets, 12 nodes),
/// with the source lines a file would give.
Scene valid_scene() {
  Scene s;
  s.source = "organ.xml";
  ModelInput in;
  box_mesh(in, 2, 1, 1, 0.02, 0.01, 0.01);
  s.nodes = in.nodes;
  s.tets = in.tets;
  s.mesh_line = 2;
  s.materials.push_back(
      {.name = "brain", .form = Material::Form::YoungPoisson, .a = 3000, .b = 0.45, .rho = 1000, .line = 10});
  s.materials.push_back(
      {.name = "capsule", .form = Material::Form::ShearBulk, .a = 2000, .b = 50000, .rho = 1100, .line = 11});
  s.sets.push_back({.name = "left", .material = "brain", .elements = {0, 1, 2, 3, 4, 5}, .line = 12});
  s.sets.push_back({.name = "right", .material = "capsule", .elements = {6, 7, 8, 9, 10, 11}, .line = 13});
  Constraint base;
  base.kind = Constraint::Kind::Box;
  base.lo[0] = base.lo[1] = base.lo[2] = -1;
  base.hi[0] = base.hi[1] = 1;
  base.hi[2] = 0;
  base.line = 14;
  s.constraints.push_back(base);
  Tool t;
  t.name = "probe";
  t.path = {{0, {0.01, 0.005, 0.02}}, {0.1, {0.01, 0.005, 0.008}}};
  t.line = 15;
  s.tools.push_back(t);
  s.solver.line = 16;
  return s;
}

/// Success when to_model_input(s) throws a SceneError whose message contains
/// every part; the failure message shows what was thrown.
testing::AssertionResult rejects(const Scene& s, std::initializer_list<std::string> parts) {
  try {
    (void)to_model_input(s);
  } catch (const SceneError& e) {
    const std::string msg = e.what();
    for (const std::string& p : parts)
      if (msg.find(p) == std::string::npos)
        return testing::AssertionFailure() << "message \"" << msg << "\" lacks \"" << p << "\"";
    return testing::AssertionSuccess() << msg;
  } catch (const std::exception& e) {
    return testing::AssertionFailure() << "threw a non-SceneError: " << e.what();
  }
  return testing::AssertionFailure() << "no error";
}

TEST(SceneValidate, ValidSceneIsAccepted) {
  EXPECT_NO_THROW(validate(valid_scene()));
}

// ---- mesh ----

TEST(SceneValidate, MeshWithoutElements) {
  Scene s = valid_scene();
  s.tets.clear();
  EXPECT_TRUE(rejects(s, {"organ.xml:2: ", "mesh", "no elements"}));
}

TEST(SceneValidate, MeshWithoutNodes) {
  Scene s = valid_scene();
  s.nodes.clear();
  EXPECT_TRUE(rejects(s, {"organ.xml:2: ", "mesh", "no nodes"}));
}

TEST(SceneValidate, MeshCoordinateCountNotMultipleOfThree) {
  Scene s = valid_scene();
  s.nodes.pop_back();
  EXPECT_TRUE(rejects(s, {"organ.xml:2: ", "mesh", "35 node coordinates", "multiple of 3"}));
}

// one coordinate typed as 1e308 (or a node of another mesh): named, with how far it lies beyond the rest
TEST(SceneValidate, AStrayNodeFarBeyondTheOthersIsNamed) {
  Scene s = valid_scene();
  s.nodes[3 * 5 + 2] = 1e308;
  EXPECT_TRUE(rejects(s, {"organ.xml:2: ", "mesh: node 5 at", "1e+308", "beyond the other nodes on z", "check its coordinates"}));
  s = valid_scene();
  s.nodes[3 * 2] = -50.0;  // 50 m to the side of a mesh a few cm across
  EXPECT_TRUE(rejects(s, {"mesh: node 2 at (-50,", "beyond the other nodes on x"}));
  s = valid_scene();
  s.nodes[3 * 2] *= 3;  // a node a little beyond the others is a mesh, not a stray
  EXPECT_NO_THROW(validate(s));
}

TEST(SceneValidate, MeshCornerOutOfRange) {
  Scene s = valid_scene();
  s.tets[4 * 7 + 2] = 12;
  EXPECT_TRUE(rejects(s, {"organ.xml:2: ", "element 7 corner 2", "node 12", "out of range", "12 nodes"}));
}

TEST(SceneValidate, NonFiniteNodeCoordinate) {
  Scene s = valid_scene();
  s.nodes[3 * 5 + 1] = kInf;
  EXPECT_TRUE(rejects(s, {"organ.xml:2: ", "node 5 coordinate y", "not a finite number"}));
}

// ---- materials ----

TEST(SceneValidate, UnknownMaterialInSet) {
  Scene s = valid_scene();
  s.sets[1].material = "capsul";
  EXPECT_TRUE(rejects(s, {"organ.xml:13: ", "element-set 'right'", "material 'capsul' is not defined", "'capsule'"}));
}

TEST(SceneValidate, PoissonRatioAtOneHalf) {
  Scene s = valid_scene();
  s.materials[0].b = 0.5;
  EXPECT_TRUE(rejects(s, {"organ.xml:10: ", "material 'brain'", "nu = 0.5", "must be in (-1, 0.5)"}));
}

TEST(SceneValidate, PoissonRatioAtMinusOne) {
  Scene s = valid_scene();
  s.materials[0].b = -1;
  EXPECT_TRUE(rejects(s, {"organ.xml:10: ", "material 'brain'", "nu = -1", "must be in (-1, 0.5)"}));
}

TEST(SceneValidate, NonPositiveYoungsModulus) {
  Scene s = valid_scene();
  s.materials[0].a = 0;
  EXPECT_TRUE(rejects(s, {"organ.xml:10: ", "material 'brain'", "Young's modulus E = 0 Pa", "must be > 0"}));
}

TEST(SceneValidate, NonPositiveDensity) {
  Scene s = valid_scene();
  s.materials[1].rho = -5;
  EXPECT_TRUE(rejects(s, {"organ.xml:11: ", "material 'capsule'", "density rho = -5", "must be > 0"}));
}

TEST(SceneValidate, ShearBulkNonPositiveMu) {
  Scene s = valid_scene();
  s.materials[1].a = -2000;
  EXPECT_TRUE(rejects(s, {"organ.xml:11: ", "material 'capsule'", "shear modulus mu = -2000 Pa", "must be > 0"}));
}

TEST(SceneValidate, ShearBulkNonPositiveK) {
  Scene s = valid_scene();
  s.materials[1].b = 0;
  EXPECT_TRUE(rejects(s, {"organ.xml:11: ", "material 'capsule'", "bulk modulus K = 0 Pa", "must be > 0"}));
}

TEST(SceneValidate, LameNonPositiveMu) {
  Scene s = valid_scene();
  s.materials[1] = {.name = "capsule", .form = Material::Form::Lame, .a = 1000, .b = 0, .rho = 1000, .line = 11};
  EXPECT_TRUE(rejects(s, {"organ.xml:11: ", "material 'capsule'", "mu = 0 Pa", "must be > 0"}));
}

TEST(SceneValidate, LameNonPositiveBulkModulus) {
  Scene s = valid_scene();
  // lambda + 2 mu / 3 = -3000 + 2000 = -1000 Pa
  s.materials[1] = {.name = "capsule", .form = Material::Form::Lame, .a = -3000, .b = 3000, .rho = 1000, .line = 11};
  EXPECT_TRUE(rejects(s, {"organ.xml:11: ", "material 'capsule'", "K = lambda + 2 mu / 3 = -1000 Pa", "must be > 0"}));
}

TEST(SceneValidate, NonFiniteMaterialNumber) {
  Scene s = valid_scene();
  s.materials[0].a = kNaN;
  EXPECT_TRUE(rejects(s, {"organ.xml:10: ", "material 'brain'", "E = nan", "not a finite number"}));
  s = valid_scene();
  s.materials[1].rho = kInf;
  EXPECT_TRUE(rejects(s, {"organ.xml:11: ", "material 'capsule'", "rho = inf", "not a finite number"}));
}

TEST(SceneValidate, DuplicateMaterialName) {
  Scene s = valid_scene();
  s.materials[1].name = "brain";
  s.sets[1].material = "brain";
  EXPECT_TRUE(rejects(s, {"organ.xml:11: ", "material 'brain' is defined twice", "organ.xml:10", "unique"}));
}

TEST(SceneValidate, EmptyMaterialName) {
  Scene s = valid_scene();
  s.materials[0].name = "";
  EXPECT_TRUE(rejects(s, {"organ.xml:10: ", "material", "name is empty"}));
}

// ---- element sets ----

TEST(SceneValidate, ElementOutOfRangeInSet) {
  Scene s = valid_scene();
  s.sets[1].elements.push_back(12);
  EXPECT_TRUE(rejects(s, {"organ.xml:13: ", "element-set 'right'", "element 12 is out of range", "12 elements"}));
  s.sets[1].elements.back() = -1;
  EXPECT_TRUE(rejects(s, {"organ.xml:13: ", "element-set 'right'", "element -1 is out of range"}));
}

TEST(SceneValidate, ElementInTwoSets) {
  Scene s = valid_scene();
  s.sets[1].elements.push_back(4);
  EXPECT_TRUE(rejects(s, {"organ.xml:13: ", "element-set 'right'", "element 4 is already in element-set 'left'",
                          "organ.xml:12", "exactly one set"}));
}

TEST(SceneValidate, AllElementsSetOverlapsAnother) {
  Scene s = valid_scene();
  s.sets[0].all = true;
  s.sets[0].elements.clear();
  EXPECT_TRUE(rejects(s, {"organ.xml:13: ", "element 6 is already in element-set 'left'"}));
}

TEST(SceneValidate, ElementListedTwiceInOneSet) {
  Scene s = valid_scene();
  s.sets[0].elements.push_back(2);
  EXPECT_TRUE(rejects(s, {"organ.xml:12: ", "element-set 'left'", "element 2 is listed twice"}));
}

TEST(SceneValidate, ElementInNoSet) {
  Scene s = valid_scene();
  s.sets[1].elements = {6, 7, 8, 10};
  EXPECT_TRUE(rejects(
      s, {"organ.xml:2: ", "element 9 (nodes", "is in no element-set", "nor are 1 others", "needs a material"}));
}

// ---- constraints ----

TEST(SceneValidate, ConstraintNodeOutOfRange) {
  Scene s = valid_scene();
  Constraint c;
  c.nodes = {0, 3, 40};
  c.line = 20;
  s.constraints.push_back(c);
  EXPECT_TRUE(rejects(s, {"organ.xml:20: ", "fixed nodes", "node 40 is out of range", "12 nodes"}));
}

TEST(SceneValidate, BoxMinAboveMax) {
  Scene s = valid_scene();
  s.constraints[0].lo[1] = 2;
  EXPECT_TRUE(
      rejects(s, {"organ.xml:14: ", "fixed box", "box-min y = 2 is greater than box-max y = 1", "need min <= max"}));
}

TEST(SceneValidate, PlaneWithZeroNormal) {
  Scene s = valid_scene();
  Constraint c;
  c.kind = Constraint::Kind::Plane;
  c.normal[2] = 0;
  c.line = 21;
  s.constraints.push_back(c);
  EXPECT_TRUE(rejects(s, {"organ.xml:21: ", "fixed plane", "normal is zero", "non-zero length"}));
}

TEST(SceneValidate, NonFiniteConstraintNumber) {
  Scene s = valid_scene();
  s.constraints[0].hi[2] = kNaN;
  EXPECT_TRUE(rejects(s, {"organ.xml:14: ", "fixed box", "box-max z = nan", "not a finite number"}));
}

TEST(SceneValidate, BoxSelectingNoNode) {
  Scene s = valid_scene();
  s.constraints[0].lo[2] = 0.5;
  s.constraints[0].hi[2] = 0.6;
  EXPECT_TRUE(rejects(
      s, {"organ.xml:14: ", "fixed box min (-1, -1, 0.5) max (1, 1, 0.6)", "selects no node", "at least one node"}));
}

TEST(SceneValidate, PlaneSelectingNoNode) {
  Scene s = valid_scene();
  Constraint c;
  c.kind = Constraint::Kind::Plane;
  c.point[0] = 0.05;  // beyond the box's x = 0.02 face, normal +x
  c.normal[0] = 1;
  c.normal[2] = 0;
  c.line = 22;
  s.constraints.push_back(c);
  EXPECT_TRUE(rejects(s, {"organ.xml:22: ", "fixed plane point (0.05, 0, 0) normal (1, 0, 0)", "selects no node"}));
}

TEST(SceneValidate, EmptyNodeList) {
  Scene s = valid_scene();
  Constraint c;
  c.line = 23;
  s.constraints.push_back(c);
  EXPECT_TRUE(rejects(s, {"organ.xml:23: ", "fixed nodes", "empty", "at least one node"}));
}

// ---- tools ----

TEST(SceneValidate, ToolRadiusNonPositive) {
  Scene s = valid_scene();
  s.tools[0].radius = 0;
  EXPECT_TRUE(rejects(s, {"organ.xml:15: ", "tool 'probe'", "radius = 0 m", "must be finite and > 0"}));
}

TEST(SceneValidate, UnknownDevice) {
  Scene s = valid_scene();
  s.tools[0].device = "omni";
  EXPECT_TRUE(rejects(s, {"organ.xml:15: ", "tool 'probe'", "unknown device 'omni'", "scripted, mouse or phantom"}));
}

TEST(SceneValidate, ScriptedToolWithoutPath) {
  Scene s = valid_scene();
  s.tools[0].path.clear();
  EXPECT_TRUE(rejects(s, {"organ.xml:15: ", "tool 'probe'", "scripted device needs a path"}));
  s.tools[0].device = "mouse";  // interactive devices need none
  EXPECT_NO_THROW(validate(s));
}

TEST(SceneValidate, WaypointTimesMustIncrease) {
  Scene s = valid_scene();
  s.tools[0].path.push_back({0.1, {0, 0, 0}});
  EXPECT_TRUE(rejects(s, {"organ.xml:15: ", "tool 'probe'", "waypoint 2 has t = 0.1 s", "times must increase"}));
}

TEST(SceneValidate, NonFiniteWaypoint) {
  Scene s = valid_scene();
  s.tools[0].path[1].p.z = kNaN;
  EXPECT_TRUE(rejects(s, {"organ.xml:15: ", "tool 'probe': waypoint 1", "z = nan", "not a finite number"}));
}

// Two tools of one name were accepted: the second's forces and messages
// could not be told from the first's.
TEST(SceneValidate, TwoToolsWithOneName) {
  Scene s = valid_scene();
  Tool second = s.tools[0];
  second.line = 20;
  s.tools.push_back(second);
  EXPECT_TRUE(rejects(s, {"organ.xml:20: ", "tool 'probe' is defined twice (first organ.xml:15)",
                          "tool names must be unique"}));
  s.tools[1].name = "grasper";
  EXPECT_NO_THROW(validate(s));
}

// shaft-length="1e6" was accepted on a 2.4 cm body: the shaft obeys the
// waypoints' reach (1000 mesh sizes).
TEST(SceneValidate, ShaftFarLongerThanTheMesh) {
  Scene s = valid_scene();
  s.tools[0].shaft = 1e6;
  EXPECT_TRUE(rejects(s, {"organ.xml:15: ", "tool 'probe': shaft-length = 1000000 m",
                          "longer than 1000 x the mesh's size (0.0245 m, the limit 24.5 m)", "metres"}));
  s.tools[0].shaft = 0.2;  // a real instrument's shaft, eight times the body
  EXPECT_NO_THROW(validate(s));
}

TEST(SceneValidate, FrictionMustBeFiniteAndNotNegative) {
  Scene s = valid_scene();
  s.tools[0].friction = -0.2;
  EXPECT_TRUE(rejects(s, {"organ.xml:15: ", "tool 'probe': friction = -0.2 must be finite and >= 0"}));
  s.tools[0].friction = INFINITY;
  EXPECT_TRUE(rejects(s, {"tool 'probe': friction = inf"}));
  s.tools[0].friction = 0.4;
  EXPECT_NO_THROW(validate(s));
  EXPECT_EQ(scheduler_settings(s).tools.at(0).shape.friction, 0.4);
}

// radius="1e-300" was accepted and pressed nothing: the radius must be at
// least a millionth of the body's largest extent.
TEST(SceneValidate, RadiusFarBelowTheBody) {
  Scene s = valid_scene();
  s.tools[0].radius = 1e-300;
  EXPECT_TRUE(rejects(s, {"organ.xml:15: ", "tool 'probe': radius = 1e-300 m", "below 1e-06 of the body's largest "
                          "extent (0.02 m)", "smallest radius allowed (2e-08 m)", "presses nothing"}));
  s.tools[0].radius = 1e-5;  // a fine needle on a 2 cm body
  EXPECT_NO_THROW(validate(s));
}

// ---- solver ----

// A waypoint at 1e300 m once reached the collision query as an invalid ray
// (an assertion in Embree): waypoints must lie near the mesh.
TEST(SceneValidate, WaypointFarFromTheMesh) {
  Scene s = valid_scene();
  s.tools[0].path[1].p.x = 1e300;
  EXPECT_TRUE(rejects(s, {"organ.xml:15: ", "tool 'probe': waypoint 1 at (1e+300, 0.005, 0.008) m", "from the mesh",
                          "1000 x its size", "metres"}));
  s.tools[0].path[1].p.x = 20.0;  // 20 m from a 2.4 cm mesh: still a plausible approach path
  EXPECT_NO_THROW(validate(s));
}

TEST(SceneValidate, UnknownBackend) {
  Scene s = valid_scene();
  s.solver.backend = "gpu";
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "unknown backend 'gpu'", "cpu or cuda"}));
}

TEST(SceneValidate, NonPositiveTimeStep) {
  Scene s = valid_scene();
  s.solver.dt = -1e-4;
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "dt = -0.0001 s", "must be > 0 (or \"auto\""}));
  s.solver.dt = 0;  // not a spelling of "auto"
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "dt = 0 s", "must be > 0"}));
  s.solver.dt.reset();  // auto
  EXPECT_NO_THROW(validate(s));
}

TEST(SceneValidate, SafetyFactorOutsideOpenUnitInterval) {
  for (double bad : {0.0, 1.0, 1.5}) {
    Scene s = valid_scene();
    s.solver.dt_safety = bad;
    EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "dt-safety", "must be in (0, 1)"}));
  }
}

TEST(SceneValidate, MassScalingOutsideItsRange) {
  for (double bad : {-0.01, 1.0, 3.0}) {
    Scene s = valid_scene();
    s.solver.mass_scaling = bad;
    EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "mass-scaling", "must be in [0, 1)"}));
  }
  Scene s = valid_scene();
  s.solver.mass_scaling = std::nan("");
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "mass-scaling"}));
}

TEST(SceneValidate, NegativeDampingOtherThanAuto) {
  Scene s = valid_scene();
  s.solver.damping = -0.5;
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "damping = -0.5", "must be >= 0 (or \"auto\")"}));
  s.solver.damping = -1;  // no longer a spelling of "auto"
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "damping = -1", "must be >= 0 (or \"auto\")"}));
  s.solver.damping.reset();  // auto
  EXPECT_NO_THROW(validate(s));
}

TEST(SceneValidate, DepthBelowMinusOne) {
  Scene s = valid_scene();
  s.solver.depth = -3;  // -1 = all, -2 = auto
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "depth = -3", "must be >= 0 (or \"all\" or \"auto\")"}));
  s.solver.depth = kDepthAll;
  EXPECT_NO_THROW(validate(s));
}

TEST(SceneValidate, TickNonPositive) {
  Scene s = valid_scene();
  s.solver.tick = 0;
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "tick = 0 s", "must be > 0"}));
}

TEST(SceneValidate, TolerancesNonPositive) {
  Scene s = valid_scene();
  s.solver.residual_tol = 0;
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "residual-tol = 0", "must be in (0, 1)"}));
  s.solver.residual_tol = 1e300;  // met by any state
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "residual-tol = 1e+300", "must be in (0, 1)", "any state"}));
  s = valid_scene();
  s.solver.kinetic_tol = -1e-6;
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "kinetic-tol = -1e-06", "must be > 0"}));
}

TEST(SceneValidate, NonFiniteSolverNumber) {
  Scene s = valid_scene();
  s.solver.tick = kInf;
  EXPECT_TRUE(rejects(s, {"organ.xml:16: ", "solver", "tick = inf", "not a finite number"}));
}

TEST(SceneValidate, SceneBuiltInCodeHasNoLineNumber) {
  Scene s = valid_scene();
  s.materials[0].line = 0;
  s.materials[0].a = -1;
  EXPECT_TRUE(rejects(s, {"organ.xml: material 'brain'"}));
}

// ---- resolution ----

TEST(SceneValidate, ValidSceneGivesModelInput) {
  Scene s = valid_scene();
  s.solver.dt = 1e-5;
  s.solver.dt_safety = 0.3;
  s.solver.mass_scaling = 0.04;
  s.solver.tick = 2e-3;
  s.solver.damping = 25;
  s.solver.ianp = false;
  const ModelInput in = to_model_input(s);
  EXPECT_EQ(in.source, "organ.xml");
  EXPECT_EQ(in.nodes, s.nodes);
  EXPECT_EQ(in.tets, s.tets);
  EXPECT_EQ(in.elem_material, (std::vector<index_t>{0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1}));
  ASSERT_EQ(in.materials.size(), 2u);
  EXPECT_DOUBLE_EQ(in.materials[0].mu, 3000 / (2 * 1.45));
  EXPECT_DOUBLE_EQ(in.materials[0].K, 3000 / (3 * (1 - 0.9)));
  EXPECT_DOUBLE_EQ(in.materials[0].rho, 1000);
  EXPECT_DOUBLE_EQ(in.materials[1].mu, 2000);
  EXPECT_DOUBLE_EQ(in.materials[1].K, 50000);
  EXPECT_DOUBLE_EQ(in.materials[1].rho, 1100);
  // the box z <= 0 holds the bottom face: grid points (i, j, 0)
  std::vector<std::uint8_t> fixed(12, 0);
  for (int j = 0; j <= 1; ++j)
    for (int i = 0; i <= 2; ++i) fixed[box_node(2, 1, i, j, 0)] = 1;
  EXPECT_EQ(in.fixed, fixed);
  EXPECT_EQ(in.dt, 1e-5);
  EXPECT_EQ(in.dt_safety, 0.3);
  EXPECT_EQ(in.mass_scaling, 0.04);
  EXPECT_EQ(in.tick, 2e-3);
  EXPECT_EQ(in.damping, 25);
  EXPECT_FALSE(in.ianp);
}

TEST(SceneValidate, ConstraintsAccumulateIntoOneMask) {
  Scene s = valid_scene();
  Constraint c;
  c.nodes = {box_node(2, 1, 2, 1, 1), box_node(2, 1, 0, 0, 0)};  // one new, one already fixed by the box
  s.constraints.push_back(c);
  const ModelInput in = to_model_input(s);
  EXPECT_EQ(std::count(in.fixed.begin(), in.fixed.end(), 1), 7);
  EXPECT_EQ(in.fixed[box_node(2, 1, 2, 1, 1)], 1);
}

TEST(SceneValidate, LoadModelBuildsTheModel) {
  const TissueModel<double> m = load_model(valid_scene());
  EXPECT_EQ(m.n_nodes, 12);
  EXPECT_EQ(m.n_elems, 12);
  EXPECT_DOUBLE_EQ(m.mu[0], 3000 / 2.9);
  EXPECT_DOUBLE_EQ(m.mu[11], 2000);
  EXPECT_EQ(m.node_flags[box_node(2, 1, 1, 0, 0)] & kFixed, kFixed);
  EXPECT_EQ(m.node_flags[box_node(2, 1, 1, 0, 1)] & kFixed, 0);
  EXPECT_NEAR(m.total_mass, 0.01 * 0.01 * 0.01 * 1000 + 0.01 * 0.01 * 0.01 * 1100, 1e-15);
}

TEST(SceneValidate, LoadModelReportsZeroVolumeElement) {
  Scene s = valid_scene();
  // element 4 flattened onto the bottom face z = 0
  const index_t flat[4] = {box_node(2, 1, 0, 0, 0), box_node(2, 1, 1, 0, 0), box_node(2, 1, 0, 1, 0),
                           box_node(2, 1, 1, 1, 0)};
  std::copy(flat, flat + 4, s.tets.begin() + 4 * 4);
  try {
    (void)load_model(s);
    FAIL() << "no error for a zero-volume tet";
  } catch (const ModelError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("organ.xml"), std::string::npos) << msg;
    EXPECT_NE(msg.find("element 4"), std::string::npos) << msg;
    EXPECT_NE(msg.find("zero volume"), std::string::npos) << msg;
  }
}

TEST(SceneValidate, LoadModelReorientsInvertedElement) {
  Scene s = valid_scene();
  std::swap(s.tets[4 * 3 + 0], s.tets[4 * 3 + 1]);  // element 3 inverted
  const TissueModel<double> m = load_model(s);
  EXPECT_EQ(m.reoriented, 1);
  EXPECT_GT(m.volume[3], 0);
}

TEST(SceneValidate, LoadModelReportsTimeStepAboveLimit) {
  Scene s = valid_scene();
  s.solver.dt = 1.0;
  try {
    (void)load_model(s);
    FAIL() << "no error for dt above dt_crit";
  } catch (const ModelError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("organ.xml"), std::string::npos) << msg;
    EXPECT_NE(msg.find("above the stable limit"), std::string::npos) << msg;
    EXPECT_NE(msg.find("element"), std::string::npos) << msg;
  }
}

TEST(SceneValidate, SchedulerSettingsFromSolver) {
  Scene s = valid_scene();
  s.solver.depth = 3;
  s.solver.tick = 2e-3;
  s.solver.residual_tol = 1e-4;
  s.solver.kinetic_tol = 1e-8;
  const SchedulerSettings st = scheduler_settings(s);
  EXPECT_EQ(st.depth, 3);
  EXPECT_EQ(st.tick, 2e-3);
  EXPECT_EQ(st.residual_tol, 1e-4);
  EXPECT_EQ(st.kinetic_tol, 1e-8);
  s.solver.tick = -1;
  EXPECT_THROW((void)scheduler_settings(s), SceneError);
}

TEST(SceneValidate, MaterialParamsOfEachForm) {
  const MaterialParams yp =
      Material{.name = "m", .form = Material::Form::YoungPoisson, .a = 3000, .b = 0.25, .rho = 900}.params();
  EXPECT_DOUBLE_EQ(yp.mu, 1200);
  EXPECT_DOUBLE_EQ(yp.K, 2000);
  EXPECT_DOUBLE_EQ(yp.rho, 900);
  const MaterialParams sb = Material{.name = "m", .form = Material::Form::ShearBulk, .a = 1200, .b = 2000}.params();
  EXPECT_DOUBLE_EQ(sb.mu, 1200);
  EXPECT_DOUBLE_EQ(sb.K, 2000);
  // lambda = K - 2 mu / 3 = 2000 - 800 = 1200
  const MaterialParams la = Material{.name = "m", .form = Material::Form::Lame, .a = 1200, .b = 1200}.params();
  EXPECT_DOUBLE_EQ(la.mu, 1200);
  EXPECT_DOUBLE_EQ(la.K, 2000);
}

// ---- per-element fibre directions (scene/fibre_field.hpp) ----

/// A 4 x 4 x 2 box of 0.04 x 0.04 x 0.02 m (192 tets), one material with
/// fibres (eta = 20 kPa) given by `field` around (or from) the vertical line
/// x = y = 0.02 m; the <fibre> on line 7.
Scene vessel_scene(Material::FibreField field, Vec3<double> axis, Vec3<double> origin) {
  Scene s;
  s.source = "vessel.xml";
  ModelInput in;
  box_mesh(in, 4, 4, 2, 0.04, 0.04, 0.02);
  s.nodes = in.nodes;
  s.tets = in.tets;
  s.mesh_line = 2;
  Material m{.name = "wall", .form = Material::Form::YoungPoisson, .a = 6000, .b = 0.45, .rho = 1060, .line = 6};
  m.fibre_eta = 20000;
  m.fibre_line = 7;
  m.fibre_field = field;
  m.fibre_axis = axis;
  m.fibre_origin = origin;
  s.materials = {m};
  s.sets.push_back({.name = "wall", .material = "wall", .all = true, .elements = {}, .line = 9});
  return s;
}

/// Element e's centroid, computed here from the scene's nodes.
Vec3<double> centroid_of(const Scene& s, index_t e) {
  double c[3] = {0, 0, 0};
  for (int a = 0; a < 4; ++a)
    for (int k = 0; k < 3; ++k) c[k] += s.nodes[3 * s.tets[4 * e + a] + k] / 4;
  return {c[0], c[1], c[2]};
}

/// The unit fibre of element e in the built model.
Vec3<double> model_fibre(const TissueModel<double>& m, index_t e) {
  return {m.fibre[e], m.fibre[m.n_elems + e], m.fibre[2 * m.n_elems + e]};
}

TEST(SceneFibres, CircumferentialFieldIsTheUnitTangentAroundTheAxis) {
  // axis z through (0.02, 0.02, 0.005): the tangent at (x, y) is
  // (-(y - 0.02), x - 0.02, 0) / r, r the distance from the axis
  for (const double sense : {1.0, -1.0}) {
    SCOPED_TRACE(sense);
    const Scene s = vessel_scene(Material::FibreField::Circumferential, {0, 0, 2.5 * sense}, {0.02, 0.02, 0.005});
    const TissueModel<double> m = load_model(s);
    ASSERT_EQ(m.n_elems, 192);
    ASSERT_EQ(m.fibre.size(), 4u * 192);
    for (index_t e = 0; e < m.n_elems; ++e) {
      const Vec3<double> c = centroid_of(s, e);
      const double rx = c.x - 0.02, ry = c.y - 0.02, r = std::hypot(rx, ry);
      ASSERT_GT(r, 1e-3);  // no centroid near the axis in this mesh
      const Vec3<double> a = model_fibre(m, e);
      EXPECT_NEAR(a.x, -sense * ry / r, 1e-14) << "element " << e;
      EXPECT_NEAR(a.y, sense * rx / r, 1e-14) << "element " << e;
      EXPECT_NEAR(a.z, 0, 1e-14) << "element " << e;
      EXPECT_EQ(m.fibre[3 * m.n_elems + e], 20000);
      // a tangent: perpendicular to the radius and to the axis
      EXPECT_NEAR(a.x * rx + a.y * ry, 0, 1e-14 * r);
    }
  }
}

TEST(SceneFibres, RadialFieldPointsAwayFromTheAxis) {
  // axis z through (0.02, 0.02, 0.005): the component along z (c.z - 0.005)
  // is dropped, leaving (x - 0.02, y - 0.02, 0) / r
  Scene s = vessel_scene(Material::FibreField::Radial, {0, 0, 1}, {0.02, 0.02, 0.005});
  TissueModel<double> m = load_model(s);
  for (index_t e = 0; e < m.n_elems; ++e) {
    const Vec3<double> c = centroid_of(s, e);
    const double rx = c.x - 0.02, ry = c.y - 0.02, r = std::hypot(rx, ry);
    const Vec3<double> a = model_fibre(m, e);
    EXPECT_NEAR(a.x, rx / r, 1e-14) << "element " << e;
    EXPECT_NEAR(a.y, ry / r, 1e-14) << "element " << e;
    EXPECT_NEAR(a.z, 0, 1e-14) << "element " << e;
  }
  // an axis along x through (0, 0.02, 0.01) (not through any centroid: the
  // centroids sit at quarter-cell heights): (0, y - 0.02, z - 0.01) / r
  s = vessel_scene(Material::FibreField::Radial, {-3, 0, 0}, {0.5, 0.02, 0.01});
  m = load_model(s);
  for (index_t e = 0; e < m.n_elems; ++e) {
    const Vec3<double> c = centroid_of(s, e);
    const double ry = c.y - 0.02, rz = c.z - 0.01, r = std::hypot(ry, rz);
    const Vec3<double> a = model_fibre(m, e);
    EXPECT_NEAR(a.x, 0, 1e-14) << "element " << e;
    EXPECT_NEAR(a.y, ry / r, 1e-14) << "element " << e;
    EXPECT_NEAR(a.z, rz / r, 1e-14) << "element " << e;
  }
}

TEST(SceneFibres, UniformMaterialsGiveNoPerElementDirections) {
  Scene s = valid_scene();
  s.materials[0].fibre_eta = 1000;
  s.materials[0].fibre_line = 20;
  s.materials[0].fibre_dir = {0, 2, 0};
  EXPECT_TRUE(to_model_input(s).fibre_dirs.empty());
}

TEST(SceneFibres, FileRowsGiveTheirElementsAndTheRestKeepTheDirection) {
  Scene s = valid_scene();  // brain: elements 0..5, capsule: 6..11
  Material& m = s.materials[0];
  m.fibre_eta = 1000;
  m.fibre_line = 20;
  m.fibre_dir = {0, 0, 3};
  m.fibre_field = Material::FibreField::File;
  m.fibre_file = "dirs.csv";
  m.fibre_rows = {{0, {0, 2, 0}, 2}, {4, {1, 1, 0}, 3}, {7, {5, 0, 0}, 4}};  // element 7 is the capsule's: not used
  const ModelInput in = to_model_input(s);
  ASSERT_EQ(in.fibre_dirs.size(), 36u);
  const auto dir = [&](index_t e) {
    return Vec3<double>{in.fibre_dirs[3 * e], in.fibre_dirs[3 * e + 1], in.fibre_dirs[3 * e + 2]};
  };
  EXPECT_EQ(dir(0).y, 2);
  EXPECT_EQ(dir(4).x, 1);
  EXPECT_EQ(dir(4).y, 1);
  for (index_t e : {1, 2, 3, 5}) EXPECT_EQ(dir(e).z, 3) << e;  // not listed: direction=
  const TissueModel<double> model = build_model(in);
  EXPECT_NEAR(model_fibre(model, 4).x, std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(model_fibre(model, 2).z, 1, 1e-15);
  EXPECT_EQ(model.fibre[3 * 12 + 7], 0);  // the capsule has no fibres
}

/// valid_scene with fibres in 'brain' (<fibre> on line 20) from `field`.
Scene fibre_scene(Material::FibreField field) {
  Scene s = valid_scene();
  Material& m = s.materials[0];
  m.fibre_eta = 1000;
  m.fibre_line = 20;
  m.fibre_field = field;
  m.fibre_file = "dirs.csv";
  m.fibre_file_path = "/data/dirs.csv";
  m.fibre_rows = {{0, {1, 0, 0}, 2}, {2, {0, 1, 0}, 3}};
  return s;
}

TEST(SceneFibres, BadFieldAxisOrOrigin) {
  Scene s = fibre_scene(Material::FibreField::Circumferential);
  s.materials[0].fibre_axis = {0, 0, 0};
  EXPECT_TRUE(rejects(s, {"organ.xml:20: ", "material 'brain': fibre field circumferential: axis (0, 0, 0) must be "
                          "non-zero"}));
  s.materials[0].fibre_axis = {0, kNaN, 1};
  EXPECT_TRUE(rejects(s, {"organ.xml:20: ", "fibre field circumferential: axis y = nan is not a finite number"}));
  s = fibre_scene(Material::FibreField::Radial);
  s.materials[0].fibre_origin = {kInf, 0, 0};
  EXPECT_TRUE(rejects(s, {"organ.xml:20: ", "fibre field radial: origin x = inf is not a finite number"}));
}

TEST(SceneFibres, CentroidOnTheAxisIsNamed) {
  for (const auto field : {Material::FibreField::Circumferential, Material::FibreField::Radial}) {
    Scene s = fibre_scene(field);
    s.materials[0].fibre_axis = {1, 2, 3};
    s.materials[0].fibre_origin = centroid_of(s, 3) + Vec3<double>{0.001, 0.002, 0.003};  // on the line, off the point
    const std::string name(to_string(field));
    EXPECT_TRUE(rejects(s, {"organ.xml:20: ", "material 'brain': fibre field " + name, "element 3's centroid",
                            "lies on the axis", "the " + name + " direction is undefined there"}));
  }
}

TEST(SceneFibres, BadFileRowsCiteTheFileLine) {
  Scene s = fibre_scene(Material::FibreField::File);
  s.materials[0].fibre_rows.push_back({12, {1, 0, 0}, 4});
  EXPECT_TRUE(rejects(s, {"/data/dirs.csv:4: ", "material 'brain', fibre file 'dirs.csv' (<fibre> at organ.xml:20)",
                          "element 12 is out of range (the mesh has 12 elements, ids 0..11"}));
  s.materials[0].fibre_rows.back() = {-1, {1, 0, 0}, 4};
  EXPECT_TRUE(rejects(s, {"/data/dirs.csv:4: ", "element -1 is out of range"}));
  s.materials[0].fibre_rows.back() = {2, {1, 0, 0}, 4};
  EXPECT_TRUE(rejects(s, {"/data/dirs.csv:4: ", "element 2 is listed twice (first at line 3)"}));
  s.materials[0].fibre_rows.back() = {3, {0, 0, 0}, 4};
  EXPECT_TRUE(rejects(s, {"/data/dirs.csv:4: ", "element 3: fibre direction (0, 0, 0) must be finite and non-zero"}));
  s.materials[0].fibre_rows.back() = {3, {kNaN, 0, 1}, 4};
  EXPECT_TRUE(rejects(s, {"/data/dirs.csv:4: ", "element 3: fibre direction (nan, 0, 1) must be finite"}));
  // rows only for the capsule's elements: the file of another mesh or set
  s = fibre_scene(Material::FibreField::File);
  s.materials[0].fibre_rows = {{6, {1, 0, 0}, 2}, {9, {1, 0, 0}, 3}};
  EXPECT_TRUE(rejects(s, {"organ.xml:20: ", "fibre file 'dirs.csv' lists none of the material's 6 elements"}));
  s.materials[0].fibre_rows.clear();
  EXPECT_TRUE(rejects(s, {"organ.xml:20: ", "fibre file 'dirs.csv' gives no directions"}));
  s.materials[0].fibre_file.clear();
  EXPECT_TRUE(rejects(s, {"organ.xml:20: ", "a fibre direction file needs a file name"}));
}

}  // namespace
}  // namespace tissue::scene
