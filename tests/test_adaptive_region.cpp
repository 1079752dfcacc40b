// The adaptive region (depth = kDepthAuto, core/scheduler.hpp): the front
// ring of a flood fill, the backend's front-ring displacement, and the
// Scheduler growing the region while that displacement exceeds auto_tol
// times the largest one. On a pressed box the adaptive region ends with a
// small front displacement, grows further for a tighter tolerance, and
// cuts the truncation error of its starting depth against the whole mesh.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "core/box_mesh.hpp"
#include "core/device.hpp"
#include "core/region.hpp"
#include "core/scheduler.hpp"
#include "cpu/cpu_backend.hpp"

namespace tissue {
namespace {

constexpr double kLx = 0.06, kLz = 0.012;  // a wide, thin layer on a fixed base (m): the response to a
constexpr int kNx = 12, kNz = 3;            // press decays over a few thicknesses, so the region can stop

TissueModel<double> pressed_box() {
  ModelInput in;
  box_mesh(in, kNx, kNx, kNz, kLx, kLx, kLz);
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
  in.source = "adaptive box";
  return build_model(in);
}

/// Ring (flood-fill distance) of every node from the seeds; -1 = unreached.
std::vector<int> rings(const TissueModel<double>& m, const std::vector<index_t>& seeds) {
  std::vector<int> ring(m.n_nodes, -1);
  std::vector<index_t> frontier = seeds, next;
  for (index_t s : seeds) ring[s] = 0;
  for (int r = 1; !frontier.empty(); ++r) {
    next.clear();
    for (index_t a : frontier)
      for (index_t k = m.node_elem_start[a]; k < m.node_elem_start[a + 1]; ++k)
        for (int c = 0; c < 4; ++c) {
          const index_t b = m.elem_nodes[c * m.n_elems + incident_element(m.node_elem[k])];
          if (ring[b] < 0) {
            ring[b] = r;
            next.push_back(b);
          }
        }
    frontier.swap(next);
  }
  return ring;
}

TEST(FrontRing, IsTheLastRingOfTheFill) {
  const TissueModel<double> m = pressed_box();
  const std::vector<index_t> seeds{box_node(kNx, kNx, 6, 6, kNz), box_node(kNx, kNx, 7, 6, kNz)};
  const std::vector<int> ring = rings(m, seeds);
  for (int depth = 0; depth <= 5; ++depth) {
    const Region r = flood_fill(m, std::span<const index_t>(seeds), depth);
    std::vector<index_t> want;
    for (index_t a = 0; a < m.n_nodes; ++a)
      if (ring[a] == depth) want.push_back(a);
    EXPECT_EQ(r.front, want) << "depth " << depth;
    for (index_t a : r.front) EXPECT_EQ(r.role[a], kInner);
  }
  // a fill that runs out of nodes before `depth` rings has no front
  EXPECT_TRUE(flood_fill(m, std::span<const index_t>(seeds), 100).front.empty());
  EXPECT_TRUE(flood_fill(m, std::span<const index_t>(seeds), kDepthAll).front.empty());
}

TEST(FrontRing, BackendReducesItsDisplacement) {
  const TissueModel<double> m = pressed_box();
  auto b = make_cpu_backend(Precision::Double);
  b->upload(m);
  const std::vector<index_t> seeds{box_node(kNx, kNx, 6, 6, kNz)};
  b->build_region(seeds, 2);
  const Region r = b->region();
  ASSERT_FALSE(r.front.empty());
  std::vector<double> u(3 * size_t(m.n_nodes), 0.0);
  double want = 0;
  for (size_t k = 0; k < r.front.size(); ++k) {  // a different displacement on each front node
    const index_t a = r.front[k];
    u[a] = 1e-5 * double(k + 1);
    u[2 * m.n_nodes + a] = -2e-5;
    want = std::max(want, std::hypot(u[a], 2e-5));
  }
  u[2 * m.n_nodes + seeds[0]] = -1e-3;  // larger, but not on the front
  b->set_displacements(u);
  const Reductions red = b->reduce();
  EXPECT_DOUBLE_EQ(red.front_disp, want);
  EXPECT_DOUBLE_EQ(red.max_disp, 1e-3);
}

/// The press of test_scheduler, centred on the top face.
std::vector<Waypoint> press() {
  return press_path({0.0305, 0.0295, kLz}, {0, 0, -1}, 0.002, 0.004, 0.05, 0.1, 0.4, 0.05);
}

struct Outcome {
  std::vector<double> u;  ///< final displacements (3 x n_nodes)
  Vec3<double> force;     ///< final force on the tool
  TickReport last;
  int max_depth = 0;
};

/// Runs the press to 0.5 s (the middle of the hold) with the given depth setting.
Outcome run(const TissueModel<double>& m, int depth, double auto_tol = 0.02) {
  auto b = make_cpu_backend(Precision::Double);
  b->upload(m);
  SchedulerSettings st;
  st.depth = depth;
  st.auto_tol = auto_tol;
  Scheduler sched(*b, m, st);
  ScriptedDevice tool(press());
  Outcome o;
  while (sched.time() < 0.5 - 1e-9) {
    o.last = sched.tick(tool);
    o.max_depth = std::max(o.max_depth, o.last.depth);
    if (depth == kDepthAuto && o.last.contact_nodes > 0) {
      EXPECT_GE(o.last.depth, st.auto_start);
      EXPECT_EQ(o.last.depth, sched.depth());
    }
  }
  o.u = b->download().u;
  o.force = o.last.force;
  return o;
}

double max_err(const std::vector<double>& u, const std::vector<double>& ref) {
  const size_t n = u.size() / 3;
  double e = 0, r = 0;
  for (size_t a = 0; a < n; ++a) {
    double d2 = 0, r2 = 0;
    for (int c = 0; c < 3; ++c) {
      d2 += (u[c * n + a] - ref[c * n + a]) * (u[c * n + a] - ref[c * n + a]);
      r2 += ref[c * n + a] * ref[c * n + a];
    }
    e = std::max(e, d2);
    r = std::max(r, r2);
  }
  return std::sqrt(e / r);
}

TEST(AdaptiveRegion, GrowsUntilTheFrontIsQuietAndBeatsItsStartDepth) {
  const TissueModel<double> m = pressed_box();
  const Outcome whole = run(m, kDepthAll);
  const Outcome start = run(m, 2);
  const Outcome loose = run(m, kDepthAuto, 0.05);
  const Outcome tight = run(m, kDepthAuto, 0.01);
  // it grew from its start depth, and further for the tighter tolerance
  EXPECT_GT(loose.last.depth, 2);
  EXPECT_GE(tight.last.depth, loose.last.depth);
  EXPECT_GT(tight.last.region_elems, start.last.region_elems);
  // it stopped because the front went quiet (or the fill covered the mesh)
  for (const Outcome* o : {&loose, &tight}) {
    const double tol = o == &loose ? 0.05 : 0.01;
    if (o->last.region_elems < m.n_elems) {
      EXPECT_LE(o->last.front_disp, tol * o->last.max_disp * 1.5);
    }
  }
  // its truncation error against the whole mesh is below its start depth's
  const double e_start = max_err(start.u, whole.u), e_loose = max_err(loose.u, whole.u),
               e_tight = max_err(tight.u, whole.u);
  std::cout << "[ INFO     ] error vs whole mesh: depth 2 " << e_start << ", auto 0.05 " << e_loose << " (depth "
            << loose.last.depth << "), auto 0.01 " << e_tight << " (depth " << tight.last.depth << ")\n";
  EXPECT_LT(e_loose, e_start);
  EXPECT_LT(e_loose, 2 * 0.05);  // on this layer the front tolerance bounds the truncation error
  EXPECT_LE(e_tight, e_loose);
  EXPECT_LT(norm(tight.force - whole.force), norm(start.force - whole.force));
}

/// A backend that does not compute the front-ring displacement (as a device
/// backend might not yet): depth auto must say so, not guess. It forwards
/// every stage to a real backend.
class NoFrontBackend final : public Backend {
 public:
  explicit NoFrontBackend(std::unique_ptr<Backend> b) : b_(std::move(b)) {}
  std::string name() const override { return "nofront"; }
  Precision precision() const override { return b_->precision(); }
  std::string device_name() const override { return b_->device_name(); }

