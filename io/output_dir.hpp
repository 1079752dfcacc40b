// An output folder owned by one run. Two rules keep runs from mixing their
// files:
//   - in use: the owner holds an exclusive flock(2) on "<dir>/.tissue.lock"
//     for its whole life; a second process is refused while it lives. The
//     kernel drops the lock whenever the owner's process ends -- normal exit,
//     exception, signal, crash or kill -9 -- so a stale lock cannot block a
//     later run. The (empty but for a pid) lock file itself stays.
//   - previous outputs: a folder that already holds files this kind of run
//     writes (the `outputs` patterns, and their ".part" temporaries) is
//     refused, unless `overwrite`, which deletes exactly those files first
//     (a new series never sits beside an old one's extra frames). Files that
//     match no pattern are never touched.
#pragma once

#include <string>
#include <vector>

namespace tissue::io {

class OutputFolder {
 public:
  /// Creates `dir` (and parents) if missing, locks it and checks it for
  /// previous outputs. `outputs`: file names this run writes; one '*' in a
  /// name matches any run of characters ("frame_*.vtu"). Throws
  /// std::runtime_error naming the folder and the rule: not a folder, cannot
  /// be created, in use by another process (its pid), or holding previous
  /// outputs (listed, with the --overwrite hint).
  OutputFolder(std::string dir, std::vector<std::string> outputs, bool overwrite);
  OutputFolder(const OutputFolder&) = delete;
  OutputFolder& operator=(const OutputFolder&) = delete;

  const std::string& path() const { return dir_; }
  /// "<dir>/<name>".
  std::string file(const std::string& name) const;
  /// Files deleted by overwrite.
  int removed() const { return removed_; }

  /// The lock file's name inside the folder.
  static const char* lock_name() { return ".tissue.lock"; }

 private:
  /// Closes the descriptor (releasing the flock) on any exit, a throwing constructor included.
  struct Fd {
    int fd = -1;
    ~Fd();
  };
  std::string dir_;
  Fd lock_;
  int removed_ = 0;
};

/// True when `name` matches `pattern` (at most one '*', any run of characters).
bool matches_pattern(const std::string& name, const std::string& pattern);

}  // namespace tissue::io
