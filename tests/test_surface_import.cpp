// Surface import: one small cube file per format, written by the test (3DS
// through Assimp's own exporter), checked for counts after welding, the unit
// scaling and closedness; unreadable files; check_closed's messages.
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <assimp/Exporter.hpp>
#include <assimp/Importer.hpp>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "io/surface_import.hpp"

namespace fs = std::filesystem;
using tissue::index_t;
using namespace tissue::io;

namespace {

// Unit cube corners, id i + 2 j + 4 k for corner (i, j, k), and its six faces
// as outward (counter-clockwise seen from outside) quads.
constexpr int kQuads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};

double corner(int v, int axis, double side) {
  return side * ((v >> axis) & 1);
}

struct TempDir {
  fs::path dir;
  TempDir() {
    dir = fs::temp_directory_path() /
          ("tissue_surface_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  ~TempDir() { fs::remove_all(dir); }
  std::string file(const std::string& name) const { return (dir / name).string(); }
};

void write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
}

std::string cube_obj(double side) {
  std::string s = "# cube\n";
  for (int v = 0; v < 8; ++v)
    s += "v " + std::to_string(corner(v, 0, side)) + " " + std::to_string(corner(v, 1, side)) + " " +
         std::to_string(corner(v, 2, side)) + "\n";
  for (const auto& q : kQuads)
    s += "f " + std::to_string(q[0] + 1) + " " + std::to_string(q[1] + 1) + " " + std::to_string(q[2] + 1) + " " +
         std::to_string(q[3] + 1) + "\n";
  return s;
}

std::string cube_off(double side) {
  std::string s = "OFF\n8 6 0\n";
  for (int v = 0; v < 8; ++v)
    s += std::to_string(corner(v, 0, side)) + " " + std::to_string(corner(v, 1, side)) + " " +
         std::to_string(corner(v, 2, side)) + "\n";
  for (const auto& q : kQuads)
    s += "4 " + std::to_string(q[0]) + " " + std::to_string(q[1]) + " " + std::to_string(q[2]) + " " +
         std::to_string(q[3]) + "\n";
  return s;
}

std::string cube_ply(double side) {
  std::string s =
      "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 6\nproperty list uchar int vertex_indices\nend_header\n";
  for (int v = 0; v < 8; ++v)
    s += std::to_string(corner(v, 0, side)) + " " + std::to_string(corner(v, 1, side)) + " " +
         std::to_string(corner(v, 2, side)) + "\n";
  for (const auto& q : kQuads)
    s += "4 " + std::to_string(q[0]) + " " + std::to_string(q[1]) + " " + std::to_string(q[2]) + " " +
         std::to_string(q[3]) + "\n";
  return s;
}

/// The 12 outward triangles of the cube, as corner ids.
std::vector<std::array<int, 3>> cube_triangles() {
  std::vector<std::array<int, 3>> t;
  for (const auto& q : kQuads) {
    t.push_back({q[0], q[1], q[2]});
    t.push_back({q[0], q[2], q[3]});
  }
  return t;
}

std::string cube_stl_ascii(double side) {
  std::string s = "solid cube\n";
  for (const auto& t : cube_triangles()) {
    s += "  facet normal 0 0 0\n    outer loop\n";
    for (int v : t)
      s += "      vertex " + std::to_string(corner(v, 0, side)) + " " + std::to_string(corner(v, 1, side)) + " " +
           std::to_string(corner(v, 2, side)) + "\n";
    s += "    endloop\n  endfacet\n";
  }
  return s + "endsolid cube\n";
}

void write_cube_stl_binary(const std::string& path, double side) {
  std::ofstream f(path, std::ios::binary);
  char header[80] = {};
  std::strncpy(header, "binary cube written by test_surface_import", sizeof header - 1);
  f.write(header, 80);
  const auto tris = cube_triangles();
  const std::uint32_t n = static_cast<std::uint32_t>(tris.size());
  f.write(reinterpret_cast<const char*>(&n), 4);
  for (const auto& t : tris) {
    float rec[12] = {0, 0, 0};
    for (int c = 0; c < 3; ++c)
      for (int a = 0; a < 3; ++a) rec[3 + 3 * c + a] = static_cast<float>(corner(t[c], a, side));
    f.write(reinterpret_cast<const char*>(rec), sizeof rec);
    const std::uint16_t attr = 0;
    f.write(reinterpret_cast<const char*>(&attr), 2);
  }
}

/// Bounding-box extents (m) per axis.
std::array<double, 3> extents(const SurfaceMesh& s) {
  std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (size_t k = 0; k < s.vertices.size(); ++k) {
    lo[k % 3] = std::min(lo[k % 3], s.vertices[k]);
    hi[k % 3] = std::max(hi[k % 3], s.vertices[k]);
  }
  return {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
}

/// A 2-unit cube read in mm is a 2 mm cube: 8 welded vertices, 12 triangles,
/// closed, enclosing 8 mm^3.
void expect_cube(const SurfaceMesh& s, double side_m) {
  EXPECT_EQ(s.n_vertices(), 8);
  EXPECT_EQ(s.n_triangles(), 12);
  for (double e : extents(s)) EXPECT_NEAR(e, side_m, 1e-9 * side_m);
  EXPECT_NO_THROW(check_closed(s, "cube"));
  EXPECT_NEAR(std::fabs(enclosed_volume(s)), side_m * side_m * side_m, 1e-9 * side_m * side_m * side_m);
}

}  // namespace

TEST(ParseUnit, KnownUnitsAndError) {
  EXPECT_DOUBLE_EQ(parse_unit("m"), 1.0);
  EXPECT_DOUBLE_EQ(parse_unit("cm"), 0.01);
  EXPECT_DOUBLE_EQ(parse_unit("mm"), 0.001);
  try {
    parse_unit("inch");
    FAIL() << "expected MeshError";
  } catch (const MeshError& e) {
    EXPECT_NE(std::string(e.what()).find("'inch'"), std::string::npos) << e.what();
  }
}

TEST(LoadSurface, Obj) {
  TempDir t;
  write_text(t.file("cube.obj"), cube_obj(2.0));
  const SurfaceMesh s = load_surface(t.file("cube.obj"), parse_unit("mm"));
  expect_cube(s, 2e-3);
  EXPECT_GT(enclosed_volume(s), 0) << "outward faces stay outward";
}

TEST(LoadSurface, StlAscii) {
  TempDir t;
  write_text(t.file("cube.stl"), cube_stl_ascii(3.0));
  const SurfaceMesh s = load_surface(t.file("cube.stl"), parse_unit("cm"));
  expect_cube(s, 0.03);
  EXPECT_GT(enclosed_volume(s), 0);
}

TEST(LoadSurface, StlBinary) {
  TempDir t;
  write_cube_stl_binary(t.file("cube.stl"), 5.0);
  const SurfaceMesh s = load_surface(t.file("cube.stl"), parse_unit("mm"));
  expect_cube(s, 5e-3);
  EXPECT_GT(enclosed_volume(s), 0);
}

// A binary STL whose header's triangle count does not match the file's
// size got Assimp's "Failed to determine STL storage representation" (and a
// count that wraps 32 bits could pass Assimp's own check): the count is
// checked against the size first, naming the file, the count and the size.
TEST(LoadSurface, StlBinaryWhoseCountLiesIsRefusedNamingCountAndSize) {
  TempDir t;
  const auto refused = [&](std::uint32_t count, std::initializer_list<std::string> parts) {
    const std::string path = t.file("lie.stl");
    write_cube_stl_binary(path, 5.0);  // 84 + 12 x 50 = 684 bytes
    {
      std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
      f.seekp(80);
      f.write(reinterpret_cast<const char*>(&count), 4);
    }
    try {
      load_surface(path, 1e-3);
      return testing::AssertionFailure() << "count " << count << " was read";
    } catch (const MeshError& e) {
      const std::string msg = e.what();
      for (const std::string& p : parts)
        if (msg.find(p) == std::string::npos) return testing::AssertionFailure() << msg << "\nlacks: " << p;
    }
    return testing::AssertionSuccess();
  };
  const std::string path = t.file("lie.stl");
  EXPECT_TRUE(refused(1000000, {path + ": the binary STL header claims 1000000 triangles, which take 84 + 50 x "
                                       "1000000 = 50000084 bytes, but the file has 684 bytes (room for 12 triangles)"}));
  EXPECT_TRUE(refused(11, {"claims 11 triangles", "684 bytes (room for 12 triangles)", "truncated"}));
  // 84 + 50 n wraps to 684 in 32 bits: Assimp's own test would take it for billions of triangles
  EXPECT_TRUE(refused(2147483660u, {"claims 2147483660 triangles", "107374183084 bytes", "684 bytes"}));
  write_text(t.file("short.stl"), "tiny");
  EXPECT_THROW(load_surface(t.file("short.stl"), 1.0), MeshError);
  write_cube_stl_binary(path, 5.0);  // the count restored: read
  expect_cube(load_surface(path, 1e-3), 5e-3);
  // a folder named like a surface is a folder, not a file of 2^63 bytes
  fs::create_directory(t.file("d.stl"));
  try {
    load_surface(t.file("d.stl"), 1.0);
    ADD_FAILURE() << "a folder was read as a surface";
  } catch (const MeshError& e) {
    EXPECT_EQ(std::string(e.what()), t.file("d.stl") + ": is a directory, not a surface file");
  }
}

TEST(LoadSurface, Ply) {
  TempDir t;
  write_text(t.file("cube.ply"), cube_ply(0.5));
  const SurfaceMesh s = load_surface(t.file("cube.ply"), parse_unit("m"));
  expect_cube(s, 0.5);
  EXPECT_GT(enclosed_volume(s), 0);
}

TEST(LoadSurface, Off) {
  TempDir t;
  write_text(t.file("cube.off"), cube_off(4.0));
  const SurfaceMesh s = load_surface(t.file("cube.off"), 0.25);
  expect_cube(s, 1.0);
}

TEST(LoadSurface, ThreeDsFromAssimpExporter) {
  TempDir t;
  write_text(t.file("cube.obj"), cube_obj(7.0));
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile(t.file("cube.obj"), aiProcess_Triangulate);
  ASSERT_NE(scene, nullptr) << importer.GetErrorString();
  Assimp::Exporter exporter;
  ASSERT_EQ(exporter.Export(scene, "3ds", t.file("cube.3ds")), aiReturn_SUCCESS) << exporter.GetErrorString();
  const SurfaceMesh s = load_surface(t.file("cube.3ds"), parse_unit("mm"));
  expect_cube(s, 7e-3);
}

TEST(LoadSurface, NodeTransformsApplied) {
  // Two OBJ groups become two meshes; both land in one welded surface. A
  // scene exported with a scaled root node comes back with the scale applied.
  TempDir t;
  write_text(t.file("cube.obj"), cube_obj(1.0));
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile(t.file("cube.obj"), aiProcess_Triangulate);
  ASSERT_NE(scene, nullptr);
  aiScene* copy = nullptr;
  aiCopyScene(scene, &copy);
  ASSERT_NE(copy, nullptr);
  aiMatrix4x4::Scaling(aiVector3D(2, 3, 4), copy->mRootNode->mTransformation);
  Assimp::Exporter exporter;
  ASSERT_EQ(exporter.Export(copy, "collada", t.file("scaled.dae")), aiReturn_SUCCESS) << exporter.GetErrorString();
  aiFreeScene(copy);
  const SurfaceMesh s = load_surface(t.file("scaled.dae"), 1.0);
  EXPECT_EQ(s.n_vertices(), 8);
  EXPECT_EQ(s.n_triangles(), 12);
  auto e = extents(s);
  std::sort(e.begin(), e.end());
  EXPECT_NEAR(e[0], 2.0, 1e-6);
  EXPECT_NEAR(e[1], 3.0, 1e-6);
  EXPECT_NEAR(e[2], 4.0, 1e-6);
}

TEST(LoadSurface, MissingFileNamesPath) {
  const std::string path = (fs::temp_directory_path() / "tissue_no_such_surface.stl").string();
  try {
    load_surface(path, 1.0);
    FAIL() << "expected MeshError";
  } catch (const MeshError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

TEST(LoadSurface, GarbageFileNamesPathAndReason) {
  TempDir t;
  write_text(t.file("junk.stl"), "solid x\n facet normal 0 0 0\n  outer loop\n   vertex 1 2\n");
  try {
    load_surface(t.file("junk.stl"), 1.0);
    FAIL() << "expected MeshError";
  } catch (const MeshError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(t.file("junk.stl")), std::string::npos) << msg;
    EXPECT_NE(msg.find("Cannot parse"), std::string::npos) << "carries Assimp's reason: " << msg;
  }
}

TEST(LoadSurface, PlyWithoutEndHeaderIsRefusedNotHung) {
  // Assimp 5.2 loops forever on this file; load_surface refuses it first.
  TempDir t;
  write_text(t.file("cut.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n");
  try {
    load_surface(t.file("cut.ply"), 1.0);
    FAIL() << "expected MeshError";
  } catch (const MeshError& e) {
    EXPECT_NE(std::string(e.what()).find("end_header"), std::string::npos) << e.what();
  }
}

TEST(LoadSurface, NoTrianglesNamesPath) {
  TempDir t;
  write_text(t.file("points.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\n");
  try {
    load_surface(t.file("points.obj"), 1.0);
    FAIL() << "expected MeshError";
  } catch (const MeshError& e) {
    EXPECT_NE(std::string(e.what()).find(t.file("points.obj")), std::string::npos) << e.what();
  }
}

TEST(LoadSurface, BadUnitScale) {
  EXPECT_THROW(load_surface("x.obj", 0.0), MeshError);
  EXPECT_THROW(load_surface("x.obj", -1.0), MeshError);
}

TEST(WeldVertices, MergesWithinToleranceAndDropsCollapsed) {
  SurfaceMesh s;
  s.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1e-12, 0, 0, 1, 1e-12, 0, 5, 5, 5};
  s.triangles = {0, 1, 2, 3, 4, 2, 0, 3, 1};  // second = first after welding, third collapses
  const index_t dropped = weld_vertices(s, 1e-9);
  EXPECT_EQ(dropped, 1);
  EXPECT_EQ(s.n_vertices(), 3);  // vertex 5 was unused
  ASSERT_EQ(s.n_triangles(), 2);
  EXPECT_EQ(s.triangles[3], s.triangles[0]);
  EXPECT_EQ(s.triangles[4], s.triangles[1]);
}

namespace {

SurfaceMesh cube_surface() {
  SurfaceMesh s;
  for (int v = 0; v < 8; ++v)
    for (int a = 0; a < 3; ++a) s.vertices.push_back(corner(v, a, 1.0));
  for (const auto& t : cube_triangles()) s.triangles.insert(s.triangles.end(), t.begin(), t.end());
  return s;
}

std::string closed_error(const SurfaceMesh& s) {
  try {
    check_closed(s, "surf.obj");
  } catch (const MeshError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(CheckClosed, OpenSurfaceNamesEdge) {
  SurfaceMesh s = cube_surface();
  // remove the triangle (4, 5, 7) of the +z face: edges (4, 5) and (5, 7) are left with one triangle
  s.triangles.erase(s.triangles.end() - 6, s.triangles.end() - 3);
  const std::string msg = closed_error(s);
  EXPECT_NE(msg.find("surf.obj"), std::string::npos) << msg;
  EXPECT_NE(msg.find("is used by 1 triangle"), std::string::npos) << msg;
  EXPECT_NE(msg.find("the surface is open"), std::string::npos) << msg;
  EXPECT_TRUE(msg.find("edge (4, 5)") != std::string::npos || msg.find("edge (5, 7)") != std::string::npos ||
              msg.find("edge (4, 7)") != std::string::npos)
      << msg;
}

TEST(CheckClosed, ClosedCubePasses) {
  EXPECT_EQ(closed_error(cube_surface()), "");
}

TEST(CheckClosed, FlippedTriangleIsInconsistent) {
  SurfaceMesh s = cube_surface();
  std::swap(s.triangles[0], s.triangles[1]);
  const std::string msg = closed_error(s);
  EXPECT_NE(msg.find("same direction"), std::string::npos) << msg;
}

TEST(CheckClosed, DegenerateTriangles) {
  SurfaceMesh s = cube_surface();
  s.triangles[2] = s.triangles[0];
  EXPECT_NE(closed_error(s).find("repeats a vertex"), std::string::npos);
  SurfaceMesh z = cube_surface();
  // move corner 6 to the midpoint of corners 0 and 4: triangle (0, 4, 6) becomes a segment
  z.vertices[3 * 6 + 0] = 0.0;
  z.vertices[3 * 6 + 1] = 0.0;
  z.vertices[3 * 6 + 2] = 0.5;
  EXPECT_NE(closed_error(z).find("zero area"), std::string::npos) << closed_error(z);
}

TEST(CheckClosed, NonManifoldEdge) {
  SurfaceMesh s = cube_surface();
  s.triangles.insert(s.triangles.end(), {0, 1, 7});
  const std::string msg = closed_error(s);
  EXPECT_TRUE(msg.find("not a manifold") != std::string::npos) << msg;
}

TEST(CheckClosed, OutOfRangeCorner) {
  SurfaceMesh s = cube_surface();
  s.triangles[5] = 99;
  EXPECT_NE(closed_error(s).find("refers to vertex 99"), std::string::npos);
}

/// The message of the MeshError that loading `path` throws ("" if none).
std::string load_error(const std::string& path) {
  try {
    load_surface(path, 1.0);
  } catch (const MeshError& e) {
    return e.what();
  }
  return "";
}

// Fuzzing's findings (docs/reliability.md, "Findings in surface import"),
// each on an input written here.
TEST(LoadSurface, PlyMagicInAnyCaseWithoutEndHeaderIsRefused) {
  TempDir t;
  for (const char* magic : {"PLY", "plY"}) {  // Assimp hangs on these: refused at the magic line
    write_text(t.file("h.ply"), std::string(magic) + "\nformat ascii 1.0\nelement vertex 3\nproperty float x\n");
    EXPECT_NE(load_error(t.file("h.ply")).find(":1: the PLY magic line is"), std::string::npos) << magic;
  }
  write_text(t.file("h.ply"), "  ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n");
  EXPECT_NE(load_error(t.file("h.ply")).find("no end_header"), std::string::npos);
  write_text(t.file("h.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nEnd_header\n0\n1\n2\n");
  EXPECT_NE(load_error(t.file("h.ply")).find(":5: PLY header line 'End_header'"), std::string::npos);
  // found by fuzzing: Assimp 5.2 hangs on an end_header line with more on it
  write_text(t.file("junk.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_headerex 4\n0\n1\n2\n");
  EXPECT_NE(load_error(t.file("junk.ply")).find(":5: PLY header line 'end_headerex 4'"), std::string::npos)
      << load_error(t.file("junk.ply"));
}

TEST(LoadSurface, HeaderCountsBeyondTheFileAreRefusedBeforeAllocating) {
  TempDir t;
  write_text(t.file("big.off"), "OFF\n4000000000 4 6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n");
  std::string msg = load_error(t.file("big.off"));
  EXPECT_NE(msg.find(t.file("big.off") + ":2:"), std::string::npos) << msg;  // file and line
  EXPECT_NE(msg.find("4000000000 vertices"), std::string::npos) << msg;
  write_text(t.file("huge.off"), "OFF\n" + std::string(80, '4') + " 4 6\n0 0 0\n");
  msg = load_error(t.file("huge.off"));
  EXPECT_NE(msg.find("cannot hold them"), std::string::npos) << msg;
  // found by fuzzing (2026-11-25): a vertex count alone on its line, the face count missing; Assimp took 3 GB
  write_text(t.file("alone.off"), "OFF\n" + std::string(86, '7') + "3\n3 0\n3 2\n3 1 2\n");
  msg = load_error(t.file("alone.off"));
  EXPECT_NE(msg.find(t.file("alone.off") + ":2:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("cannot hold them"), std::string::npos) << msg;
  // found by fuzzing (2026-11-25): a .off file without the OFF keyword, its counts on the first line
  write_text(t.file("bare.off"), std::string(50, '7') + " 4 6\n0 0 0\n1 0 0\n0 1 0\n");
  msg = load_error(t.file("bare.off"));
  EXPECT_NE(msg.find(t.file("bare.off") + ":1:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("cannot hold them"), std::string::npos) << msg;
  // found by fuzzing (2026-11-25): the face count on the line after the vertex count
  write_text(t.file("split.off"), "6\n0" + std::string(70, '7') + " 4 1 3\n3 0\n3 2\n");
  msg = load_error(t.file("split.off"));
  EXPECT_NE(msg.find("cannot hold them"), std::string::npos) << msg;
  write_text(t.file("alone-small.off"), "OFF\n900000\n0 0 0\n");
  msg = load_error(t.file("alone-small.off"));
  EXPECT_NE(msg.find("900000 vertices and 0 faces"), std::string::npos) << msg;
  write_text(t.file("big.ply"), "ply\nformat ascii 1.0\nelement vertex 3000000000\nproperty float x\n"
                                "property float y\nproperty float z\nend_header\n0 0 0\n");
  msg = load_error(t.file("big.ply"));
  EXPECT_NE(msg.find(t.file("big.ply") + ":3:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("3000000000 vertex elements"), std::string::npos) << msg;
}

TEST(LoadSurface, PolygonsAreFannedAndBadFaceListsRefusedWithoutAborting) {
  TempDir t;
  // a quad and a pentagon: 2 + 3 triangles (Assimp's Triangulate is not used: it aborts on malformed lists)
  write_text(t.file("poly.off"), "OFF\n6 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 1.5 0\n-0.5 0.5 0\n"
                                 "4 0 1 2 3\n5 0 1 2 4 5\n");
  const SurfaceMesh s = load_surface(t.file("poly.off"), 1.0);
  EXPECT_EQ(s.n_triangles(), 5);
  // a face naming a vertex that does not exist: an error, not a crash
  write_text(t.file("bad.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                "end_header\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2 9\n");
  EXPECT_FALSE(load_error(t.file("bad.ply")).empty());
}

TEST(LoadSurface, NonFiniteVerticesAreRefusedNamingTheVertex) {
  TempDir t;
  write_text(t.file("nan.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 nan 0\nf 1 2 3\nf 1 2 4\n");
  const std::string msg = load_error(t.file("nan.obj"));
  EXPECT_NE(msg.find("vertex 3"), std::string::npos) << msg;
  EXPECT_NE(msg.find("not finite"), std::string::npos) << msg;
  SurfaceMesh s;
  s.vertices = {0, 0, 0, 1, 0, 0, 0, std::nan(""), 0};
  s.triangles = {0, 1, 2};
  EXPECT_THROW(weld_vertices(s), MeshError);
}

TEST(WeldVertices, FarFromTheOriginAndTinyTolerancesStayDefined) {
  // cell indices counted from the box's corner: a mesh 1e12 m from the origin welds like one at it
  SurfaceMesh s;
  s.vertices = {1e12, 1e12, 1e12, 1e12 + 1, 1e12, 1e12, 1e12, 1e12 + 1, 1e12, 1e12, 1e12, 1e12};
  s.triangles = {0, 1, 2, 3, 1, 2};
  EXPECT_EQ(weld_vertices(s, 1e-3), 0);
  EXPECT_EQ(s.n_vertices(), 3);  // vertex 3 merged into vertex 0
  SurfaceMesh u;
  u.vertices = {0, 0, 0, 1e300, 0, 0, 0, 1, 0, 0, 0, 0};
  u.triangles = {0, 1, 2, 3, 1, 2};
  EXPECT_EQ(weld_vertices(u, 1e-300), 0);  // cells beyond the integers: exact duplicates only
  EXPECT_EQ(u.n_vertices(), 3);
}
