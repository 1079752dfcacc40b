#include "io/vtu_writer.hpp"

#include <fmt/format.h>

#include <filesystem>
#include <sstream>
#include <stdexcept>

#include "io/atomic_file.hpp"

namespace tissue::io {
namespace {

void check_size(const std::string& path, const char* field, size_t got, size_t want) {
  if (got != want)
    throw std::runtime_error(fmt::format("{}: field '{}' has {} values, the model needs {}", path, field, got, want));
}

/// Entries [first, first + count) of a component-major (3 x n) field as
/// interleaved xyz triples.
void write_vec3(std::ostream& out, const std::vector<double>& v, index_t n, index_t first, index_t count) {
  for (index_t i = first; i < first + count; ++i)
    out << fmt::format("{:.9g} {:.9g} {:.9g}\n", v[i], v[n + i], v[2 * size_t(n) + i]);
}

void write_scalars(std::ostream& out, const std::vector<double>& v, index_t first, index_t count) {
  for (index_t i = 0; i < count; ++i)
    out << fmt::format("{:.9g}{}", v[size_t(first + i)], (i % 8 == 7 || i + 1 == count) ? "\n" : " ");
}

/// One output array of core/store.hpp (TISSUE_OUTPUT_ARRAYS) as the file writes it.
struct OutputArray {
  const std::vector<double>* values;
  const char* name;
  Per per;
  int components;
};

std::vector<OutputArray> output_arrays(const Fields& f) {
  return {
#define TISSUE_OUTPUT_ENTRY(member, vtu, field, per, components, unit) {&f.member, vtu, Per::per, components},
      TISSUE_OUTPUT_ARRAYS(TISSUE_OUTPUT_ENTRY)
#undef TISSUE_OUTPUT_ENTRY
  };
}

/// The arrays of `per` as a PointData or CellData section, entries [first,
/// first + count) of n: the first vector and the first scalar are its default
/// Vectors and Scalars. body >= 0 adds an Int32 "body" array holding it.
void write_section(std::ostream& out, const char* section, const std::vector<OutputArray>& arrays, Per per,
                   index_t n, index_t first, index_t count, int body) {
  std::string defaults;
  for (int components : {3, 1})
    for (const OutputArray& a : arrays)
      if (a.per == per && a.components == components) {
        defaults += fmt::format(" {}=\"{}\"", components == 3 ? "Vectors" : "Scalars", a.name);
        break;
      }
  out << "<" << section << defaults << ">\n";
  for (const OutputArray& a : arrays) {
    if (a.per != per) continue;
    out << fmt::format("<DataArray type=\"Float64\" Name=\"{}\"{} format=\"ascii\">\n", a.name,
                       a.components == 3 ? " NumberOfComponents=\"3\"" : "");
    if (a.components == 3)
      write_vec3(out, *a.values, n, first, count);
    else
      write_scalars(out, *a.values, first, count);
    out << "</DataArray>\n";
  }
  if (body >= 0) {
    out << "<DataArray type=\"Int32\" Name=\"body\" format=\"ascii\">\n";
    for (index_t i = 0; i < count; ++i) out << body << ((i % 32 == 31 || i + 1 == count) ? "\n" : " ");
    out << "</DataArray>\n";
  }
  out << "</" << section << ">\n";
}

/// One <Piece>: nodes [first_node, + n_nodes) and the elements [first_element,
/// + n_elements), whose corners lie among those nodes (renumbered from 0).
void write_piece(std::ostream& out, const TissueModel<double>& m, const std::vector<OutputArray>& arrays,
                 const scene::Body& p, int body) {
  const index_t n = m.n_nodes, ne = m.n_elems, e0 = p.first_element, count = p.n_elements;
  out << fmt::format("<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n", p.n_nodes, count);
  out << "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  write_vec3(out, m.X, n, p.first_node, p.n_nodes);
  out << "</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n";
  for (index_t e = e0; e < e0 + count; ++e)
    out << fmt::format("{} {} {} {}\n", m.elem_nodes[e] - p.first_node, m.elem_nodes[size_t(ne) + e] - p.first_node,
                       m.elem_nodes[2 * size_t(ne) + e] - p.first_node, m.elem_nodes[3 * size_t(ne) + e] - p.first_node);
  out << "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n";
  for (index_t e = 0; e < count; ++e) out << 4 * (e + 1) << ((e % 16 == 15 || e + 1 == count) ? "\n" : " ");
  out << "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (index_t e = 0; e < count; ++e) out << "10" << ((e % 32 == 31 || e + 1 == count) ? "\n" : " ");  // VTK_TETRA
  out << "</DataArray>\n</Cells>\n";
  write_section(out, "PointData", arrays, Per::Node, n, p.first_node, p.n_nodes, -1);
  write_section(out, "CellData", arrays, Per::Element, ne, e0, count, body);
  out << "</Piece>\n";
}

}  // namespace

void write_vtu(const std::string& path, const TissueModel<double>& m, const Fields& f,
               std::span<const scene::Body> bodies) {
  const std::vector<OutputArray> arrays = output_arrays(f);
  for (const OutputArray& a : arrays) check_size(path, a.name, a.values->size(), store_entries(a.per, m) * a.components);
  index_t nodes = 0, elems = 0;
  for (const scene::Body& b : bodies) {
    if (b.first_node != nodes || b.first_element != elems)
      throw std::runtime_error(fmt::format("{}: body '{}' does not follow the bodies before it (nodes from {}, "
                                           "elements from {})",
                                           path, b.name, nodes, elems));
    nodes += b.n_nodes;
    elems += b.n_elements;
  }
  if (!bodies.empty() && (nodes != m.n_nodes || elems != m.n_elems))
    throw std::runtime_error(fmt::format("{}: the bodies hold {} nodes and {} elements, the model {} and {}", path,
                                         nodes, elems, m.n_nodes, m.n_elems));
  std::ostringstream out;
  out << "<?xml version=\"1.0\"?>\n"
         "<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
         "<UnstructuredGrid>\n";
  if (bodies.empty()) {
    scene::Body whole;
    whole.n_nodes = m.n_nodes;
    whole.n_elements = m.n_elems;
    write_piece(out, m, arrays, whole, -1);
  }
  for (std::size_t k = 0; k < bodies.size(); ++k) write_piece(out, m, arrays, bodies[k], int(k));
  out << "</UnstructuredGrid>\n</VTKFile>\n";
  write_file_atomic(path, out.str());
}

VtuSeries::VtuSeries(std::string directory, std::vector<scene::Body> bodies)
    : directory_(std::move(directory)), bodies_(std::move(bodies)) {
  std::error_code ec;
  std::filesystem::create_directories(directory_, ec);
  if (ec || !std::filesystem::is_directory(directory_))
    throw std::runtime_error(
        fmt::format("{}: cannot create the output directory: {}", directory_, ec ? ec.message() : "not a directory"));
}

std::string VtuSeries::pvd_path() const {
  return (std::filesystem::path(directory_) / "series.pvd").string();
}

std::string VtuSeries::write(const TissueModel<double>& model, const Fields& fields, double time) {
  if (!times_.empty() && time < times_.back())
    throw std::runtime_error(
        fmt::format("{}: frame time {} s is before the previous frame's {} s", pvd_path(), time, times_.back()));
  const std::string name = fmt::format("frame_{:04d}.vtu", frames());
  const std::string path = (std::filesystem::path(directory_) / name).string();
  write_vtu(path, model, fields, bodies_);
  times_.push_back(time);
  files_.push_back(name);
  write_pvd();
  return path;
}

void VtuSeries::write_pvd() const {
  std::ostringstream out;
  out << "<?xml version=\"1.0\"?>\n"
         "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n<Collection>\n";
  for (size_t k = 0; k < files_.size(); ++k)
    out << fmt::format("<DataSet timestep=\"{:.9g}\" group=\"\" part=\"0\" file=\"{}\"/>\n", times_[k], files_[k]);
  out << "</Collection>\n</VTKFile>\n";
  write_file_atomic(pvd_path(), out.str());
}

}  // namespace tissue::io
