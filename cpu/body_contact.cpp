#include "cpu/body_contact.hpp"

#include <algorithm>

#include "core/node_rules.hpp"

namespace tissue::cpu {
namespace {

template <class T>
Vec3<T> at(const std::vector<T>& v, index_t n, index_t a) {
  return {v[a], v[n + a], v[2 * size_t(n) + a]};
}

}  // namespace

template <class T>
T BodyStage<T>::inverse_mass(const TissueState<T>& s, index_t a) const {
  const bool still = s.held[a] == kAllAxes || s.region.role[a] != kInner || s.contact[a] == kGrasped;
  return still ? T(0) : T(1) / m_.mass[a];
}

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
  if (anchors_.size() != std::size_t(lists_.rows())) anchors_.assign(std::size_t(lists_.rows()), BodyAnchor<T>{});
  moves_.assign(std::size_t(lists_.rows()), Vec3<T>{});
  counts_.assign(std::size_t(lists_.rows()), T(0));
  tris_.assign(lists_.cand_tri.begin(), lists_.cand_tri.end());
  std::sort(tris_.begin(), tris_.end());
  tris_.erase(std::unique(tris_.begin(), tris_.end()), tris_.end());
  tri_slot_.assign(std::size_t(m_.n_tris), -1);
  for (std::size_t i = 0; i < tris_.size(); ++i) tri_slot_[std::size_t(tris_[i])] = index_t(i);
  geom_.resize(tris_.size());
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
void BodyStage<T>::geometry(const TissueState<T>& s, int part, int parts) {
  const index_t n = m_.n_nodes, nt = m_.n_tris;
  const auto pos = [&](index_t a) { return at(m_.X, n, a) + at(s.u_next, n, a); };
  const auto tri = [&](index_t t, int k) { return m_.tris[k * nt + t]; };
  const std::size_t k = tris_.size(), first = k * std::size_t(part) / std::size_t(parts),
                    last = k * std::size_t(part + 1) / std::size_t(parts);
  for (std::size_t i = first; i < last; ++i) geom_[i] = body_tri<T>(tris_[i], pos, tri);
}

template <class T>
void BodyStage<T>::hits(const TissueState<T>& s, int part, int parts) {
  const index_t n = m_.n_nodes, nt = m_.n_tris;
  const auto pos = [&](index_t a) { return at(m_.X, n, a) + at(s.u_next, n, a); };
  const auto prev = [&](index_t a) { return at(m_.X, n, a) + at(s.u, n, a); };
  const auto tri = [&](index_t t, int k) { return m_.tris[k * nt + t]; };
  const auto geom = [&](index_t t) -> const BodyTri<T>& { return geom_[std::size_t(tri_slot_[std::size_t(t)])]; };
  const auto inv_mass = [&](index_t a) { return inverse_mass(s, a); };
  // the parts split the candidates, not the rows: most rows have none
  const std::vector<index_t>& start = lists_.cand_start;
  const long total = start.back();
  const auto row_at = [&](long c) { return index_t(std::lower_bound(start.begin(), start.end() - 1, index_t(c)) - start.begin()); };
  const index_t first = part == 0 ? 0 : row_at(total * part / parts),
                last = part + 1 == parts ? lists_.rows() : row_at(total * (part + 1) / parts);
  const T reach = T(lists_.skin);
  for (index_t r = first; r < last; ++r) {
    const BodyAnchor<T> was = anchors_[r];
    hits_[r] = body_row_hit<T>(lists_.node[r], start[r], start[r + 1], lists_.cand_tri.data(), cand_mu_.data(), reach,
                               pos, prev, inv_mass, tri, geom, was, anchors_[r]);
  }
}

template <class T>
void BodyStage<T>::finish(TissueState<T>& s) {
  const index_t n = m_.n_nodes, rows = lists_.rows();
  const auto inv_mass = [&](index_t a) { return inverse_mass(s, a); };
  // Rule 3 as scatters from the rows that hit, in ascending row order: the
  // same counts and, for each node, the same terms summed in the same order
  // as the gathers over corner entries (body_row_count, body_row_move) that
  // cuda runs, at the cost of the hits rather than of every corner entry.
  for (index_t r = 0; r < rows; ++r) counts_[r] = hits_[r].cand >= 0 ? T(1) : T(0);
  for (index_t r = 0; r < rows; ++r)
    if (const BodyHit<T>& h = hits_[r]; h.cand >= 0)
      for (int k = 0; k < 3; ++k)
        if (h.w[k] > T(0)) counts_[lists_.cand_rows[3 * size_t(h.cand) + k]] += h.w[k];
  for (index_t r = 0; r < rows; ++r) body_scale_hit(hits_[r], r, lists_.cand_rows.data(), counts_.data());
  for (index_t r = 0; r < rows; ++r) moves_[r] = hits_[r].cand >= 0 ? hits_[r].c : Vec3<T>{};
  for (index_t r = 0; r < rows; ++r)
    if (const BodyHit<T>& h = hits_[r]; h.cand >= 0)
      for (int k = 0; k < 3; ++k)
        if (const T w = h.w[k]; w > T(0)) {
          const index_t c = lists_.cand_rows[3 * size_t(h.cand) + k];
          moves_[c] = moves_[c] - w * h.c;
        }
  for (index_t r = 0; r < rows; ++r) {
    const index_t a = lists_.node[r];
    const T im = inv_mass(a);
    moves_[r] = im > T(0) ? free_part(s.held[a], im * moves_[r]) : Vec3<T>{};
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
