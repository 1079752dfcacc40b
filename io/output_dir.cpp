#include "io/output_dir.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "io/atomic_file.hpp"

namespace tissue::io {
namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const std::string& dir, const std::string& what) {
  throw std::runtime_error(fmt::format("{}: {}", dir, what));
}

/// The pid the current lock holder wrote into the lock file ("" if none).
std::string holder_pid(const std::string& lock_path) {
  std::ifstream in(lock_path);
  std::string pid;
  in >> pid;
  return pid;
}

bool is_output(const std::string& name, const std::vector<std::string>& outputs) {
  for (const std::string& p : outputs)
    if (matches_pattern(name, p) || matches_pattern(name, part_path(p))) return true;
  return false;
}

}  // namespace

bool matches_pattern(const std::string& name, const std::string& pattern) {
  const size_t star = pattern.find('*');
  if (star == std::string::npos) return name == pattern;
  const std::string_view head(pattern.data(), star), tail(pattern.data() + star + 1, pattern.size() - star - 1);
  return name.size() >= head.size() + tail.size() && name.compare(0, head.size(), head) == 0 &&
         name.compare(name.size() - tail.size(), tail.size(), tail) == 0;
}

OutputFolder::OutputFolder(std::string dir, std::vector<std::string> outputs, bool overwrite) : dir_(std::move(dir)) {
  std::error_code ec;
  if (fs::exists(dir_, ec) && !fs::is_directory(dir_, ec))
    fail(dir_, "exists and is not a folder; give a folder for the outputs");
  fs::create_directories(dir_, ec);
  if (ec) fail(dir_, fmt::format("cannot create the output folder: {}", ec.message()));

  const std::string lock_path = file(lock_name());
  lock_.fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (lock_.fd < 0) fail(dir_, fmt::format("cannot create the lock file {}: {}", lock_name(), std::strerror(errno)));
  if (::flock(lock_.fd, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    if (err != EWOULDBLOCK) fail(dir_, fmt::format("cannot lock {}: {}", lock_name(), std::strerror(err)));
    const std::string pid = holder_pid(lock_path);
    fail(dir_, fmt::format("the folder is in use by another running tissue process{}; wait for it to finish or "
                           "choose another folder",
                           pid.empty() ? "" : " (pid " + pid + ")"));
  }
  const std::string me = std::to_string(::getpid()) + "\n";
  if (::ftruncate(lock_.fd, 0) != 0 || ::pwrite(lock_.fd, me.data(), me.size(), 0) != ssize_t(me.size())) {
    // the pid is only for messages; the lock is what counts
  }

  std::vector<std::string> found;
  for (const fs::directory_entry& e : fs::directory_iterator(dir_, ec))
    if (!e.is_directory() && is_output(e.path().filename().string(), outputs))
      found.push_back(e.path().filename().string());
  if (ec) fail(dir_, fmt::format("cannot list the folder: {}", ec.message()));
  std::sort(found.begin(), found.end());
  if (found.empty()) return;
  if (!overwrite) {
    std::string list;
    for (size_t k = 0; k < found.size() && k < 4; ++k) list += (k ? ", " : "") + found[k];
    if (found.size() > 4) list += fmt::format(" and {} more", found.size() - 4);
    fail(dir_, fmt::format("the folder holds another run's outputs ({}); pass --overwrite to replace them, or choose "
                           "another folder",
                           list));
  }
  for (const std::string& name : found) {
    fs::remove(fs::path(dir_) / name, ec);
    if (ec) fail(dir_, fmt::format("--overwrite: cannot remove {}: {}", name, ec.message()));
    ++removed_;
  }
}

OutputFolder::Fd::~Fd() {
  if (fd >= 0) ::close(fd);  // releases the flock
}

std::string OutputFolder::file(const std::string& name) const {
  return (fs::path(dir_) / name).string();
}

}  // namespace tissue::io
