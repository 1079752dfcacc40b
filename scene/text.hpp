// Strict text-to-number conversion shared by the scene readers (io/scene_xml,
// io/tetgen_files, io/path_csv): a token is a number only if all of it is
// one, so "3e", "1.5mm" or "abc" are rejected instead of silently read as a
// prefix. Callers add the file, line and field to the error.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/hd.hpp"

namespace tissue::scene {

/// The real number spelled by all of `text` (surrounding blanks ignored;
/// decimal or scientific notation, optional sign, "inf"/"nan" accepted so that
/// validation can name them); nullopt when any character is left over.
std::optional<double> parse_real(std::string_view text);

/// The integer spelled by all of `text` (surrounding blanks ignored, optional
/// sign); nullopt when it is not one or does not fit in a long long.
std::optional<long long> parse_integer(std::string_view text);

/// Blank-separated tokens of `text` (spaces, tabs, CR, LF), as views into it.
std::vector<std::string_view> split_blanks(std::string_view text);

/// `text` without leading and trailing blanks.
std::string_view trim(std::string_view text);

/// The comma-separated fields of one CSV line, each trimmed (views into it).
std::vector<std::string_view> split_commas(std::string_view text);

/// True for a CSV line to skip: blank, or a comment starting with '#'.
bool csv_skipped(std::string_view line);

/// Where `line` holds a byte that no text file holds (NUL or another control
/// character but tab, CR, vertical tab and form feed): its offset, or nullopt
/// for a line of text. A CSV reader checks each line with it, so that a binary
/// file is named as such instead of as a field that is not a number.
std::optional<size_t> binary_byte(std::string_view line);

/// `text` safe to quote in a message: printable ASCII as it is, every other
/// byte as \xNN (a NUL would otherwise end the message where it is printed),
/// cut after `max` bytes with "...".
std::string printable(std::string_view text, size_t max = 60);

/// "<what> is binary, not text: line L holds byte 0xNN at column C
/// ('<printable line>')": the message for a line binary_byte found.
std::string binary_line_message(const std::string& what, int line, std::string_view text, size_t at);

/// "float" | "double"; std::invalid_argument naming the text otherwise.
Precision parse_precision(const std::string& s);

/// A region depth: a whole number >= 0, "all" (kDepthAll) or "auto"
/// (kDepthAuto); std::invalid_argument naming the text otherwise.
int parse_depth(const std::string& s);

}  // namespace tissue::scene
