// The organ meshing pipeline (io/organ_mesher) on surfaces the test
// generates: target counts hold within kTargetPromise whatever the surface's
// unit and triangle count, Mesh_3 meets the quality goal of docs/meshing.md,
// an inclusion becomes its own region with its own volume, implausible units
// are named, absurd targets are refused before any run.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/tet.hpp"
#include "io/cgal_mesher.hpp"
#include "io/mesh_quality.hpp"
#include "io/organ_mesher.hpp"
#include "tests/surfaces.hpp"

using namespace tissue::io;
using tissue::index_t;
using tissue::Vec3;
namespace tt = tissue::test;

namespace {

constexpr double kPi = 3.14159265358979323846;

/// A 12 x 7 x 5 cm organ-sized ellipsoid, 5,120 triangles.
NamedSurface organ(int levels = 4) { return {tt::ellipsoid({0, 0, 0}, {0.06, 0.035, 0.025}, levels), "organ.obj"}; }

double tet_volume(const VolumeMesh& m, index_t e) {
  Vec3<double> X[4];
  for (int a = 0; a < 4; ++a) {
    const index_t c = m.tets[4 * e + a];
    X[a] = {m.nodes[3 * c], m.nodes[3 * c + 1], m.nodes[3 * c + 2]};
  }
  double dN[12];
  return tissue::tet_shape_gradients(X, dN);
}

QualityReport quality(const VolumeMesh& m) {
  return mesh_quality(m, {{1000.0, 30000.0, 1000.0}}, {}, 1e-3, 0.9, 0.025);
}

OrganMeshOptions target(int n, Mesher mesher) {
  OrganMeshOptions o;
  o.mesher = mesher;
  o.meshing.target_tets = n;
  o.meshing.min_dihedral = kDefaultMinDihedral;
  o.meshing.optimise = kDefaultOptimise;
  return o;
}

}  // namespace

TEST(OrganMesher, TargetHoldsForBothMeshers) {
  for (Mesher mesher : {Mesher::TetGen, Mesher::Mesh3}) {
    const OrganMesh r = mesh_organ(organ(), {}, target(20000, mesher));
    EXPECT_NEAR(r.mesh.n_tets(), 20000, kTargetPromise * 20000) << "mesher " << int(mesher);
    for (index_t e = 0; e < r.mesh.n_tets(); ++e) ASSERT_GT(tet_volume(r.mesh, e), 0);
  }
}

TEST(OrganMesher, TargetHoldsOnAMillimetreSurface) {
  // the same organ written in millimetres and read with the right unit
  NamedSurface mm{tt::scaled(tt::scaled(organ().surface, 1e3), 1e-3), "organ_mm.obj"};
  const OrganMesh r = mesh_organ(mm, {}, target(8000, Mesher::Auto));
  EXPECT_EQ(r.mesher, Mesher::Mesh3);
  EXPECT_NEAR(r.mesh.n_tets(), 8000, kTargetPromise * 8000);
}

TEST(OrganMesher, DenseSurfaceIsRemeshedAndTheTargetHolds) {
  NamedSurface dense = organ(7);  // 327,680 triangles
  ASSERT_GT(dense.surface.n_triangles(), 200000);
  int lines = 0;
  OrganMeshOptions o = target(20000, Mesher::TetGen);
  o.meshing.progress = [&](const std::string&) { ++lines; };
  const OrganMesh r = mesh_organ(dense, {}, o);
  EXPECT_GT(r.surfaces[0].remeshed_to, 0);
  EXPECT_LT(r.surfaces[0].triangles_out, 10000);
  EXPECT_GE(lines, 4) << "repair, remesh passes and TetGen runs print progress";
  EXPECT_NEAR(r.mesh.n_tets(), 20000, kTargetPromise * 20000);
}

TEST(OrganMesher, Mesh3MeetsTheQualityGoalTetGenDoesNot) {
  // docs/meshing.md: at ~20k tets, min dihedral >= 10 degrees and dt_crit >=
  // 1/4 of the median element's L/c. Mesh_3's perturbation and exudation
  // aim at 12 degrees; TetGen's q/10 bound leaves slivers.
  const QualityReport q = quality(mesh_organ(organ(), {}, target(20000, Mesher::Mesh3)).mesh);
  EXPECT_GE(q.min_dihedral, 10.0);
  EXPECT_GE(q.dt_ratio(), 0.25);
  const QualityReport t = quality(mesh_organ(organ(), {}, target(20000, Mesher::TetGen)).mesh);
  EXPECT_LT(t.dt_ratio(), q.dt_ratio()) << "the measurement behind the default";
}

