#include "cpu/body_contact.hpp"

#include "core/node_rules.hpp"

namespace tissue::cpu {
namespace {

template <class T>
Vec3<T> at(const std::vector<T>& v, index_t n, index_t a) {
  return {v[a], v[n + a], v[2 * size_t(n) + a]};
}

}  // namespace

template <class T>
BodyStage<T>::BodyStage(const TissueModel<T>& m, const BodyContactSpec& spec, const TissueState<T>& s)
    : m_(m), spec_(spec) {
  build(s);
}

template <class T>
void BodyStage<T>::build(const TissueState<T>& s) {
  const index_t n = m_.n_nodes;
  std::vector<double> x(3 * std::size_t(n));
  for (index_t a = 0; a < n; ++a)
    for (int c = 0; c < 3; ++c) x[3 * size_t(a) + c] = double(m_.X[c * n + a]) + double(s.u[c * n + a]);
  lists_ = build_body_lists(m_, spec_, x);
  cand_mu_.assign(lists_.cand_mu.begin(), lists_.cand_mu.end());
  hits_.assign(std::size_t(lists_.rows()), BodyHit<T>{});
  moves_.assign(std::size_t(lists_.rows()), Vec3<T>{});
  counts_.assign(std::size_t(lists_.rows()), 0);
  ++builds_;
}

template <class T>
void BodyStage<T>::refresh(const TissueState<T>& s) {
  const index_t n = m_.n_nodes;
  const auto pos = [&](index_t a) {
    return Vec3<double>{double(m_.X[a]) + double(s.u[a]), double(m_.X[n + a]) + double(s.u[n + a]),
                        double(m_.X[2 * size_t(n) + a]) + double(s.u[2 * size_t(n) + a])};
  };
  if (body_lists_stale(lists_, pos)) build(s);
}

template <class T>
void BodyStage<T>::step(TissueState<T>& s) {
  const index_t n = m_.n_nodes, nt = m_.n_tris, rows = lists_.rows();
  const auto pos = [&](index_t a) { return at(m_.X, n, a) + at(s.u_next, n, a); };
  const auto prev = [&](index_t a) { return at(m_.X, n, a) + at(s.u, n, a); };
  const auto inv_mass = [&](index_t a) {
    const bool still = s.held[a] == kAllAxes || s.region.role[a] != kInner || s.contact[a] == kGrasped;
    return still ? T(0) : T(1) / m_.mass[a];
  };
  const auto tri = [&](index_t t, int k) { return m_.tris[k * nt + t]; };
  const T reach = T(lists_.skin);
  for (index_t r = 0; r < rows; ++r)
    hits_[r] = body_row_hit<T>(lists_.node[r], lists_.cand_start[r], lists_.cand_start[r + 1], lists_.cand_tri.data(),
                               cand_mu_.data(), reach, pos, prev, inv_mass, tri);
  const auto hits = [&](index_t r) -> const BodyHit<T>& { return hits_[r]; };
  for (index_t r = 0; r < rows; ++r)
    counts_[r] = body_row_count<T>(r, lists_.corner_start[r], lists_.corner_start[r + 1], lists_.corner_cand.data(),
                                   lists_.corner_row.data(), lists_.corner_slot.data(), hits);
  for (index_t r = 0; r < rows; ++r) body_scale_hit(hits_[r], r, lists_.cand_rows.data(), counts_.data());
  for (index_t r = 0; r < rows; ++r) {
    const index_t a = lists_.node[r];
    moves_[r] = free_part(s.held[a], body_row_move<T>(r, inv_mass(a), lists_.corner_start[r], lists_.corner_start[r + 1],
                                                      lists_.corner_cand.data(), lists_.corner_row.data(),
                                                      lists_.corner_slot.data(), hits));
  }
  for (index_t r = 0; r < rows; ++r) {
    const Vec3<T> d = moves_[r];
    if (d.x == T(0) && d.y == T(0) && d.z == T(0)) continue;
    const index_t a = lists_.node[r];
    for (int c = 0; c < 3; ++c) {
      s.u_next[c * size_t(n) + a] += d[c];
      s.u_carry[c * size_t(n) + a] = T(0);  // a position set by contact carries no rounding (as on cuda)
    }
  }
}

template <class T>
std::vector<BodyContactNode> BodyStage<T>::contacts() const {
  std::vector<BodyContactNode> out;
  for (index_t r = 0; r < lists_.rows(); ++r)
    if (hits_[r].cand >= 0) out.push_back({lists_.node[r], lists_.cand_tri[hits_[r].cand], double(hits_[r].gap)});
  return out;
}

template class BodyStage<float>;
template class BodyStage<double>;

}  // namespace tissue::cpu
