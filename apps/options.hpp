// Command-line values checked in one place, with messages that name the
// option, the value and the rule: whole numbers written in digits (no "2.5",
// no "1e12"), within a range; real numbers finite (no "nan", "inf"),
// within a range. CLI11 runs the checks before converting, so a bad value
// never reaches a command as a default or a wrapped-around number.
#pragma once

#include <CLI/CLI.hpp>

#include <string>
#include <string_view>

namespace tissue::app {

/// "" when `text` is a whole number in digits within [lo, hi]; otherwise
/// why not ("'1e12' is not a whole number written in digits ...").
std::string whole_number_error(std::string_view text, long long lo, long long hi);

/// "" when `text` is a finite real number within the range (lo and hi
/// included unless lo_open / hi_open); otherwise why not.
std::string real_number_error(std::string_view text, double lo, double hi, bool lo_open = false,
                              bool hi_open = false);

/// "" when `path` can be written as an output file: not empty, not a folder,
/// its folder exists; otherwise why not. Checked before a long command
/// runs, so that its result is not lost at the end.
std::string output_file_error(const std::string& path);

/// "" when `path` is a usable output folder name (not empty, not a file).
std::string output_folder_error(const std::string& path);

/// CLI11 checks wrapping the functions above (for each value of a list option too).
CLI::Validator whole_number(long long lo, long long hi);
CLI::Validator real_number(double lo, double hi, bool lo_open = false, bool hi_open = false);
/// A finite number > 0 (real_number over (0, inf)).
CLI::Validator positive_real();
CLI::Validator output_file();
CLI::Validator output_folder();

}  // namespace tissue::app