/// A groove 3 mm wide and 8 mm deep across the organ's top, against the
/// 4.7 mm elements 20,000 tets ask for: its walls forced elements a few
/// times smaller than the median (dt ratio 0.07 with the surface-distance
/// criterion, docs/meshing.md). The alpha wrap at half the target edge
/// closes it: the step goal holds, the angles are Mesh_3's 18 degrees, and
/// the volume moves by the groove's and the wrap's offset, a few percent.
TEST(OrganMesher, AGrooveNarrowerThanTheElementsForcesNoSmallerOnes) {
  const NamedSurface grooved{tt::grooved_ellipsoid({0, 0, 0}, {0.06, 0.035, 0.025}, 6, 0.008, 0.003), "grooved.obj"};
  const double volume = std::fabs(enclosed_volume(grooved.surface));
  const OrganMesh r = mesh_organ(grooved, {}, target(20000, Mesher::Auto));
  EXPECT_EQ(r.mesher, Mesher::Mesh3);
  EXPECT_NEAR(r.surfaces[0].wrapped_alpha, kWrapAlpha * r.target_edge, 1e-12);
  EXPECT_NEAR(r.mesh.n_tets(), 20000, kTargetPromise * 20000);
  const QualityReport q = quality(r.mesh);
  EXPECT_GE(q.dt_ratio(), 0.25);
  EXPECT_GE(q.min_dihedral, 17.5);
  double meshed = 0;
  for (index_t e = 0; e < r.mesh.n_tets(); ++e) meshed += tet_volume(r.mesh, e);
  EXPECT_NEAR(meshed / volume, 1.0, 0.03);
}

TEST(OrganMesher, InclusionIsItsOwnConformingRegion) {
  NamedSurface tumour{tt::ellipsoid({0.01, 0, 0.005}, {0.01, 0.008, 0.007}, 3), "tumour.obj"};
  const double tumour_volume = enclosed_volume(tumour.surface);
  OrganMeshOptions o = target(0, Mesher::Auto);
  o.meshing.max_volume = enclosed_volume(organ().surface) / 10000;
  o.remesh_edge = -1;  // the surfaces as given, so that the region volumes are exact
  const OrganMesh r = mesh_organ(organ(), {tumour}, o);
  EXPECT_EQ(r.mesher, Mesher::TetGen);
  ASSERT_EQ(r.mesh.tet_region.size(), size_t(r.mesh.n_tets()));
  double v_in = 0, v_all = 0;
  for (index_t e = 0; e < r.mesh.n_tets(); ++e) {
    const double v = tet_volume(r.mesh, e);
    v_all += v;
    ASSERT_TRUE(r.mesh.tet_region[e] == 0 || r.mesh.tet_region[e] == 1);
    if (r.mesh.tet_region[e] == 1) {
      v_in += v;
      // conforming: every tet of the region lies inside the tumour surface
      Vec3<double> c{0, 0, 0};
      for (int a = 0; a < 4; ++a)
        for (int k = 0; k < 3; ++k) (&c.x)[k] += 0.25 * r.mesh.nodes[3 * r.mesh.tets[4 * e + a] + k];
      ASSERT_GT(winding_number(tumour.surface, c), 0.5) << "tet " << e;
    }
  }
  EXPECT_NEAR(v_in, tumour_volume, 1e-9 * tumour_volume) << "the region fills the inclusion exactly";
  EXPECT_NEAR(v_all, enclosed_volume(organ().surface), 1e-9 * v_all);
}

TEST(OrganMesher, InclusionOutsideTheOrganIsNamed) {
  NamedSurface outside{tt::ellipsoid({0.2, 0, 0}, {0.01, 0.01, 0.01}, 2), "tumour.obj"};
  try {
    mesh_organ(organ(), {outside}, target(5000, Mesher::Auto));
    FAIL();
  } catch (const MeshError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("tumour.obj"), std::string::npos) << msg;
    EXPECT_NE(msg.find("outside the organ"), std::string::npos) << msg;
  }
}

TEST(OrganMesher, NoRepairKeepsTodaysErrors) {
  NamedSurface holed = organ(3);
  tt::cut_fan(holed.surface, 0);
  OrganMeshOptions o = target(5000, Mesher::TetGen);
  o.repair = false;
  try {
    mesh_organ(holed, {}, o);
    FAIL();
  } catch (const MeshError& e) {
    EXPECT_NE(std::string(e.what()).find("the surface is open"), std::string::npos) << e.what();
  }
  o.repair = true;
  const OrganMesh r = mesh_organ(holed, {}, o);
  EXPECT_EQ(r.surfaces[0].repair.holes_filled, 1);
}

TEST(OrganMesher, AbsurdTargetIsRefusedNamingTheMemory) {
  for (Mesher mesher : {Mesher::TetGen, Mesher::Mesh3}) {
    try {
      mesh_organ(organ(2), {}, target(2000000000, mesher));
      FAIL();
    } catch (const MeshError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("GB of memory"), std::string::npos) << msg;
      EXPECT_NE(msg.find("organ.obj"), std::string::npos) << msg;
    }
  }
}