 protected:
  void do_upload(const TissueModel<double>& m) override {
    dt_ = m.dt;
    damping_ = m.damping;
    b_->upload(m);
  }
  void do_set_motion(std::span<const double> u, std::span<const double> u_prev) override { b_->set_motion(u, u_prev); }
  void do_set_masses(const NodeMasses& k) override { b_->set_masses(k.mass, dt_, damping_); }
  std::vector<double> do_previous_displacements() override { return b_->previous_displacements(); }
  RegionSizes do_build_region(std::span<const index_t> s, int d) override { return b_->build_region(s, d); }
  Region do_region() override { return b_->region(); }
  std::vector<std::uint8_t> do_roles(std::span<const index_t> nodes) override {
    const Region r = b_->region();
    std::vector<std::uint8_t> out;
    for (index_t a : nodes) out.push_back(r.role[a]);
    return out;
  }
  void do_set_driven(std::span<const index_t> n, std::span<const double> u,
                     std::span<const std::uint8_t> axes) override {
    b_->set_driven_axes(n, u, axes);
  }
  void do_clear_driven() override { b_->clear_driven(); }
  void do_set_loads(std::span<const double> load) override {  // forwarded as (node, force) lists
    std::vector<index_t> nodes;
    std::vector<double> force;
    const std::size_t n = load.size() / 3;
    for (std::size_t a = 0; a < n; ++a) {
      nodes.push_back(index_t(a));
      force.insert(force.end(), {load[a], load[n + a], load[2 * n + a]});
    }
    b_->set_loads(nodes, force);
  }
  void do_begin_grasp(int, const ToolPose&) override {}
  void do_end_grasp(int) override {}
  void do_reset_contacts() override { b_->set_tools(tools()); }
  void do_element_pressure() override { b_->element_pressure(); }
  void do_nodal_pressure() override { b_->nodal_pressure(); }
  void do_element_forces() override { b_->element_forces(); }
  void do_node_update() override { b_->node_update(); }
  void do_advance(int steps, const ContactTools<double>& tools) override {
    if (b_->n_tools() != tools.n_tools) b_->set_tools(this->tools());
    std::vector<ToolMotion> m;
    for (int t = 0; t < tools.n_tools; ++t)
      m.push_back({{tools.tool[t].tip0, tools.tool[t].axis0}, {tools.tool[t].tip1, tools.tool[t].axis1}});
    b_->move_tools(m);
    b_->advance(steps);
  }
  std::vector<index_t> do_contact_candidates(const ContactTools<double>& sweep) override {
    if (b_->n_tools() != sweep.n_tools) b_->set_tools(tools());
    std::vector<ToolMotion> m;
    for (int t = 0; t < sweep.n_tools; ++t)
      m.push_back({{sweep.tool[t].tip0, sweep.tool[t].axis0}, {sweep.tool[t].tip1, sweep.tool[t].axis1}});
    b_->move_tools(m);
    return b_->contact_candidates();
  }
  std::vector<ContactNode> do_contacts() override { return b_->contacts(); }
  Reductions do_reduce() override {
    Reductions r = b_->reduce();
    r.front_disp = -1;
    return r;
  }
  Fields do_download() override { return b_->download(); }
  void do_write_positions(float* dst) override { b_->write_positions(dst); }

