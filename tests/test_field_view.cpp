// The viewer's fields (apps/viewer/field_view.hpp): nodal values from a
// download, their ranges, the colour maps and the force history.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "apps/viewer/field_view.hpp"
#include "apps/viewer/surface_rings.hpp"
#include "core/box_mesh.hpp"

namespace tissue::viewer {
namespace {

/// Three nodes; two elements: node 0 in both, node 1 in element 0, node 2 in element 1.
struct TwoElements {
  Fields f;
  std::vector<index_t> start = {0, 2, 3, 4};
  std::vector<index_t> slots = {4 * 0 + 0, 4 * 1 + 2, 4 * 0 + 1, 4 * 1 + 3};
  TwoElements() {
    f.u = {3e-3, 0, 0, /*y*/ 4e-3, 0, 0, /*z*/ 0, 0, -2e-3};  // component-major
    f.node_p = {-50, 20, 10};
    f.elem_J = {0.9, 1.02};
  }
};

TEST(FieldView, DisplacementIsTheMagnitudeInMillimetres) {
  TwoElements s;
  const NodeField d = node_field(FieldKind::Displacement, s.f, 3, s.start, s.slots);
  ASSERT_EQ(d.value.size(), 3u);
  EXPECT_DOUBLE_EQ(d.value[0], 5.0);  // |(3, 4, 0)| mm
  EXPECT_DOUBLE_EQ(d.value[1], 0.0);
  EXPECT_DOUBLE_EQ(d.value[2], 2.0);
  EXPECT_EQ(d.lo, 0.0);
  EXPECT_DOUBLE_EQ(d.hi, 5.0);
  EXPECT_EQ(d.label, "|u| (mm)");
}

TEST(FieldView, PressureAndJAreSymmetricAboutRest) {
  TwoElements s;
  const NodeField p = node_field(FieldKind::Pressure, s.f, 3, s.start, s.slots);
  EXPECT_DOUBLE_EQ(p.lo, -50);
  EXPECT_DOUBLE_EQ(p.hi, 50);
  const NodeField j = node_field(FieldKind::Jacobian, s.f, 3, s.start, s.slots);
  EXPECT_DOUBLE_EQ(j.value[0], 0.5 * (0.9 + 1.02));  // the mean of its two elements
  EXPECT_DOUBLE_EQ(j.value[1], 0.9);
  EXPECT_DOUBLE_EQ(j.value[2], 1.02);
  EXPECT_NEAR(j.lo, 1 - (1 - 0.9), 1e-12);
  EXPECT_NEAR(j.hi, 1 + (1 - 0.9), 1e-12);
  // at rest the range keeps a small span: one colour, the map's middle
  TwoElements rest;
  rest.f.node_p = {0, 0, 0};
  const NodeField z = node_field(FieldKind::Pressure, rest.f, 3, rest.start, rest.slots);
  EXPECT_LT(z.lo, 0);
  EXPECT_GT(z.hi, 0);
  const std::vector<std::uint8_t> c = node_colours(z);
  EXPECT_EQ(c[0], c[3]);
  EXPECT_GT(c[0], 230);  // white: neither tension nor compression
}

TEST(FieldView, ColourMapsRunBetweenTheirEnds) {
  const auto lo = field_colour(FieldKind::Displacement, 0), hi = field_colour(FieldKind::Displacement, 1);
  EXPECT_GT(lo[2], lo[0]);                      // dark blue-violet at rest
  EXPECT_GT(hi[0], 200);                        // yellow at the largest
  EXPECT_GT(hi[1], 200);
  EXPECT_LT(hi[2], 80);
  EXPECT_EQ(field_colour(FieldKind::Displacement, 7), hi);  // clamped
  const auto blue = field_colour(FieldKind::Pressure, 0), red = field_colour(FieldKind::Pressure, 1);
  EXPECT_GT(blue[2], blue[0]);
  EXPECT_GT(red[0], red[2]);
  const auto nan = field_colour(FieldKind::Jacobian, NAN);
  EXPECT_EQ(nan[0], 255);
  EXPECT_EQ(nan[1], 0);
  EXPECT_EQ(nan[2], 255);
}

TEST(FieldView, NamesRoundTripAndBadNamesAreRefused) {
  for (FieldKind k : {FieldKind::None, FieldKind::Displacement, FieldKind::Pressure, FieldKind::Jacobian})
    EXPECT_EQ(parse_field_kind(field_name(k)), k);
  try {
    parse_field_kind("stress");
    FAIL() << "accepted 'stress'";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'stress'"), std::string::npos);
  }
}

TEST(FieldView, ForceHistoryKeepsItsWindowAndStartsOverOnARebuild) {
  ForceHistory h(1.0);
  for (int k = 0; k <= 30; ++k) h.add(0.1 * k, {0.01 * k, 1.0});
  EXPECT_EQ(h.n_tools(), 2);
  EXPECT_LE(h.span(), 1.0 + 1e-9);
  EXPECT_GT(h.span(), 0.9);
  EXPECT_NEAR(h.latest(0), 0.30, 1e-6);
  EXPECT_NEAR(h.peak(0), 0.30, 1e-6);
  EXPECT_NEAR(h.series(0).front(), 0.20, 1e-6);  // the oldest kept: t = 2.0 s
  h.add(0.0, {0.5, 0.5});                         // time went back: the tissue was rebuilt
  EXPECT_EQ(h.size(), 1u);
  EXPECT_NEAR(h.latest(1), 0.5, 1e-6);
}

// The smooth shading's rings: every surface triangle once at each of its
// corners, and the area-weighted normal they give points out of the body
// (along the face normal on a flat face, between the faces at an edge).
TEST(SurfaceRings, EachNodesTrianglesGiveItsOutwardNormal) {
  ModelInput in;
  box_mesh(in, 3, 2, 2, 0.03, 0.02, 0.02);
  in.materials = {{1000.0, 10000.0, 1000.0}};
  const TissueModel<double> m = build_model(in);
  const SurfaceRings r = surface_rings(m);
  ASSERT_EQ(r.range.size(), 2u * m.n_nodes);
  ASSERT_EQ(r.corners.size(), 2u * 3 * m.n_tris);
  const auto X = [&](index_t a) { return Vec3<double>{m.X[a], m.X[m.n_nodes + a], m.X[2 * size_t(m.n_nodes) + a]}; };
  const Vec3<double> centre{0.015, 0.01, 0.01};
  double area = 0;
  int surface = 0;
  for (index_t a = 0; a < m.n_nodes; ++a) {
    const int first = r.range[2 * a], count = r.range[2 * a + 1];
    Vec3<double> n{0, 0, 0};
    for (int k = first; k < first + count; ++k) {
      const Vec3<double> x = X(a), b = X(r.corners[2 * k]), c = X(r.corners[2 * k + 1]);
      n = n + cross(b - x, c - x);
      area += norm(cross(b - x, c - x)) / 6;  // a third of each triangle's area, at each corner
    }
    if (count == 0) continue;
    ++surface;
    EXPECT_GT(dot(n, X(a) - centre), 0) << "node " << a << " normal points into the box";
    const Vec3<double> d = X(a) - centre;  // on a face's interior the normal is the face's
    if (std::fabs(std::fabs(d.z) - 0.01) < 1e-12 && std::fabs(d.x) < 0.0149 && std::fabs(d.y) < 0.0099) {
      EXPECT_NEAR(std::fabs(n.z) / norm(n), 1.0, 1e-12) << "node " << a;
    }
  }
  EXPECT_EQ(surface, 4 * 3 * 3 - 2);  // the 4 x 3 x 3 grid nodes less the 2 interior ones
  EXPECT_NEAR(area, 2 * (0.03 * 0.02 + 0.03 * 0.02 + 0.02 * 0.02), 1e-15);
}

}  // namespace
}  // namespace tissue::viewer
