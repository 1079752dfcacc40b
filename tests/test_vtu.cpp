// VTU and CSV output: a small box model with known fields is written, parsed
// back with pugixml and checked for counts, arrays and values; the frame
// series and its .pvd; the tick log's header and rows; errors name the path.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <pugixml.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "core/box_mesh.hpp"
#include "io/csv_log.hpp"
#include "io/vtu_writer.hpp"

namespace fs = std::filesystem;
using tissue::index_t;
using namespace tissue::io;

namespace {

struct TempDir {
  fs::path dir;
  TempDir() {
    dir = fs::temp_directory_path() /
          (std::string("tissue_vtu_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  ~TempDir() { fs::remove_all(dir); }
  std::string file(const std::string& name) const { return (dir / name).string(); }
};

tissue::TissueModel<double> box_model() {
  tissue::ModelInput in;
  tissue::box_mesh(in, 2, 1, 1, 0.02, 0.01, 0.01);
  in.materials = {{1000.0, 10000.0, 1000.0}};
  return tissue::build_model(in);
}

/// Fields with values that identify their node/element and component.
tissue::Fields marked_fields(const tissue::TissueModel<double>& m) {
  tissue::Fields f;
  const index_t n = m.n_nodes;
  f.u.resize(3 * n);
  f.f.resize(3 * n);
  f.node_p.resize(n);
  f.elem_J.resize(m.n_elems);
  for (index_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) {
      f.u[c * n + i] = 1e-3 * i + 1e-5 * c;  // component-major
      f.f[c * n + i] = -0.5 * i + 0.1 * c;
    }
    f.node_p[i] = 10.0 * i;
  }
  for (index_t e = 0; e < m.n_elems; ++e) f.elem_J[e] = 1.0 + 0.01 * e;
  return f;
}

std::vector<double> numbers(const pugi::xml_node& array) {
  std::istringstream in(array.child_value());
  std::vector<double> v;
  double x;
  while (in >> x) v.push_back(x);
  return v;
}

pugi::xml_node named_array(const pugi::xml_node& parent, const char* name) {
  return parent.find_child_by_attribute("DataArray", "Name", name);
}

}  // namespace

TEST(WriteVtu, ParsesWithCountsArraysAndValues) {
  TempDir t;
  const auto m = box_model();
  const auto f = marked_fields(m);
  write_vtu(t.file("box.vtu"), m, f);

  pugi::xml_document doc;
  const pugi::xml_parse_result ok = doc.load_file(t.file("box.vtu").c_str());
  ASSERT_TRUE(ok) << ok.description();
  const auto vtk = doc.child("VTKFile");
  EXPECT_STREQ(vtk.attribute("type").value(), "UnstructuredGrid");
  const auto piece = vtk.child("UnstructuredGrid").child("Piece");
  ASSERT_TRUE(piece);
  EXPECT_EQ(piece.attribute("NumberOfPoints").as_int(), m.n_nodes);
  EXPECT_EQ(piece.attribute("NumberOfCells").as_int(), m.n_elems);

  const auto points = numbers(piece.child("Points").child("DataArray"));
  ASSERT_EQ(points.size(), 3u * m.n_nodes);
  for (index_t i = 0; i < m.n_nodes; ++i)
    for (int c = 0; c < 3; ++c) EXPECT_DOUBLE_EQ(points[3 * i + c], m.X[c * m.n_nodes + i]);

  const auto cells = piece.child("Cells");
  const auto conn = numbers(named_array(cells, "connectivity"));
  ASSERT_EQ(conn.size(), 4u * m.n_elems);
  for (index_t e = 0; e < m.n_elems; ++e)
    for (int a = 0; a < 4; ++a) EXPECT_EQ(conn[4 * e + a], m.elem_nodes[a * m.n_elems + e]);
  const auto offsets = numbers(named_array(cells, "offsets"));
  ASSERT_EQ(offsets.size(), size_t(m.n_elems));
  EXPECT_EQ(offsets.back(), 4.0 * m.n_elems);
  const auto types = numbers(named_array(cells, "types"));
  ASSERT_EQ(types.size(), size_t(m.n_elems));
  for (double ty : types) EXPECT_EQ(ty, 10.0);  // VTK_TETRA

  const auto pd = piece.child("PointData");
  const auto u = named_array(pd, "displacement");
  ASSERT_TRUE(u);
  EXPECT_EQ(u.attribute("NumberOfComponents").as_int(), 3);
  const auto uv = numbers(u);
  ASSERT_EQ(uv.size(), 3u * m.n_nodes);
  EXPECT_DOUBLE_EQ(uv[3 * 5 + 2], 1e-3 * 5 + 2e-5);  // node 5, z: interleaved in the file
  const auto p = numbers(named_array(pd, "nodal_pressure"));
  ASSERT_EQ(p.size(), size_t(m.n_nodes));
  EXPECT_DOUBLE_EQ(p[7], 70.0);
  const auto fi = named_array(pd, "internal_force");
  EXPECT_EQ(fi.attribute("NumberOfComponents").as_int(), 3);
  const auto fv = numbers(fi);
  ASSERT_EQ(fv.size(), 3u * m.n_nodes);
  EXPECT_DOUBLE_EQ(fv[3 * 3 + 1], -1.5 + 0.1);

  const auto J = numbers(named_array(piece.child("CellData"), "J"));
  ASSERT_EQ(J.size(), size_t(m.n_elems));
  EXPECT_DOUBLE_EQ(J[4], 1.04);
}

/// Two boxes as one model: the first box's nodes and elements, then the
/// second's (shifted 5 cm along x), as the reader merges a scene's bodies.
tissue::TissueModel<double> two_box_model(std::vector<tissue::scene::Body>& bodies) {
  tissue::ModelInput in, a, b;
  tissue::box_mesh(a, 2, 1, 1, 0.02, 0.01, 0.01);
  tissue::box_mesh(b, 1, 1, 1, 0.01, 0.01, 0.01);
  for (size_t i = 0; i < b.nodes.size(); i += 3) b.nodes[i] += 0.05;
  in.nodes = a.nodes;
  in.nodes.insert(in.nodes.end(), b.nodes.begin(), b.nodes.end());
  in.tets = a.tets;
  const index_t na = index_t(a.nodes.size() / 3);
  for (index_t v : b.tets) in.tets.push_back(v + na);
  in.materials = {{1000.0, 10000.0, 1000.0}};
  bodies = {{.name = "a", .n_nodes = na, .n_elements = index_t(a.tets.size() / 4)},
            {.name = "b", .first_node = na, .n_nodes = index_t(b.nodes.size() / 3),
             .first_element = index_t(a.tets.size() / 4), .n_elements = index_t(b.tets.size() / 4)}};
  return tissue::build_model(in);
}

// One <Piece> per body, each with its own points, connectivity counted from
// its first node, its part of every field and its "body" index per cell.
TEST(WriteVtu, ABodyIsAPiece) {
  TempDir t;
  std::vector<tissue::scene::Body> bodies;
  const auto m = two_box_model(bodies);
  const auto f = marked_fields(m);
  write_vtu(t.file("two.vtu"), m, f, bodies);
  pugi::xml_document doc;
  ASSERT_TRUE(doc.load_file(t.file("two.vtu").c_str()));
  std::vector<pugi::xml_node> pieces;
  for (pugi::xml_node p : doc.child("VTKFile").child("UnstructuredGrid").children("Piece")) pieces.push_back(p);
  ASSERT_EQ(pieces.size(), 2u);
  for (int k = 0; k < 2; ++k) {
    const tissue::scene::Body& b = bodies[k];
    const pugi::xml_node piece = pieces[k];
    ASSERT_EQ(piece.attribute("NumberOfPoints").as_int(), b.n_nodes);
    ASSERT_EQ(piece.attribute("NumberOfCells").as_int(), b.n_elements);
    const auto points = numbers(piece.child("Points").child("DataArray"));
    ASSERT_EQ(points.size(), 3u * b.n_nodes);
    for (index_t i = 0; i < b.n_nodes; ++i)
      for (int c = 0; c < 3; ++c) EXPECT_DOUBLE_EQ(points[3 * i + c], m.X[c * m.n_nodes + b.first_node + i]);
    const auto conn = numbers(named_array(piece.child("Cells"), "connectivity"));
    ASSERT_EQ(conn.size(), 4u * b.n_elements);
    for (index_t e = 0; e < b.n_elements; ++e)
      for (int a = 0; a < 4; ++a)
        EXPECT_EQ(conn[4 * e + a], m.elem_nodes[a * m.n_elems + b.first_element + e] - b.first_node);
    const auto u = numbers(named_array(piece.child("PointData"), "displacement"));
    ASSERT_EQ(u.size(), 3u * b.n_nodes);
    EXPECT_DOUBLE_EQ(u[3 * 1 + 2], 1e-3 * (b.first_node + 1) + 2e-5);  // its node 1, z
    const auto J = numbers(named_array(piece.child("CellData"), "J"));
    ASSERT_EQ(J.size(), size_t(b.n_elements));
    EXPECT_DOUBLE_EQ(J[0], 1.0 + 0.01 * b.first_element);
    const auto body = numbers(named_array(piece.child("CellData"), "body"));
    ASSERT_EQ(body.size(), size_t(b.n_elements));
    for (double v : body) EXPECT_EQ(v, double(k));
  }
  // bodies that do not tile the model are refused, naming the file
  bodies[1].first_node += 1;
  try {
    write_vtu(t.file("bad.vtu"), m, f, bodies);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("body 'b' does not follow"), std::string::npos) << e.what();
  }
}

TEST(WriteVtu, WrongFieldSizeNamesPathAndField) {
  TempDir t;
  const auto m = box_model();
  auto f = marked_fields(m);
  f.elem_J.pop_back();
  try {
    write_vtu(t.file("bad.vtu"), m, f);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(t.file("bad.vtu")), std::string::npos) << msg;
    EXPECT_NE(msg.find("'J'"), std::string::npos) << msg;
  }
}

