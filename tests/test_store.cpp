// The store declared once (core/store.hpp): every array of its lists has
// its declared shape and initial value on the host, survives convert(), is
// checked by the upload, reaches the download and the device views; a
// StateView holds no pointer outside the lists (so a group's launch moves
// every one), and a group moves the material's arrays, not the mesh's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "backends/registry.hpp"
#include "core/backend.hpp"
#include "core/box_mesh.hpp"
#include "core/state.hpp"
#include "core/store.hpp"
#include "cuda/views.hpp"

using namespace tissue;

namespace {

/// A 3 x 2 x 2 box (1 cm cells), its x = 0 face fixed and its x = max face
/// held in x only, with a fibre set and a two-term Prony set: every
/// declared array non-empty.
ModelInput box_input() {
  ModelInput in;
  box_mesh(in, 3, 2, 2, 0.03, 0.02, 0.02);
  MaterialParams soft{1000.0, 10000.0, 1000.0};
  soft.fibre_eta = 2000.0;
  MaterialParams visco{1500.0, 15000.0, 1000.0};
  visco.prony_terms = 2;
  visco.prony_g[0] = 0.2, visco.prony_g[1] = 0.1;
  visco.prony_tau[0] = 0.05, visco.prony_tau[1] = 0.5;
  in.materials = {soft, visco};
  const std::size_t ne = in.tets.size() / 4, nn = in.nodes.size() / 3;
  in.elem_material.assign(ne, 0);
  for (std::size_t e = ne / 2; e < ne; ++e) in.elem_material[e] = 1;
  in.fixed.assign(nn, 0);
  in.fixed_axes.assign(nn, 0);
  for (std::size_t a = 0; a < nn; ++a) {
    if (in.nodes[3 * a] < 1e-9) in.fixed[a] = 1;
    if (in.nodes[3 * a] > 0.03 - 1e-9) in.fixed_axes[a] = 1;  // x only
  }
  return in;
}

template <class V>
double value(V v) {
  return double(v);
}

}  // namespace

TEST(Store, EveryHostStateArrayHasItsDeclaredShapeAndInitialValue) {
  const TissueModel<double> m = build_model(box_input());
  TissueState<double> s;
  s.resize(m);
  int arrays = 0;
  const auto check = [&](const auto& v, const char* name, Per per, int components, Init init) {
    ++arrays;
    ASSERT_EQ(v.size(), store_entries(per, m) * components) << name;
    for (std::size_t k = 0; k < v.size(); ++k) {
      const double want = init == Init::One         ? 1.0
                          : init == Init::NoTool    ? -1.0
                          : init == Init::FixedAxes ? double(fixed_axes(m.node_flags[k]))
                                                    : 0.0;
      ASSERT_EQ(value(v[k]), want) << name << "[" << k << "]";
    }
  };
#define TISSUE_CHECK_STATE(name, type, per, components, init, unit, what) \
  check(s.name, #name, Per::per, components, Init::init);
  TISSUE_STATE_ARRAYS(TISSUE_CHECK_STATE)
  TISSUE_PASS_ARRAYS(TISSUE_CHECK_STATE)
  TISSUE_HOST_STATE_ARRAYS(TISSUE_CHECK_STATE)
#undef TISSUE_CHECK_STATE
  EXPECT_EQ(arrays, 17);
  // the support: fixed nodes hold every axis, the rollers x alone, and both kinds are there
  EXPECT_NE(std::count(s.held.begin(), s.held.end(), kAllAxes), 0);
  EXPECT_NE(std::count(s.held.begin(), s.held.end(), std::uint8_t(1)), 0);
  EXPECT_TRUE(s.load.empty());
  EXPECT_EQ(s.visco_q.size(), std::size_t(kSymComponents) * m.n_prony * m.n_visco);
  EXPECT_GT(s.visco_q.size(), 0u);
}

TEST(Store, ConvertCarriesEveryDeclaredModelArray) {
  const TissueModel<double> m = build_model(box_input());
  const TissueModel<float> f = convert<float>(m);
  int arrays = 0;
  const auto check = [&](const auto& to, const auto& from, const char* name) {
    ++arrays;
    ASSERT_FALSE(from.empty()) << name << " (the test's model uses every array)";
    ASSERT_EQ(to.size(), from.size()) << name;
    for (std::size_t k = 0; k < from.size(); ++k)
      ASSERT_EQ(double(to[k]), double(static_cast<std::decay_t<decltype(to[k])>>(from[k]))) << name << "[" << k << "]";
  };
#define TISSUE_CHECK_MODEL(name, ...) check(f.name, m.name, #name);
#define TISSUE_CHECK_LAW(kind, name, len) check(f.name, m.name, #name);
  TISSUE_MODEL_ARRAYS(TISSUE_CHECK_MODEL)
  TISSUE_LAW_MODEL_FIELDS(TISSUE_CHECK_LAW)
#undef TISSUE_CHECK_LAW
#undef TISSUE_CHECK_MODEL
  EXPECT_EQ(arrays, 19 + 6);
  EXPECT_EQ(f.n_surf, m.n_surf);
  EXPECT_EQ(f.n_visco, m.n_visco);
  EXPECT_EQ(f.n_prony, m.n_prony);
}

/// Each model array one value short (or one long) is refused by the
/// upload, naming the array and its declared shape.
TEST(Store, UploadRefusesAnyModelArrayOffItsDeclaredShape) {
  const TissueModel<double> good = build_model(box_input());
  auto backend = create_backend("cpu", Precision::Double);
  backend->upload(good);  // the model as built passes
  int arrays = 0;
  const auto refuse = [&](auto TissueModel<double>::*array, const char* name, Per per) {
    ++arrays;
    for (const int change : {-1, +1}) {
      TissueModel<double> bad = good;
      auto& v = bad.*array;
      if (change < 0)
        v.pop_back();
      else
        v.push_back(v.back());
      try {
        backend->upload(bad);
        ADD_FAILURE() << name << " with " << v.size() << " values was accepted";
      } catch (const std::invalid_argument& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(std::string("model's ") + name + " holds"), std::string::npos) << msg;
        EXPECT_NE(msg.find(to_string(per)), std::string::npos) << msg;
      }
    }
  };
#define TISSUE_REFUSE(name, type, per, components, unit, what) refuse(&TissueModel<double>::name, #name, Per::per);
  TISSUE_MODEL_ARRAYS(TISSUE_REFUSE)
#undef TISSUE_REFUSE
  EXPECT_EQ(arrays, 19);
  backend->upload(good);  // and a good model still goes up after the refusals
}

