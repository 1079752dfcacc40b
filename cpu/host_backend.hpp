// The cpu backend's class (private to cpu/ and its tests; everyone else uses
// make_cpu_backend() and the Backend interface). It owns the model and the
// state in its scalar T (float or double), allocated once in upload(); the
// step loop (advance: the four passes and the contact stage, reduce)
// allocates nothing once the contact scratch has grown. advance runs all its
// steps as one job of a persistent thread team (cpu/thread_team.hpp) over
// fixed slices of the region (cpu/partition.hpp). Stages are the free
// functions of cpu/passes.hpp, cpu/constraints.hpp, cpu/reduce.hpp and the
// contact stage of cpu/contact.hpp; this class only sequences them. Not
// thread-safe: one thread (the haptic loop) drives it.
#pragma once

#include <algorithm>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/backend.hpp"
#include "core/state.hpp"
#include "cpu/bad_element.hpp"
#include "cpu/body_contact.hpp"
#include "cpu/contact.hpp"
#include "cpu/partition.hpp"
#include "cpu/passes.hpp"
#include "cpu/reduce.hpp"
#include "cpu/thread_team.hpp"

namespace tissue::cpu {

template <class T>
class CpuBackend final : public Backend {
 public:
  std::string name() const override { return "cpu"; }
  Precision precision() const override;
  std::string device_name() const override;

  /// The store, read-only (tests).
  const TissueModel<T>& model() const { return model_; }
  const TissueState<T>& state() const { return state_; }
  /// Surface BVH builds so far (tests: rebuilt only when the surface left its margin).
  long surface_builds() const { return contact_ ? contact_->bvh().builds() : 0; }
  /// The contact stage (tests: its query skin and query count); null before upload.
  ContactStage<T>* contact_stage() { return contact_.get(); }
  /// Runs advance and reduce on a team of `size` members (1..255) instead
  /// of default_team_size() (0: the default again). Tests: results must not
  /// depend on it.
  void set_team_size(int size) {
    if (size < 0 || size > ThreadTeam::kMaxSize)
      throw std::invalid_argument("set_team_size: " + std::to_string(size) + " is outside 0..255");
    team_size_ = size;
  }
  /// A batch runs one scene per thread: set_team_size(threads).
  void set_worker_threads(int threads) override { set_team_size(threads); }
  void lend_cores(int cores) override { lent_cores_ = std::max(0, cores); }
  /// The members the last advance or reduce kept busy (0 before the first,
  /// and after upload or build_region until the next).
  int busy_team_members() const { return slices_.parts; }

 protected:
  void do_upload(const TissueModel<double>& model) override;
  void do_set_motion(std::span<const double> u, std::span<const double> u_prev) override;
  std::vector<double> do_previous_displacements() override;
  void do_warm_up() override;
  void do_set_masses(const NodeMasses& masses) override;
  /// From the displacements it holds (no copy of the state).
  std::vector<double> do_deformed_altitudes(const TissueModel<double>& model, std::span<const index_t> elems) override;
  RegionSizes do_build_region(std::span<const index_t> seeds, int depth) override;
  Region do_region() override { return state_.region; }
  std::vector<std::uint8_t> do_roles(std::span<const index_t> nodes) override;
  void do_set_driven(std::span<const index_t> nodes, std::span<const double> u,
                     std::span<const std::uint8_t> axes) override;
  void do_clear_driven() override;
  void do_set_loads(std::span<const double> load) override;
  void do_begin_grasp(int tool, const ToolPose& pose) override;
  void do_end_grasp(int tool) override;
  void do_reset_contacts() override;
  void do_element_pressure() override;
  void do_nodal_pressure() override;
  void do_element_forces() override;
  void do_node_update() override;
  void do_advance(int steps, const ContactTools<double>& tools) override;
  std::vector<index_t> do_contact_candidates(const ContactTools<double>& sweep) override;
  std::vector<ContactNode> do_contacts() override;
  /// Also the strain energy over the region's elements and the front
  /// ring's displacement (cpu/reduce.hpp).
  Reductions do_reduce() override;
  Fields do_download() override;
  void do_write_positions(float* dst) override;
  void do_set_body_contact(const BodyContactSpec& spec) override;
  std::vector<BodyContactNode> do_body_contacts() override;

 public:
  long body_list_builds() const override { return body_ ? body_->builds() : 0; }

 private:
  /// Creates team_ (default_team_size() or set_team_size's members) and
  /// slices the region for it when either changed; returns the slices.
  const Slices& team_slices();

  TissueModel<T> model_;
  TissueState<T> state_;
  std::vector<T> node_divisor_;       ///< V_a / K_a per node (n_nodes) m^3/Pa, pass 2's divisor (core nodal_pressure_divisors)
  std::vector<index_t> all_elems_;    ///< 0..n_elems-1: pass 1 over every element
  std::vector<index_t> driven_list_;  ///< currently driven nodes
  std::unique_ptr<ContactStage<T>> contact_;
  std::unique_ptr<BodyStage<T>> body_;  ///< contact between bodies; null when off
  T friction_[kMaxTools] = {};        ///< each tool's friction coefficient in the last advance (the reaction's)
  EnergyScratch<T> energy_;           ///< reduce's passes 1-2, taken by the next step
  BadElementFlag bad_;
  PassPartitioners parts_;            ///< the one-pass calls' TBB loops
  std::unique_ptr<ThreadTeam> team_;  ///< advance's threads (created on first use, sized by default_team_size)
  Slices slices_;                     ///< the region's slices for team_ (parts 0 after the region changes)
  ReduceScratch sums_;                ///< reduce's per-chunk sums
  int team_size_ = 0;                 ///< set_team_size's, 0 = default_team_size()
  int lent_cores_ = 0;                ///< lend_cores': the team keeps this many members fewer busy
  tbb::affinity_partitioner all_elems_part_;
};

}  // namespace tissue::cpu
