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

std::vector<std::string_view> split_commas(std::string_view text) {
  std::vector<std::string_view> out;
  size_t i = 0;
  for (size_t j; (j = text.find(',', i)) != std::string_view::npos; i = j + 1)
    out.push_back(scene::trim(text.substr(i, j - i)));
  out.push_back(scene::trim(text.substr(i)));
  return out;
}

bool skipped(std::string_view line) {
  const std::string_view t = scene::trim(line);
  return t.empty() || t.front() == '#';
}

Waypoint parse_row(std::string_view text, const std::string& source, int line) {
  const auto f = split_commas(text);
  if (f.size() != 4) fail(source, line, fmt::format("{} fields; expected 4: t,x,y,z", f.size()));
  double v[4];
  for (int k = 0; k < 4; ++k) {
    const auto r = scene::parse_real(f[k]);
    if (!r) fail(source, line, fmt::format("{} '{}' is not a number", "txyz"[k], f[k]));
    if (!std::isfinite(*r)) fail(source, line, fmt::format("{} = {} is not a finite number", "txyz"[k], *r));
    v[k] = *r;
  }
  return {v[0], {v[1], v[2], v[3]}};
}

}  // namespace

std::vector<Waypoint> parse_path_csv(std::istream& in, const std::string& source) {
  std::string text;
  int line = 0;
  bool have_header = false;
  std::vector<Waypoint> path;
  while (std::getline(in, text)) {
    ++line;
    if (skipped(text)) continue;
    if (!have_header) {
      const auto f = split_commas(text);
      if (f != std::vector<std::string_view>{"t", "x", "y", "z"})
        fail(source, line, fmt::format("header is '{}'; expected 't,x,y,z' (s, m)", scene::trim(text)));
      have_header = true;
      continue;
    }
    const Waypoint w = parse_row(text, source, line);
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
  std::string text = "t,x,y,z\n";
  for (const Waypoint& w : waypoints) text += fmt::format("{},{},{},{}\n", w.t, w.p.x, w.p.y, w.p.z);
  try {
    write_file_atomic(path, text);
  } catch (const std::runtime_error& e) {
    throw PathCsvError(e.what());
  }
}

}  // namespace tissue::io