// A mesh whose step is set by a tiny element: the report says where that element lies and how small it is
TEST(MeshQuality, AStepFarBelowTheMedianNamesItsElement) {
  VolumeMesh m;
  // three corner tets of edge 10 mm, and one of edge 0.1 mm at (20, 0, 0) mm
  const auto corner = [&](double x0, double a) {
    const index_t b = m.n_nodes();
    for (const Vec3<double>& p : {Vec3<double>{0, 0, 0}, Vec3<double>{a, 0, 0}, Vec3<double>{0, a, 0},
                                  Vec3<double>{0, 0, a}})
      m.nodes.insert(m.nodes.end(), {x0 + p.x, p.y, p.z});
    m.tets.insert(m.tets.end(), {b, b + 1, b + 2, b + 3});
  };
  corner(0.0, 0.01);
  corner(0.03, 0.01);
  corner(0.06, 0.01);
  corner(0.02, 0.0001);
  const QualityReport q = quality(m);
  EXPECT_EQ(q.dt_crit_elem, 3);
  EXPECT_LT(q.dt_ratio(), kDtRatioGoal);
  const std::string s = q.summary();
  EXPECT_NE(s.find("below the goal of 0.25: element 3 at (20.03, 0.025, 0.025) mm sets the step, its edges 0.1 to "
                   "0.141 mm against a median element's longest edge of 14.1 mm"),
            std::string::npos)
      << s;
  // a mesh of equal tets meets the goal and says nothing more
  m.tets.resize(12);
  EXPECT_EQ(quality(m).summary().find("below the goal"), std::string::npos);
}

// a tiny largest volume is refused naming the option and its value, on either mesher
TEST(OrganMesher, TinyMaxVolumeIsRefusedNamingTheOption) {
  for (Mesher mesher : {Mesher::TetGen, Mesher::Mesh3}) {
    OrganMeshOptions o = target(0, mesher);
    o.meshing.max_volume = 1e-15;
    try {
      mesh_organ(organ(2), {}, o);
      FAIL();
    } catch (const MeshError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("--max-volume 1e-15 m^3"), std::string::npos) << msg;
      EXPECT_NE(msg.find("GB of memory"), std::string::npos) << msg;
    }
  }
}

TEST(UnitWarning, NamesTheLikelyUnit) {
  EXPECT_EQ(unit_warning(0.12, "m"), "");
  const std::string big = unit_warning(120.0, "m");  // a 12 cm organ written in mm, read as m
  EXPECT_NE(big.find("too large"), std::string::npos) << big;
  EXPECT_NE(big.find("--unit mm"), std::string::npos) << big;
  const std::string small = unit_warning(0.0012, "mm");  // 1.2 mm: written in cm, read as mm
  EXPECT_NE(small.find("too small"), std::string::npos) << small;
  EXPECT_NE(small.find("--unit cm"), std::string::npos) << small;
  EXPECT_NE(unit_warning(5000.0, "m").find("5e+06 mm across"), std::string::npos);
}

TEST(MeshQuality, RegularTetAndSliver) {
  const double a = 0.01;
  Vec3<double> X[4] = {{0, 0, 0}, {a, 0, 0}, {a / 2, a * std::sqrt(3.0) / 2, 0},
                       {a / 2, a * std::sqrt(3.0) / 6, a * std::sqrt(2.0 / 3.0)}};
  double ang[6];
  tet_dihedral_angles(X, ang);
  for (double t : ang) EXPECT_NEAR(t, std::acos(1.0 / 3.0), 1e-12);
  VolumeMesh m;
  for (const auto& p : X) m.nodes.insert(m.nodes.end(), {p.x, p.y, p.z});
  m.tets = {0, 1, 2, 3};
  const QualityReport q = quality(m);
  EXPECT_NEAR(q.min_dihedral, std::acos(1.0 / 3.0) * 180 / kPi, 1e-9);
  EXPECT_DOUBLE_EQ(q.dt_ratio(), 1.0);
  // a sliver: the apex pushed down onto the base's plane
  X[3].z = 1e-4 * a;
  tet_dihedral_angles(X, ang);
  EXPECT_LT(*std::min_element(ang, ang + 6), 1e-3);
  EXPECT_GT(*std::max_element(ang, ang + 6), kPi - 1e-3);
}

namespace tissue::io {
namespace {

// A coarse organ (a 12-triangle box) with a finely meshed inclusion: the
// inclusion's surface forces more tets than the target, and the organ,
// whose own surface is not too fine, must not be coarsened for it (it was
// remeshed into a 4-triangle tetrahedron, leaving the inclusion outside:
// docs/meshing.md).
TEST(OrganMesher, AFineInclusionDoesNotCoarsenACoarseOrgan) {
  io::SurfaceMesh box;
  tt::add_box(box, 0.0, 0.04);
  const NamedSurface tumour{tt::ellipsoid({0.02, 0.02, 0.02}, {0.004, 0.004, 0.004}, 3), "tumour.obj"};
  OrganMeshOptions o;
  o.mesher = Mesher::TetGen;
  o.meshing.target_tets = 2000;
  const OrganMesh r = mesh_organ({box, "box.obj"}, {tumour}, o);
  EXPECT_GE(r.surfaces[0].triangles_out, 12) << "the organ keeps its shape";
  EXPECT_GT(r.mesh.n_tets(), (1 + kTargetPromise) * 2000) << "the inclusion's surface forces more tets";
  long in_tumour = 0;
  for (int region : r.mesh.tet_region) in_tumour += region == 1;
  EXPECT_GT(in_tumour, 0);
}

}  // namespace
}  // namespace tissue::io
