#include "scene/text.hpp"

#include <fmt/format.h>

#include <charconv>
#include <stdexcept>

#include "core/region.hpp"

namespace tissue::scene {
namespace {

constexpr std::string_view kBlanks = " \t\r\n\v\f";

/// from_chars rejects a leading '+'; accept one (not "+-1").
std::string_view drop_plus(std::string_view t) {
  if (t.size() > 1 && t[0] == '+' && t[1] != '-' && t[1] != '+') t.remove_prefix(1);
  return t;
}

}  // namespace

std::string_view trim(std::string_view text) {
  const size_t b = text.find_first_not_of(kBlanks);
  if (b == std::string_view::npos) return {};
  const size_t e = text.find_last_not_of(kBlanks);
  return text.substr(b, e - b + 1);
}

std::optional<double> parse_real(std::string_view text) {
  const std::string_view t = drop_plus(trim(text));
  if (t.empty()) return std::nullopt;
  double v = 0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v, std::chars_format::general);
  // out-of-range values (1e999) are reported as errors too, not rounded to inf
  if (ec != std::errc() || end != t.data() + t.size()) return std::nullopt;
  return v;
}

std::optional<long long> parse_integer(std::string_view text) {
  const std::string_view t = drop_plus(trim(text));
  if (t.empty()) return std::nullopt;
  long long v = 0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
  if (ec != std::errc() || end != t.data() + t.size()) return std::nullopt;
  return v;
}

std::vector<std::string_view> split_blanks(std::string_view text) {
  std::vector<std::string_view> out;
  size_t i = text.find_first_not_of(kBlanks);
  while (i != std::string_view::npos) {
    const size_t j = text.find_first_of(kBlanks, i);
    out.push_back(text.substr(i, j == std::string_view::npos ? std::string_view::npos : j - i));
    i = text.find_first_not_of(kBlanks, j);
  }
  return out;
}

Precision parse_precision(const std::string& s) {
  if (s == "float") return Precision::Float;
  if (s == "double") return Precision::Double;
  throw std::invalid_argument(fmt::format("precision '{}' is neither 'float' nor 'double'", s));
}

int parse_depth(const std::string& s) {
  if (s == "all") return kDepthAll;
  if (s == "auto") return kDepthAuto;
  int d = -1;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), d);
  if (ec != std::errc() || end != s.data() + s.size() || d < 0)
    throw std::invalid_argument(fmt::format("region depth '{}' is neither a whole number >= 0 nor 'all' nor 'auto'", s));
  return d;
}

std::vector<std::string_view> split_commas(std::string_view text) {
  std::vector<std::string_view> out;
  size_t i = 0;
  for (size_t j; (j = text.find(',', i)) != std::string_view::npos; i = j + 1) out.push_back(trim(text.substr(i, j - i)));
  out.push_back(trim(text.substr(i)));
  return out;
}

std::optional<size_t> binary_byte(std::string_view line) {
  for (size_t k = 0; k < line.size(); ++k) {
    const unsigned char c = static_cast<unsigned char>(line[k]);
    if ((c < 0x20 && c != '\t' && c != '\r' && c != '\v' && c != '\f') || c == 0x7f) return k;
  }
  return std::nullopt;
}

std::string printable(std::string_view text, size_t max) {
  std::string out;
  for (size_t k = 0; k < text.size() && k < max; ++k) {
    const unsigned char c = static_cast<unsigned char>(text[k]);
    if (c >= 0x20 && c < 0x7f && c != '\\')
      out += static_cast<char>(c);
    else if (c == '\\')
      out += "\\\\";
    else
      out += fmt::format("\\x{:02x}", c);
  }
  if (text.size() > max) out += "...";
  return out;
}

std::string binary_line_message(const std::string& what, int line, std::string_view text, size_t at) {
  return fmt::format("{} is binary, not text: line {} holds byte 0x{:02x} at column {} ('{}')", what, line,
                     static_cast<unsigned char>(text[at]), at + 1, printable(text));
}

bool csv_skipped(std::string_view line) {
  const std::string_view t = trim(line);
  return t.empty() || t.front() == '#';
}

}  // namespace tissue::scene
