// TetGen's .node/.ele text pair (the files `tetgen` writes and reads):
//   x.node: "<n points> 3 <n attributes> <0|1 boundary marker>", then per point
//           "<id> <x> <y> <z> [attributes...] [marker]";
//   x.ele:  "<n tets> 4 <n attributes>", then per tet "<id> <n0> <n1> <n2> <n3> [attributes...]".
// '#' starts a comment to the end of the line; blank lines are skipped. Ids
// start at 0 or 1 (TetGen's -z switch): the first point's id decides, ids must
// then be consecutive, and the .ele corners use the same base. Attributes and
// boundary markers are read past and ignored. Only linear (4-node) tets are
// accepted. Coordinates are taken as metres. Every error names file:line.
// Header counts are checked before anything is allocated for them: a count
// that the rest of the file cannot hold (each record is a line of at least
// two characters per field) or that 32-bit ids cannot number is refused.
#pragma once

#include <iosfwd>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/hd.hpp"

namespace tissue::io {

/// A malformed .node/.ele file; the message starts with "<file>:<line>: ".
struct TetgenFileError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// The contents of a .node/.ele pair, renumbered from 0.
struct TetgenFiles {
  std::vector<double> nodes;  ///< (n_nodes x 3) m, xyz interleaved
  std::vector<index_t> tets;  ///< (n_elems x 4) node ids from 0
  int first_index = 0;        ///< 0 or 1: the numbering the files used
};

/// Parses .node text; returns the coordinates (n_nodes x 3) and sets
/// `first_index` to the first point's id (0 or 1). `source` names the text in errors.
std::vector<double> parse_tetgen_node(std::istream& in, const std::string& source, int& first_index);

/// Parses .ele text whose corner ids count from `first_index` and must lie in
/// [first_index, first_index + n_nodes); returns 0-based corners (n_elems x 4).
std::vector<index_t> parse_tetgen_ele(std::istream& in, const std::string& source, index_t n_nodes, int first_index);

/// The .ele path that pairs with a .node path ("dir/x.node" -> "dir/x.ele").
/// Throws TetgenFileError if node_path does not end in ".node".
std::string ele_path_for(const std::string& node_path);

/// Reads node_path and its .ele partner (ele_path_for).
TetgenFiles read_tetgen(const std::string& node_path);

/// Writes node_path and its .ele partner, ids from 0, coordinates with
/// round-trip precision. nodes: (n_nodes x 3) m; tets: (n_elems x 4).
void write_tetgen(const std::string& node_path, std::span<const double> nodes, std::span<const index_t> tets);

}  // namespace tissue::io