TEST(WriteVtu, UnwritablePathNamed) {
  const auto m = box_model();
  const std::string path = (fs::temp_directory_path() / "tissue_no_such_dir" / "x" / "a.vtu").string();
  try {
    write_vtu(path, m, marked_fields(m));
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

TEST(VtuSeries, FramesAndCollection) {
  TempDir t;
  const auto m = box_model();
  const auto f = marked_fields(m);
  VtuSeries series(t.file("out/frames"));
  EXPECT_EQ(series.write(m, f, 0.0), t.file("out/frames/frame_0000.vtu"));
  series.write(m, f, 0.25);
  series.write(m, f, 0.5);
  EXPECT_EQ(series.frames(), 3);
  EXPECT_THROW(series.write(m, f, 0.4), std::runtime_error);  // time going back

  pugi::xml_document doc;
  ASSERT_TRUE(doc.load_file(series.pvd_path().c_str()));
  const auto coll = doc.child("VTKFile").child("Collection");
  EXPECT_STREQ(doc.child("VTKFile").attribute("type").value(), "Collection");
  std::vector<double> times;
  for (const auto& ds : coll.children("DataSet")) {
    times.push_back(ds.attribute("timestep").as_double());
    const fs::path frame = fs::path(t.file("out/frames")) / ds.attribute("file").value();
    EXPECT_TRUE(fs::exists(frame)) << frame;
    pugi::xml_document vtu;
    EXPECT_TRUE(vtu.load_file(frame.c_str())) << frame;
  }
  EXPECT_EQ(times, (std::vector<double>{0.0, 0.25, 0.5}));
}

TEST(TickLog, HeaderAndRows) {
  TempDir t;
  {
    TickLog log(t.file("ticks.csv"));
    tissue::TickReport r;
    r.tick = 7;
    r.time = 0.007;
    r.n_tools = 1;
    r.tools[0].tip = {0.01, 0.02, -0.03};
    r.tools[0].contact_nodes = 42;
    r.tools[0].force = {0.5, -0.25, 1.5};
    r.tools[0].grasp = true;
    r.internal = {1e-6, 0, -2e-6};
    r.region_nodes = 120;
    r.region_elems = 300;
    r.residual = 1e-4;
    r.kinetic = 2e-9;
    r.max_disp = 0.004;
    r.equilibrium = true;
    r.steps = 23;
    r.strain_energy = 3e-6;
    r.kinetic_rel = 0.05;
    r.front_disp = 1e-3;
    r.depth = 6;
    r.visco_power = 2.5e-4;
    r.visco_stored = 1e-7;
    r.dissipated = 3.25e-6;
    log.write(r);
    r.tick = 8;
    r.tools[0].contact_nodes = 0;
    r.tools[0].grasp = false;
    r.equilibrium = false;
    log.write(r);
    EXPECT_EQ(log.rows(), 2);
  }
  std::ifstream in(t.file("ticks.csv"));
  std::string header, row1, row2, extra;
  std::getline(in, header);
  std::getline(in, row1);
  std::getline(in, row2);
  EXPECT_FALSE(std::getline(in, extra));
  EXPECT_EQ(header,
            "tick,time,tool_x,tool_y,tool_z,contact_nodes,force_x,force_y,force_z,grasp,internal_x,internal_y,"
            "internal_z,region_nodes,region_elems,residual,kinetic,max_disp,equilibrium,steps,strain_energy,"
            "kinetic_rel,front_disp,depth,visco_power,visco_stored,dissipated");
  EXPECT_EQ(row1,
            "7,0.007,0.01,0.02,-0.03,42,0.5,-0.25,1.5,1,1e-06,0,-2e-06,120,300,0.0001,2e-09,0.004,1,23,3e-06,0.05,"
            "0.001,6,0.00025,1e-07,3.25e-06");
  EXPECT_EQ(row2.substr(0, 2), "8,");
  EXPECT_NE(row2.find(",-0.03,0,0.5,"), std::string::npos);
  EXPECT_NE(row2.find(",0,23,"), std::string::npos);
  // same number of columns everywhere
  auto cols = [](const std::string& s) { return std::count(s.begin(), s.end(), ','); };
  EXPECT_EQ(cols(row1), cols(header));
  EXPECT_EQ(cols(row2), cols(header));
}

TEST(TickLog, EveryFurtherToolHasItsColumns) {
  TempDir t;
  {
    TickLog log(t.file("ticks.csv"), 2);
    tissue::TickReport r;
    r.n_tools = 2;
    r.tools[1].tip = {1, 2, 3};
    r.tools[1].contact_nodes = 5;
    r.tools[1].force = {0, 0, 0.25};
    r.tools[1].grasp = true;
    log.write(r);
  }
  std::ifstream in(t.file("ticks.csv"));
  std::string header, row;
  std::getline(in, header);
  std::getline(in, row);
  EXPECT_NE(header.find(",dissipated,tool2_x,tool2_y,tool2_z,tool2_contact_nodes,tool2_force_x,tool2_force_y,"
                        "tool2_force_z,tool2_grasp"),
            std::string::npos)
      << header;
  EXPECT_EQ(row.substr(row.size() - 19), ",1,2,3,5,0,0,0.25,1") << row;
  EXPECT_THROW(TickLog(t.file("bad.csv"), 0), std::invalid_argument);
  EXPECT_THROW(TickLog(t.file("bad.csv"), tissue::kMaxTools + 1), std::invalid_argument);
}

TEST(TickLog, UnwritablePathNamed) {
  const std::string path = (fs::temp_directory_path() / "tissue_no_such_dir" / "y" / "ticks.csv").string();
  try {
    TickLog log(path);
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}
