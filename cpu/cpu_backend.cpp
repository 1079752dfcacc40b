#include "cpu/cpu_backend.hpp"

#include <algorithm>
#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <fstream>
#include <numeric>
#include <stdexcept>

#include "cpu/constraints.hpp"
#include "cpu/element_lanes.hpp"
#include "cpu/host_backend.hpp"

#include "core/step_guard.hpp"

namespace tissue {

std::unique_ptr<Backend> make_cpu_backend(Precision precision) {
  // the lane kernels' tuning, read here on the caller's thread: a bad
  // TISSUE_CPU_TUNING is refused now, not inside a thread team's pass
  (void)cpu::lanes_tuning();
  if (precision == Precision::Float) return std::make_unique<cpu::CpuBackend<float>>();
  return std::make_unique<cpu::CpuBackend<double>>();
}

std::string cpu_device_name() {
  std::string model = "unknown CPU";
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) != 0) continue;
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    const auto first = line.find_first_not_of(" \t", colon + 1);
    if (first != std::string::npos) model = line.substr(first);
    break;
  }
  return fmt::format("{} ({} TBB threads)", model, tbb::this_task_arena::max_concurrency());
}

namespace cpu {

template <class T>
Precision CpuBackend<T>::precision() const {
  return std::is_same_v<T, float> ? Precision::Float : Precision::Double;
}

template <class T>
std::string CpuBackend<T>::device_name() const {
  return cpu_device_name();
}

template <class T>
void CpuBackend<T>::do_upload(const TissueModel<double>& model) {
  energy_.fresh = energy_.synced = false;
  contact_.reset();
  body_.reset();
  model_ = convert<T>(model);
  state_.resize(model_);  // held = the fixed axes, u_held = 0, nothing driven (core/store.hpp's initial values)
  node_divisor_ = nodal_pressure_divisors(model_);
  all_elems_.resize(model_.n_elems);
  std::iota(all_elems_.begin(), all_elems_.end(), 0);
  driven_list_.clear();
  driven_list_.reserve(64);
  state_.region = flood_fill(model_, std::span<const index_t>{}, kDepthAll);
  slices_.parts = 0;
  cpu::element_pressure(model_, state_, all_elems_, all_elems_part_);
  double J;
  bad_.take(&J);
  contact_ = std::make_unique<ContactStage<T>>(model_);
}

template <class T>
void CpuBackend<T>::do_set_motion(std::span<const double> u, std::span<const double> u_prev) {
  const index_t n = model_.n_nodes;
  for (std::size_t k = 0; k < u.size(); ++k) {
    state_.u[k] = state_.u_next[k] = T(u[k]);
    state_.u_prev[k] = T(u_prev[k]);
  }
  std::fill(state_.u_carry.begin(), state_.u_carry.end(), T(0));
  state_.clear_law_state();  // a new initial state: no Prony history
  energy_.fresh = energy_.synced = false;
  if (contact_) contact_->surface_moved();
  if (body_) body_->restart(state_);
  for (index_t a = 0; a < n; ++a)
    if (state_.region.role[a] == kHalo) {
      const std::uint8_t keep = state_.driven[a] | fixed_axes(model_.node_flags[a]);
      for (int c = 0; c < 3; ++c)
        if (!(keep >> c & 1)) state_.u_held[c * n + a] = state_.u[c * n + a];
    }
  cpu::element_pressure(model_, state_, all_elems_, all_elems_part_);
}

template <class T>
void CpuBackend<T>::do_warm_up() {
  if (contact_) contact_->warm_up(state_);
}

template <class T>
void CpuBackend<T>::do_set_masses(const NodeMasses& k) {
  model_.mass.assign(k.mass.begin(), k.mass.end());
  model_.cd_A.assign(k.cd_A.begin(), k.cd_A.end());
  model_.cd_B.assign(k.cd_B.begin(), k.cd_B.end());
  model_.cd_C.assign(k.cd_C.begin(), k.cd_C.end());
}

template <class T>
std::vector<double> CpuBackend<T>::do_deformed_altitudes(const TissueModel<double>& model,
                                                         std::span<const index_t> elems) {
  std::vector<double> out(elems.size());
  const std::span<const T> u(state_.u);
  for (std::size_t k = 0; k < elems.size(); ++k) out[k] = deformed_altitude(model, u, elems[k]);
  return out;
}

template <class T>
std::vector<double> CpuBackend<T>::do_previous_displacements() {
  return {state_.u_prev.begin(), state_.u_prev.end()};
}

template <class T>
RegionSizes CpuBackend<T>::do_build_region(std::span<const index_t> seeds, int depth) {
  install_region(model_, state_, flood_fill(model_, seeds, depth));
  slices_.parts = 0;
  energy_.fresh = energy_.synced = false;
  if (contact_) contact_->surface_moved();
  cpu::element_pressure(model_, state_, all_elems_, all_elems_part_);
  return state_.region.sizes();
}

template <class T>
std::vector<std::uint8_t> CpuBackend<T>::do_roles(std::span<const index_t> nodes) {
  std::vector<std::uint8_t> r(nodes.size());
  for (std::size_t k = 0; k < nodes.size(); ++k) r[k] = state_.region.role[nodes[k]];
  return r;
}

template <class T>
void CpuBackend<T>::do_set_driven(std::span<const index_t> nodes, std::span<const double> u,
                                  std::span<const std::uint8_t> axes) {
  drive_nodes(model_, state_, driven_list_, nodes, u, axes);
  if (contact_) contact_->surface_moved();
}

template <class T>
void CpuBackend<T>::do_set_loads(std::span<const double> load) {
  state_.load.assign(load.begin(), load.end());
}

template <class T>
void CpuBackend<T>::do_clear_driven() {
  release_driven(model_, state_, driven_list_);
  if (contact_) contact_->surface_moved();
}

template <class T>
void CpuBackend<T>::do_begin_grasp(int tool, const ToolPose& pose) {
  contact_->begin_grasp(state_, tool, pose.tip);
}

template <class T>
void CpuBackend<T>::do_end_grasp(int tool) {
  contact_->end_grasp(state_, tool);
}

template <class T>
void CpuBackend<T>::do_reset_contacts() {
  contact_->reset(state_);
}

template <class T>
void CpuBackend<T>::do_element_pressure() {
  energy_.fresh = false;  // a caller running the passes one by one
  cpu::element_pressure(model_, state_, state_.region.elems, parts_.element_pressure);
}

template <class T>
void CpuBackend<T>::do_nodal_pressure() {
  cpu::nodal_pressure(model_, state_, node_divisor_, state_.region.nodes, parts_.nodal_pressure);
}

template <class T>
void CpuBackend<T>::do_element_forces() {
  cpu::element_forces(model_, state_, state_.region.elems, bad_, parts_.element_forces);
}

template <class T>
void CpuBackend<T>::do_node_update() {
  energy_.fresh = false;  // u moves
  cpu::node_update(model_, state_, state_.region.nodes, parts_.node_update);
  rotate(state_);
}

template <class T>
const Slices& CpuBackend<T>::team_slices() {
  const int size = team_size_ > 0 ? team_size_ : default_team_size();
  if (!team_ || team_->size() != size) {
    team_ = std::make_unique<ThreadTeam>(size);
    slices_.parts = 0;
  }
  const int members = busy_members(state_.region.elems.size(), std::max(1, size - lent_cores_));
  if (slices_.parts != members) slice_region(state_.region, model_.node_elem_start.data(), members, kLanes, slices_);
  return slices_;
}

static_assert(kMaxParts >= ThreadTeam::kMaxSize, "a contact part per team member");

template <class T>
void CpuBackend<T>::do_advance(int steps, const ContactTools<double>& tools) {
  const ContactTools<T> t = contact_tools_as<T>(tools);
  for (int k = 0; k < kMaxTools; ++k) friction_[k] = k < t.n_tools ? t.tool[k].friction : T(0);
  // reduce() may have run passes 1-2 at this u already
  const bool have_pressure = take_passes(energy_, state_);
  energy_.fresh = false;  // u moves
  const std::span<const index_t> elems = state_.region.elems, nodes = state_.region.nodes;
  if (body_) body_->refresh(state_);
  const int members = team_slices().parts;
  ThreadTeam& team = *team_;
  bool sweeping = false;  // written by one barrier's last(), read by every member after it
  // each pass reads what the others' slices wrote in the pass before: a barrier between passes;
  // the contact stage starts on the last member to finish pass 4, every member sweeps its share of
  // the triangles near the tools, and the last to finish its share merges them and rotates
  team.run(members, [&](int r) {
    const std::span<const index_t> my_elems = slices_.elems(elems, r), my_nodes = slices_.nodes(nodes, r);
    for (int k = 0; k < steps; ++k) {
      if (k > 0 || !have_pressure) {
        cpu::element_pressure(model_, state_, my_elems);
        team.barrier();
        cpu::nodal_pressure(model_, state_, node_divisor_, my_nodes);
        team.barrier();
      }
      cpu::element_forces(model_, state_, my_elems, bad_);
      team.barrier();
      cpu::node_update(model_, state_, my_nodes);
      if (t.n_tools > 0) contact_->check_region(state_, my_nodes, r);  // its nodes' u_next in this core's cache
      if (body_) {  // the bodies' contact, before the tools': a rigid tool has the last word
        if (!team.barrier()) return;
        body_->geometry(state_, r, members);
        if (!team.barrier()) return;
        body_->hits(state_, r, members);
      }
      if (!team.barrier([&] {
            if (body_) body_->finish(state_);
            sweeping = contact_->begin_step(state_, t, k, members);
            if (!sweeping) rotate(state_);
          }))
        return;
      if (!sweeping) continue;
      contact_->sweep(state_, t, k, r);
      if (!team.barrier([&] {
            contact_->finish_step(state_, t, k);
            rotate(state_);
          }))
        return;
    }
  });
}

template <class T>
void CpuBackend<T>::do_set_body_contact(const BodyContactSpec& spec) {
  body_.reset();
  if (!spec.empty()) body_ = std::make_unique<BodyStage<T>>(model_, spec, state_);
}

template <class T>
std::vector<BodyContactNode> CpuBackend<T>::do_body_contacts() {
  return body_ ? body_->contacts() : std::vector<BodyContactNode>{};
}

template <class T>
std::vector<index_t> CpuBackend<T>::do_contact_candidates(const ContactTools<double>& sweep) {
  return contact_->candidates(state_, contact_tools_as<T>(sweep));
}

template <class T>
std::vector<ContactNode> CpuBackend<T>::do_contacts() {
  const index_t n = model_.n_nodes;
  std::vector<ContactNode> out;
  for (index_t a : contact_->touched()) {
    const Vec3<double> nrm = {double(state_.contact_normal[a]), double(state_.contact_normal[n + a]),
                              double(state_.contact_normal[2 * size_t(n) + a])};
    out.push_back({a, state_.contact_tool[a], state_.contact[a], state_.contact[a] == kPushed ? nrm : Vec3<double>{}});
  }
  return out;
}

template <class T>
Reductions CpuBackend<T>::do_reduce() {
  const Slices& slices = team_slices();
  Reductions r = reduce_region(model_, state_, node_divisor_, energy_, sums_, *team_, slices);
  r.front_disp = front_displacement(model_, state_);
  r.bad_elem = bad_.take(&r.bad_J);
  if (r.bad_elem < 0) r.bad_J = 1;
  reduce_contacts(model_, state_, contact_->touched(), friction_, r.tools);
  for (const ToolReduction& t : r.tools)
    r.finite = r.finite && std::isfinite(t.reaction.x + t.reaction.y + t.reaction.z);
  return r;
}

template <class T>
Fields CpuBackend<T>::do_download() {
  Fields f;
#define TISSUE_OUTPUT_COPY(name, ...) f.name.assign(state_.name.begin(), state_.name.end());
  TISSUE_OUTPUT_ARRAYS(TISSUE_OUTPUT_COPY)
#undef TISSUE_OUTPUT_COPY
  return f;
}

template <class T>
void CpuBackend<T>::do_write_positions(float* dst) {
  const index_t n = model_.n_nodes;
  const T* X = model_.X.data();
  const T* u = state_.u.data();
  tbb::parallel_for(tbb::blocked_range<index_t>(0, n, 4096), [&](const tbb::blocked_range<index_t>& r) {
    for (index_t i = r.begin(); i != r.end(); ++i)
      for (int c = 0; c < 3; ++c) dst[3 * i + c] = float(X[c * n + i] + u[c * n + i]);
  });
}

template class CpuBackend<float>;
template class CpuBackend<double>;

}  // namespace cpu
}  // namespace tissue
