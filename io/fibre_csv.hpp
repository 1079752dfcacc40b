// Fibre directions per element as CSV (<fibre file="dirs.csv">,
// docs/scene-format.md): one row "element,ax,ay,az" per element (0-based
// element ids of the mesh; the direction any length but 0, normalised on
// load), optionally after the header line "element,ax,ay,az". Blank lines
// and lines starting with '#' are skipped; fields may carry surrounding
// blanks. The reader checks the syntax (four fields, whole-number ids,
// finite numbers); the element ids and directions are checked against the
// mesh by scene validation (scene/fibre_field.hpp), citing the row's line.
// Every error names file:line.
#pragma once

#include <iosfwd>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "scene/scene.hpp"

namespace tissue::io {

/// A malformed fibre CSV; the message starts with "<file>:<line>: ".
struct FibreCsvError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Parses fibre CSV text (at least one row), each row with its line. `source`
/// names it in errors.
std::vector<scene::Material::FibreRow> parse_fibre_csv(std::istream& in, const std::string& source);

/// Reads a fibre CSV file.
std::vector<scene::Material::FibreRow> read_fibre_csv(const std::string& path);

/// Writes rows as fibre CSV (with the header) with round-trip precision.
void write_fibre_csv(const std::string& path, std::span<const scene::Material::FibreRow> rows);

}  // namespace tissue::io
