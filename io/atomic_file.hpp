// Files in and out. Output files that no reader ever sees half-written: the contents go to
// "<path>.part" beside the final name, and a rename(2) -- atomic within one
// file system -- puts the complete file in place. A reader opening <path>
// sees the previous complete version or the new complete one, never a
// truncated file, whether the writer finishes, throws, is interrupted
// (SIGINT, SIGTERM) or crashes; at worst a stale "<path>.part" is left.
#pragma once

#include <sstream>
#include <string>
#include <string_view>

namespace tissue::io {

/// Why `path` cannot be read as an input file: "is a directory" or "is a
/// device or socket, not a file" (reading /dev/zero would never end); ""
/// for a regular file, a pipe or a path that does not exist (the caller's
/// open reports that).
std::string not_a_file(const std::string& path);

/// The temporary name a file is written under before it is renamed: "<path>.part".
std::string part_path(const std::string& path);

/// Renames `from` over `to` (rename(2): atomic, replaces an existing `to`).
/// Throws std::runtime_error naming both paths and the reason on failure.
void rename_into_place(const std::string& from, const std::string& to);

/// Writes `contents` to part_path(path), flushes it, then renames it to
/// `path`. Throws std::runtime_error naming the path when a step fails (disk
/// full, folder missing, permission); the .part file is then removed.
void write_file_atomic(const std::string& path, std::string_view contents);

/// A text file assembled in memory and written atomically by commit(): for
/// writers that stream (`out() << ...`). Destroyed without commit(), it
/// writes nothing.
class AtomicTextFile {
 public:
  explicit AtomicTextFile(std::string path) : path_(std::move(path)) {}
  std::ostream& out() { return text_; }
  /// write_file_atomic(path, what was streamed).
  void commit() { write_file_atomic(path_, text_.str()); }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::ostringstream text_;
};

}  // namespace tissue::io
