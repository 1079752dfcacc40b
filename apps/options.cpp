#include "apps/options.hpp"

#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <filesystem>

#include "scene/text.hpp"

namespace tissue::app {

std::string whole_number_error(std::string_view text, long long lo, long long hi) {
  const auto v = scene::parse_integer(text);
  const std::string_view t = scene::trim(text);
  const size_t digits = t.find_first_not_of("+-") == 1 ? 1 : 0;
  if (!v && t.size() > digits && t.find_first_not_of("0123456789", digits) == std::string_view::npos)
    return fmt::format("{} is out of range: it must be in [{}, {}]", t, lo, hi);  // digits beyond long long
  if (!v) {
    const auto r = scene::parse_real(text);
    if (r && std::isfinite(*r) && *r == std::floor(*r))
      return fmt::format("'{}' is not a whole number written in digits{}", text,
                         std::fabs(*r) <= double(hi) ? fmt::format(" (write {:.0f})", *r)
                                                     : fmt::format(" (and {:.3g} is above the most, {})", *r, hi));
    return fmt::format("'{}' is not a whole number", text);
  }
  if (*v < lo || *v > hi) return fmt::format("{} is out of range: it must be in [{}, {}]", *v, lo, hi);
  return "";
}

std::string real_number_error(std::string_view text, double lo, double hi, bool lo_open, bool hi_open) {
  const auto v = scene::parse_real(text);
  if (!v) return fmt::format("'{}' is not a number", text);
  if (!std::isfinite(*v)) return fmt::format("{} is not a finite number", text);
  const bool below = lo_open ? !(*v > lo) : !(*v >= lo), above = hi_open ? !(*v < hi) : !(*v <= hi);
  if (below || above)
    return fmt::format("{} is out of range: it must be in {}{}, {}{}", text, lo_open ? "(" : "[", lo, hi,
                       hi_open ? ")" : "]");
  return "";
}

std::string output_file_error(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) return "an empty file name";
  std::error_code ec;
  if (fs::is_directory(path, ec)) return fmt::format("{} is a folder; give a file name", path);
  const fs::path dir = fs::path(path).parent_path();
  if (!dir.empty() && !fs::is_directory(dir, ec)) return fmt::format("{}: the folder {} does not exist", path, dir.string());
  return "";
}

std::string output_folder_error(const std::string& path) {
  std::error_code ec;
  if (path.empty()) return "an empty folder name";
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_directory(path, ec))
    return fmt::format("{} exists and is not a folder", path);
  return "";
}

CLI::Validator output_file() {
  return CLI::Validator([](std::string& s) { return output_file_error(s); }, "FILE");
}

CLI::Validator output_folder() {
  return CLI::Validator([](std::string& s) { return output_folder_error(s); }, "DIR");
}

CLI::Validator whole_number(long long lo, long long hi) {
  return CLI::Validator([lo, hi](std::string& s) { return whole_number_error(s, lo, hi); },
                        fmt::format("INT in [{}, {}]", lo, hi));
}

CLI::Validator real_number(double lo, double hi, bool lo_open, bool hi_open) {
  return CLI::Validator(
      [=](std::string& s) { return real_number_error(s, lo, hi, lo_open, hi_open); },
      fmt::format("REAL in {}{}, {}{}", lo_open ? "(" : "[", lo, hi, hi_open ? ")" : "]"));
}

CLI::Validator positive_real() {
  return real_number(0, std::numeric_limits<double>::infinity(), true, true);
}

}  // namespace tissue::app
