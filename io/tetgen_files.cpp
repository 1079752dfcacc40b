#include "io/tetgen_files.hpp"

#include <fmt/format.h>

#include <filesystem>
#include <fstream>
#include <istream>
#include <iterator>
#include <limits>

#include "io/atomic_file.hpp"
#include "scene/text.hpp"

namespace tissue::io {
namespace {

[[noreturn]] void fail(const std::string& source, int line, const std::string& what) {
  throw TetgenFileError(fmt::format("{}:{}: {}", source, line, what));
}

/// Yields the blank-separated tokens of each line that has any once '#'
/// comments are cut, with its 1-based line number. The views stay valid
/// until the next call.
class DataLines {
 public:
  DataLines(std::istream& in, std::string source) : in_(in), source_(std::move(source)) {}

  bool next(std::vector<std::string_view>& tokens) {
    while (std::getline(in_, text_)) {
      ++line_;
      const size_t hash = text_.find('#');
      tokens = scene::split_blanks(std::string_view(text_).substr(0, hash));
      if (!tokens.empty()) return true;
    }
    return false;
  }
  int line() const { return line_; }
  /// Characters left in the stream after the current line; -1 when the
  /// stream cannot tell (not seekable).
  long long remaining() {
    const std::istream::pos_type here = in_.tellg();
    if (here == std::istream::pos_type(-1)) {
      in_.clear();
      return -1;
    }
    in_.seekg(0, std::ios::end);
    const std::istream::pos_type end = in_.tellg();
    in_.seekg(here);
    if (end == std::istream::pos_type(-1) || !in_) {
      in_.clear();
      in_.seekg(here);
      return -1;
    }
    return static_cast<long long>(end - here);
  }
  const std::string& source() const { return source_; }

