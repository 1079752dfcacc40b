#include "io/path_csv.hpp"

#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <istream>

#include "io/atomic_file.hpp"
#include "scene/text.hpp"

namespace tissue::io {
namespace {

[[noreturn]] void fail(const std::string& source, int line, const std::string& what) {
  throw PathCsvError(fmt::format("{}:{}: {}", source, line, what));
}

using scene::split_commas;

/// Column layout from the header: t,x,y,z first, then optionally grasp and
/// ax,ay,az (together), in any order.
struct Columns {
  std::size_t count = 4;
  int grasp = -1, axis[3] = {-1, -1, -1};
};

Columns parse_header(std::string_view text, const std::string& source, int line) {
  const auto f = split_commas(text);
  const std::string expected = "expected 't,x,y,z' (s, m), optionally followed by 'grasp' and 'ax,ay,az'";
  if (f.size() < 4 || f[0] != "t" || f[1] != "x" || f[2] != "y" || f[3] != "z")
    fail(source, line, fmt::format("header is '{}'; {}", scene::trim(text), expected));
  Columns c;
  c.count = f.size();
  for (std::size_t k = 4; k < f.size(); ++k) {
    int* slot = f[k] == "grasp" ? &c.grasp
                : f[k] == "ax"  ? &c.axis[0]
                : f[k] == "ay"  ? &c.axis[1]
                : f[k] == "az"  ? &c.axis[2]
                                : nullptr;
    if (slot == nullptr) fail(source, line, fmt::format("unknown column '{}'; {}", f[k], expected));
    if (*slot >= 0) fail(source, line, fmt::format("column '{}' appears twice", f[k]));
    *slot = static_cast<int>(k);
  }
  const int axes = (c.axis[0] >= 0) + (c.axis[1] >= 0) + (c.axis[2] >= 0);
  if (axes != 0 && axes != 3) fail(source, line, "give all three axis columns ax,ay,az or none");
  return c;
}

Waypoint parse_row(std::string_view text, const Columns& cols, const std::string& source, int line) {
  const auto f = split_commas(text);
  if (f.size() != cols.count)
    fail(source, line, fmt::format("{} fields; the header has {}", f.size(), cols.count));
  const auto number = [&](std::size_t k, std::string_view name) {
    const auto r = scene::parse_real(f[k]);
    if (!r) fail(source, line, fmt::format("{} '{}' is not a number", name, f[k]));
    if (!std::isfinite(*r)) fail(source, line, fmt::format("{} = {} is not a finite number", name, *r));
    return *r;
  };
  Waypoint w{number(0, "t"), {number(1, "x"), number(2, "y"), number(3, "z")}};
  if (cols.grasp >= 0) {
    const std::string_view g = f[cols.grasp];
    if (g != "0" && g != "1") fail(source, line, fmt::format("grasp '{}' must be 0 or 1 (the grasp button)", g));
    w.grasp = g == "1";
  }
  if (cols.axis[0] >= 0) {
    w.axis = {number(cols.axis[0], "ax"), number(cols.axis[1], "ay"), number(cols.axis[2], "az")};  // 0,0,0: none
  }
  return w;
}

}  // namespace

std::vector<Waypoint> parse_path_csv(std::istream& in, const std::string& source) {
  std::string text;
  int line = 0;
  bool have_header = false;
  Columns cols;
  std::vector<Waypoint> path;
  while (std::getline(in, text)) {
    ++line;
    if (const auto at = scene::binary_byte(text))
      fail(source, line,
           scene::binary_line_message("the file", line, text, *at) +
               "; a tool path is a text CSV with the header t,x,y,z and one waypoint a row");
    if (scene::csv_skipped(text)) continue;
    if (!have_header) {
      cols = parse_header(text, source, line);
      have_header = true;
      continue;
    }
    const Waypoint w = parse_row(text, cols, source, line);
    if (!path.empty() && !(w.t > path.back().t))  // (parse_row has refused NaN)
      fail(source, line,
           fmt::format("t = {} s is not after the previous waypoint's t = {} s; times must increase", w.t,
                       path.back().t));
    path.push_back(w);
  }
  if (!have_header) fail(source, line, "the file is empty; expected the header 't,x,y,z' and waypoints");
  if (path.empty()) fail(source, line, "no waypoints after the header; a path needs at least one");
  return path;
}

std::vector<Waypoint> read_path_csv(const std::string& path) {
  if (const std::string why = not_a_file(path); !why.empty()) throw PathCsvError(path + ": " + why + ", not a path CSV file");
  std::ifstream in(path);
  if (!in) throw PathCsvError(path + ": cannot open the file");
  return parse_path_csv(in, path);
}

void write_path_csv(const std::string& path, std::span<const Waypoint> waypoints) {
  bool grasp = false, axis = false;
  for (const Waypoint& w : waypoints) {
    grasp = grasp || w.grasp;
    axis = axis || norm(w.axis) > 0;
  }
  std::string text = fmt::format("t,x,y,z{}{}\n", grasp ? ",grasp" : "", axis ? ",ax,ay,az" : "");
  for (const Waypoint& w : waypoints) {
    text += fmt::format("{},{},{},{}", w.t, w.p.x, w.p.y, w.p.z);
    if (grasp) text += w.grasp ? ",1" : ",0";
    if (axis) text += fmt::format(",{},{},{}", w.axis.x, w.axis.y, w.axis.z);
    text += '\n';
  }
  try {
    write_file_atomic(path, text);
  } catch (const std::runtime_error& e) {
    throw PathCsvError(e.what());
  }
}

}  // namespace tissue::io
