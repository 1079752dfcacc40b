#include "io/fibre_csv.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <istream>
#include <limits>

#include "io/atomic_file.hpp"
#include "scene/text.hpp"

namespace tissue::io {
namespace {

using Row = scene::Material::FibreRow;

[[noreturn]] void fail(const std::string& source, int line, const std::string& what) {
  throw FibreCsvError(fmt::format("{}:{}: {}", source, line, what));
}

using scene::split_commas;

constexpr const char* kColumns = "element,ax,ay,az";

Row parse_row(std::string_view text, const std::string& source, int line) {
  const auto f = split_commas(text);
  if (f.size() != 4)
    fail(source, line,
         fmt::format("{} field{}; a row is {} (0-based element id, fibre direction)", f.size(),
                     f.size() == 1 ? "" : "s", kColumns));
  const auto id = scene::parse_integer(f[0]);
  if (!id) fail(source, line, fmt::format("element '{}' is not an element id (a whole number)", scene::printable(f[0])));
  if (*id < std::numeric_limits<index_t>::min() || *id > std::numeric_limits<index_t>::max())
    fail(source, line, fmt::format("element {} is out of range", *id));
  const auto number = [&](int k, std::string_view name) {
    const auto r = scene::parse_real(f[k]);
    if (!r) fail(source, line, fmt::format("{} '{}' is not a number", name, scene::printable(f[k])));
    if (!std::isfinite(*r)) fail(source, line, fmt::format("{} = {} is not a finite number", name, *r));
    return *r;
  };
  Row row;
  row.element = static_cast<index_t>(*id);
  row.dir = {number(1, "ax"), number(2, "ay"), number(3, "az")};
  row.line = line;
  return row;
}

}  // namespace

std::vector<Row> parse_fibre_csv(std::istream& in, const std::string& source) {
  std::string text;
  int line = 0;
  bool first = true;
  std::vector<Row> rows;
  while (std::getline(in, text)) {
    ++line;
    if (const auto at = scene::binary_byte(text))
      fail(source, line,
           scene::binary_line_message("the file", line, text, *at) +
               fmt::format("; a fibre file is a text CSV of rows {}", kColumns));
    if (scene::csv_skipped(text)) continue;
    if (first) {
      first = false;
      const auto f = split_commas(text);
      if (!scene::parse_real(f[0])) {  // a header (a row starts with a number)
        if (f.size() != 4 || f[0] != "element" || f[1] != "ax" || f[2] != "ay" || f[3] != "az")
          fail(source, line,
               fmt::format("header is '{}'; expected '{}' (or no header: rows start with an element id)",
                           scene::printable(scene::trim(text)), kColumns));
        continue;
      }
    }
    rows.push_back(parse_row(text, source, line));
  }
  if (rows.empty())
    fail(source, std::max(line, 1), fmt::format("no rows; expected one row {} per element", kColumns));
  return rows;
}

std::vector<Row> read_fibre_csv(const std::string& path) {
  if (const std::string why = not_a_file(path); !why.empty())
    throw FibreCsvError(path + ": " + why + ", not a fibre CSV file");
  std::ifstream in(path);
  if (!in) throw FibreCsvError(path + ": cannot open the file");
  return parse_fibre_csv(in, path);
}

void write_fibre_csv(const std::string& path, std::span<const Row> rows) {
  std::string text = std::string(kColumns) + "\n";
  for (const Row& r : rows) text += fmt::format("{},{},{},{}\n", r.element, r.dir.x, r.dir.y, r.dir.z);
  try {
    write_file_atomic(path, text);
  } catch (const std::runtime_error& e) {
    throw FibreCsvError(e.what());
  }
}

}  // namespace tissue::io
