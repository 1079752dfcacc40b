#include "io/atomic_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <fmt/format.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>

namespace tissue::io {

std::string not_a_file(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return "";
  if (S_ISDIR(st.st_mode)) return "is a directory";
  if (S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) || S_ISSOCK(st.st_mode)) return "is a device or socket";
  return "";
}

std::string part_path(const std::string& path) {
  return path + ".part";
}

void rename_into_place(const std::string& from, const std::string& to) {
  if (std::rename(from.c_str(), to.c_str()) != 0)
    throw std::runtime_error(fmt::format("{}: cannot rename {} into place: {}", to, from, std::strerror(errno)));
}

void write_file_atomic(const std::string& path, std::string_view contents) {
  const std::string part = part_path(path);
  const int fd = ::open(part.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error(fmt::format("{}: cannot open {} for writing: {}", path, part, std::strerror(errno)));
  size_t done = 0;
  while (done < contents.size()) {
    const ssize_t n = ::write(fd, contents.data() + done, contents.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = n < 0 ? std::strerror(errno) : "no progress";
      ::close(fd);
      ::unlink(part.c_str());
      throw std::runtime_error(fmt::format("{}: write failed after {} of {} bytes: {}", path, done, contents.size(), why));
    }
    done += size_t(n);
  }
  if (::close(fd) != 0) {
    const std::string why = std::strerror(errno);
    ::unlink(part.c_str());
    throw std::runtime_error(fmt::format("{}: write failed: {}", path, why));
  }
  try {
    rename_into_place(part, path);
  } catch (...) {
    ::unlink(part.c_str());
    throw;
  }
}

}  // namespace tissue::io