TEST(Store, DownloadCarriesEveryOutputArrayAtItsDeclaredShape) {
  const TissueModel<double> m = build_model(box_input());
  for (const Precision p : {Precision::Float, Precision::Double}) {
    auto backend = create_backend("cpu", p);
    backend->upload(m);
    const Fields f = backend->download();
    int arrays = 0;
#define TISSUE_CHECK_OUTPUT(name, vtu, field, per, components, unit) \
  ++arrays;                                                          \
  EXPECT_EQ(f.name.size(), store_entries(Per::per, m) * (components)) << #name;
    TISSUE_OUTPUT_ARRAYS(TISSUE_CHECK_OUTPUT)
#undef TISSUE_CHECK_OUTPUT
    EXPECT_EQ(arrays, 4);
    EXPECT_EQ(sizeof(Fields), 4 * sizeof(std::vector<double>));  // nothing outside the list
    for (double J : f.elem_J) ASSERT_EQ(J, 1.0);                 // at rest
  }
}

/// A StateView's every pointer is one of the store's arrays (or the load
/// or the skip flag): a pointer added outside the lists would not be moved
/// to each scene's slot by a group's launch, nor checked in its layout.
TEST(Store, DeviceStateViewHoldsOnlyDeclaredArraysAndMovesEachOne) {
  using View = gpu::StateView<float>;
  constexpr int declared = 0
#define TISSUE_COUNT(...) +1
      TISSUE_STATE_ARRAYS(TISSUE_COUNT) TISSUE_PASS_ARRAYS(TISSUE_COUNT) TISSUE_DEVICE_STATE_ARRAYS(TISSUE_COUNT);
#undef TISSUE_COUNT
  static_assert(sizeof(View) == (declared + 2) * sizeof(void*) + sizeof(gpu::SceneSlots),
                "StateView holds a pointer that is not in core/store.hpp's lists");
  EXPECT_EQ(declared, 18);
  // every pointer at its own address; moved(2) in a group of 4096-byte slots moves each by 8192
  alignas(64) static char arena[1 << 16];
  View v;
  std::size_t k = 0;
  const auto place = [&](auto*& p) { p = reinterpret_cast<std::remove_reference_t<decltype(p)>>(arena + 64 * ++k); };
#define TISSUE_PLACE(name, ...) place(v.name);
  TISSUE_STATE_ARRAYS(TISSUE_PLACE)
  TISSUE_PASS_ARRAYS(TISSUE_PLACE)
  TISSUE_DEVICE_STATE_ARRAYS(TISSUE_PLACE)
#undef TISSUE_PLACE
  v.slots.stride = 4096;
  const View w = v.moved(2);
  const auto moved_bytes = [](const void* a, const void* b) {
    return static_cast<const char*>(b) - static_cast<const char*>(a);
  };
  // compare the two views' bytes pointer by pointer: every declared pointer moved by two slots
  void* before[declared];
  void* after[declared];
  std::memcpy(before, &v, sizeof before);
  std::memcpy(after, &w, sizeof after);
  for (int i = 0; i < declared; ++i) EXPECT_EQ(moved_bytes(before[i], after[i]), 8192) << "pointer " << i;
}

TEST(Store, AGroupMovesTheMaterialsArraysNotTheMeshes) {
  gpu::ModelView<double> m;
  alignas(64) static char arena[1 << 12];
  const auto at = [&](int k) { return reinterpret_cast<const double*>(arena + 64 * k); };
  m.X = reinterpret_cast<const gpu::Packed3<double>*>(at(1));
  m.elem_nodes = reinterpret_cast<const index_t*>(at(2));
  m.dndx = at(3);
  int k = 4;
#define TISSUE_PLACE(name, ...) m.name = at(k++);
  TISSUE_MATERIAL_ARRAYS(TISSUE_PLACE)
#undef TISSUE_PLACE
  m.node_divisor = at(k++);
  const gpu::ModelView<double> w = m.materials_moved(1 << 20);
  EXPECT_EQ(w.X, m.X);
  EXPECT_EQ(w.elem_nodes, m.elem_nodes);
  EXPECT_EQ(w.dndx, m.dndx);
  int moved = 0;
#define TISSUE_MOVED(name, ...)                                                                                    \
  ++moved;                                                                                                         \
  EXPECT_EQ(reinterpret_cast<const char*>(w.name) - reinterpret_cast<const char*>(m.name), std::ptrdiff_t(1 << 20)) \
      << #name;
  TISSUE_MATERIAL_ARRAYS(TISSUE_MOVED)
#undef TISSUE_MOVED
  EXPECT_EQ(moved, 6);
  EXPECT_EQ(reinterpret_cast<const char*>(w.node_divisor) - reinterpret_cast<const char*>(m.node_divisor), 1 << 20);
}