 private:
  std::unique_ptr<Backend> b_;
  double dt_ = 0, damping_ = 0;
};

TEST(AdaptiveRegion, BackendWithoutFrontMeasureIsNamed) {
  const TissueModel<double> m = pressed_box();
  NoFrontBackend b(make_cpu_backend(Precision::Double));
  b.upload(m);
  SchedulerSettings st;
  st.depth = kDepthAuto;
  Scheduler sched(b, m, st);
  ScriptedDevice tool(press());
  try {
    while (sched.time() < 0.2) sched.tick(tool);
    FAIL() << "depth auto ran without a front measure";
  } catch (const SimulationError& e) {
    EXPECT_NE(std::string(e.what()).find("nofront"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("front_disp"), std::string::npos) << e.what();
  }
}

TEST(AdaptiveRegion, BadSettingsAreRefused) {
  const TissueModel<double> m = pressed_box();
  auto b = make_cpu_backend(Precision::Double);
  b->upload(m);
  SchedulerSettings st;
  st.depth = kDepthAuto;
  st.auto_tol = 0;
  EXPECT_THROW(Scheduler(*b, m, st), std::invalid_argument);
  st.auto_tol = 0.02;
  st.auto_start = -1;
  EXPECT_THROW(Scheduler(*b, m, st), std::invalid_argument);
}

}  // namespace
}  // namespace tissue
