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

/// Writes a component-major (3 x n) field as n interleaved xyz triples.
void write_vec3(std::ostream& out, const std::vector<double>& v, index_t n) {
  for (index_t i = 0; i < n; ++i) out << fmt::format("{:.9g} {:.9g} {:.9g}\n", v[i], v[n + i], v[2 * size_t(n) + i]);
}

void write_scalars(std::ostream& out, const std::vector<double>& v) {
  for (size_t i = 0; i < v.size(); ++i)
    out << fmt::format("{:.9g}{}", v[i], (i % 8 == 7 || i + 1 == v.size()) ? "\n" : " ");
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

/// The arrays of `per` as a PointData or CellData section: the first vector
/// and the first scalar are its default Vectors and Scalars.
void write_section(std::ostream& out, const char* section, const std::vector<OutputArray>& arrays, Per per,
                   index_t n) {
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
      write_vec3(out, *a.values, n);
    else
      write_scalars(out, *a.values);
    out << "</DataArray>\n";
  }
  out << "</" << section << ">\n";
}

}  // namespace

void write_vtu(const std::string& path, const TissueModel<double>& m, const Fields& f) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  const std::vector<OutputArray> arrays = output_arrays(f);
  for (const OutputArray& a : arrays) check_size(path, a.name, a.values->size(), store_entries(a.per, m) * a.components);
  std::ostringstream out;
  out << "<?xml version=\"1.0\"?>\n"
         "<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
         "<UnstructuredGrid>\n";
  out << fmt::format("<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n", n, ne);
  out << "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  write_vec3(out, m.X, n);
  out << "</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n";
  for (index_t e = 0; e < ne; ++e)
    out << fmt::format("{} {} {} {}\n", m.elem_nodes[e], m.elem_nodes[size_t(ne) + e], m.elem_nodes[2 * size_t(ne) + e],
                       m.elem_nodes[3 * size_t(ne) + e]);
  out << "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n";
  for (index_t e = 0; e < ne; ++e) out << 4 * (e + 1) << ((e % 16 == 15 || e + 1 == ne) ? "\n" : " ");
  out << "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (index_t e = 0; e < ne; ++e) out << "10" << ((e % 32 == 31 || e + 1 == ne) ? "\n" : " ");  // VTK_TETRA
  out << "</DataArray>\n</Cells>\n";
  write_section(out, "PointData", arrays, Per::Node, n);
  write_section(out, "CellData", arrays, Per::Element, ne);
  out << "</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
  write_file_atomic(path, out.str());
}

VtuSeries::VtuSeries(std::string directory) : directory_(std::move(directory)) {
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
  write_vtu(path, model, fields);
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