 private:
  std::istream& in_;
  std::string source_;
  std::string text_;
  int line_ = 0;
};

long long integer_field(const DataLines& r, std::string_view token, std::string_view what) {
  const auto v = scene::parse_integer(token);
  if (!v) fail(r.source(), r.line(), fmt::format("{} '{}' is not a whole number", what, token));
  return *v;
}

double real_field(const DataLines& r, std::string_view token, std::string_view what) {
  const auto v = scene::parse_real(token);
  if (!v) fail(r.source(), r.line(), fmt::format("{} '{}' is not a number", what, token));
  return *v;
}

/// Reads a header line and returns its integer fields (count must be `n`).
std::vector<long long> header(DataLines& r, size_t n, std::string_view layout) {
  std::vector<std::string_view> tok;
  if (!r.next(tok)) fail(r.source(), r.line(), fmt::format("the file is empty; expected the header '{}'", layout));
  if (tok.size() != n)
    fail(r.source(), r.line(), fmt::format("header has {} fields; expected {}: '{}'", tok.size(), n, layout));
  std::vector<long long> v;
  for (size_t k = 0; k < n; ++k) {
    v.push_back(integer_field(r, tok[k], fmt::format("header field {}", k + 1)));
    if (v.back() < 0) fail(r.source(), r.line(), fmt::format("header field {} = {} must be >= 0", k + 1, v.back()));
    if (v.back() > (1LL << 40))  // keeps the field-count sums below from overflowing
      fail(r.source(), r.line(), fmt::format("header field {} = {} is beyond any real mesh", k + 1, v.back()));
  }
  return v;
}

/// Counts up to this are read as they come (the reserve is capped at it).
constexpr long long kPlainCount = 1 << 20;

/// Refuses a header whose record count or field count cannot be true, before
/// anything is allocated for it: more records than index_t can number, or
/// -- for claims beyond kPlainCount, which the readers would reserve room
/// for -- more than the rest of the file can hold (a record is at least one
/// line of `fields` numbers, 2 characters each: a digit and a blank).
/// Smaller shortfalls are reported where the file ends, with that line.
void check_counts(DataLines& r, long long count, long long fields, std::string_view what, std::string_view whats) {
  constexpr long long kMaxIds = std::numeric_limits<index_t>::max();
  if (count > kMaxIds)
    fail(r.source(), r.line(),
         fmt::format("the header declares {} {}; at most {} fit tissue's 32-bit ids", count, whats, kMaxIds));
  const long long left = r.remaining();
  if (left < 0) return;
  const long long fit = (left + 1) / 2;  // the last line may lack its newline
  if (fields > fit && fields > kPlainCount)
    fail(r.source(), r.line(),
         fmt::format("the header declares {} fields per {} line, but the rest of the file holds only {} characters",
                     fields, what, left));
  if (count > fit / fields && count > kPlainCount)
    fail(r.source(), r.line(),
         fmt::format("the header declares {} {}, but the rest of the file holds only {} characters: at most {} "
                     "lines of {} fields fit (is the file truncated, or the count wrong?)",
                     count, whats, left, fit / fields, fields));
}

/// Checks the id of the k-th record (0-based) and returns the numbering base.
int check_id(const DataLines& r, std::string_view token, long long k, int first, std::string_view what) {
  const long long id = integer_field(r, token, fmt::format("{} id", what));
  if (k == 0) {
    if (id != 0 && id != 1) fail(r.source(), r.line(), fmt::format("first {} id is {}; ids start at 0 or 1", what, id));
    return int(id);
  }
  if (id != first + k)
    fail(r.source(), r.line(),
         fmt::format("{} id {} breaks the numbering; expected {} (ids are consecutive)", what, id, first + k));
  return first;
}

/// After the declared records: any further data is an error.
void expect_end(DataLines& r, long long n, std::string_view what) {
  std::vector<std::string_view> tok;
  if (r.next(tok)) fail(r.source(), r.line(), fmt::format("more {}s than the {} the header declares", what, n));
}

}  // namespace

std::vector<double> parse_tetgen_node(std::istream& in, const std::string& source, int& first_index) {
  DataLines r(in, source);
  const auto h = header(r, 4, "<points> 3 <attributes> <0|1 boundary markers>");
  if (h[0] == 0) fail(source, r.line(), "the header declares 0 points");
  if (h[1] != 3) fail(source, r.line(), fmt::format("dimension is {}; only 3-D meshes are supported", h[1]));
  if (h[3] > 1) fail(source, r.line(), fmt::format("boundary marker flag is {}; expected 0 or 1", h[3]));
  check_counts(r, h[0], 4 + h[2] + h[3], "point", "points");
  const size_t fields = 4 + h[2] + h[3];
  std::vector<double> xyz;
  xyz.reserve(3 * size_t(std::min(h[0], kPlainCount)));  // grows past that with the data actually read
  std::vector<std::string_view> tok;
  first_index = 0;
  for (long long k = 0; k < h[0]; ++k) {
    if (!r.next(tok))
      fail(source, r.line(), fmt::format("the file ends after {} of the {} points its header declares", k, h[0]));
    if (tok.size() != fields)
      fail(source, r.line(),
           fmt::format("point line has {} fields; expected {} (id x y z, {} attributes, {} marker)", tok.size(), fields,
                       h[2], h[3]));
    first_index = check_id(r, tok[0], k, first_index, "point");
    for (int c = 0; c < 3; ++c) xyz.push_back(real_field(r, tok[1 + c], fmt::format("{} coordinate", "xyz"[c])));
  }
  expect_end(r, h[0], "point");
  return xyz;
}

std::vector<index_t> parse_tetgen_ele(std::istream& in, const std::string& source, index_t n_nodes, int first_index) {
  DataLines r(in, source);
  const auto h = header(r, 3, "<tetrahedra> 4 <attributes>");
  if (h[0] == 0) fail(source, r.line(), "the header declares 0 tetrahedra");
  if (h[1] != 4)
    fail(source, r.line(), fmt::format("{} nodes per tetrahedron; only linear 4-node tets are supported", h[1]));
  check_counts(r, h[0], 5 + h[2], "tetrahedron", "tetrahedra");
  const size_t fields = 5 + h[2];
  std::vector<index_t> tets;
  tets.reserve(4 * size_t(std::min(h[0], kPlainCount)));
  std::vector<std::string_view> tok;
  int base = first_index;
  for (long long k = 0; k < h[0]; ++k) {
    if (!r.next(tok))
      fail(source, r.line(), fmt::format("the file ends after {} of the {} tetrahedra its header declares", k, h[0]));
    if (tok.size() != fields)
      fail(source, r.line(),
           fmt::format("tetrahedron line has {} fields; expected {} (id, 4 corners, {} attributes)", tok.size(), fields,
                       h[2]));
    base = check_id(r, tok[0], k, base, "tetrahedron");
    for (int a = 0; a < 4; ++a) {
      const long long v = integer_field(r, tok[1 + a], fmt::format("corner {}", a));
      if (v < first_index || v >= first_index + (long long)n_nodes)
        fail(source, r.line(),
             fmt::format("corner {} refers to point {}, but the points are numbered {}..{}", a, v, first_index,
                         first_index + (long long)n_nodes - 1));
      tets.push_back(static_cast<index_t>(v - first_index));
    }
  }
  expect_end(r, h[0], "tetrahedron");
  return tets;
}

std::string ele_path_for(const std::string& node_path) {
  static const std::string kExt = ".node";
  if (node_path.size() <= kExt.size() || node_path.compare(node_path.size() - kExt.size(), kExt.size(), kExt) != 0)
    throw TetgenFileError(
        fmt::format("{}: a TetGen mesh is named by its .node file (x.node, with x.ele beside it)", node_path));
  return node_path.substr(0, node_path.size() - kExt.size()) + ".ele";
}

TetgenFiles read_tetgen(const std::string& node_path) {
  const std::string ele_path = ele_path_for(node_path);
  for (const std::string& p : {node_path, ele_path})
    if (const std::string why = not_a_file(p); !why.empty()) throw TetgenFileError(p + ": " + why + ", not a TetGen file");
  std::ifstream node_in(node_path), ele_in(ele_path);
  if (!node_in) throw TetgenFileError(node_path + ": cannot open the file");
  if (!ele_in) throw TetgenFileError(ele_path + ": cannot open the file (the .ele partner of " + node_path + ")");
  TetgenFiles out;
  out.nodes = parse_tetgen_node(node_in, node_path, out.first_index);
  out.tets = parse_tetgen_ele(ele_in, ele_path, static_cast<index_t>(out.nodes.size() / 3), out.first_index);
  return out;
}

void write_tetgen(const std::string& node_path, std::span<const double> nodes, std::span<const index_t> tets) {
  const std::string ele_path = ele_path_for(node_path);
  const size_t n = nodes.size() / 3, ne = tets.size() / 4;
  fmt::memory_buffer node_text, ele_text;
  fmt::format_to(std::back_inserter(node_text), "# {} points (m), written by tissue\n{} 3 0 0\n", n, n);
  for (size_t i = 0; i < n; ++i)
    fmt::format_to(std::back_inserter(node_text), "{} {} {} {}\n", i, nodes[3 * i], nodes[3 * i + 1], nodes[3 * i + 2]);
  fmt::format_to(std::back_inserter(ele_text), "# {} linear tetrahedra, written by tissue\n{} 4 0\n", ne, ne);
  for (size_t e = 0; e < ne; ++e)
    fmt::format_to(std::back_inserter(ele_text), "{} {} {} {} {}\n", e, tets[4 * e], tets[4 * e + 1], tets[4 * e + 2],
                   tets[4 * e + 3]);
  try {  // each file whole or not at all (io/atomic_file.hpp)
    write_file_atomic(node_path, std::string_view(node_text.data(), node_text.size()));
    write_file_atomic(ele_path, std::string_view(ele_text.data(), ele_text.size()));
  } catch (const std::runtime_error& e) {
    throw TetgenFileError(e.what());
  }
}

}  // namespace tissue::io
