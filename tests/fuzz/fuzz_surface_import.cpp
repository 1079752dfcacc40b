// Fuzzes surface import (io/surface_import): our side of it -- walking
// Assimp's scene (node transforms, faces, index ranges), the unit scale,
// welding, dropping unused vertices, the closed-surface check and the
// enclosed volume. Assimp itself is a prebuilt library and is not
// instrumented. The first input byte picks the format (OBJ, STL, PLY,
// OFF; PLY is off for now, below), the rest is the file, written to a per-process file in /dev/shm
// (the importer reads files; its format comes from the extension). Only
// MeshError may escape; a surface that loads has every corner in range.
#include <unistd.h>

#include <cctype>
#include <cstddef>
#include <cstdint>
#include <fstream>
#include <string>

#include "io/surface_import.hpp"

namespace {

/// Assimp 5.2's PLY reader loops forever on a header without end_header.
/// load_surface guards against that, but only for files starting with
/// lowercase "ply": "PLY", "plY" or leading blanks slip past its guard and
/// hang (docs/reliability.md, "Fuzzing"; the fix belongs in
/// io/surface_import.cpp). Until it is fixed this harness skips such
/// inputs -- every .ply input without an end_header, in any case -- so that
/// the fuzzer explores the rest instead of rediscovering that hang.
bool hangs_assimp_ply(const char* text, std::size_t size) {
  std::string lower(text, size);
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return lower.find("end_header") == std::string::npos;
}

/// PLY inputs are skipped for now: a malformed PLY face list makes Assimp
/// 5.2's Triangulate step abort the process (ai_assert, kept in Debian's
/// build), which load_surface cannot catch; the fix (read without
/// aiProcess_Triangulate and fan-triangulate in our own walk) belongs in
/// io/surface_import.cpp. docs/reliability.md has the reproducer. Set to true
/// once it is fixed.
constexpr bool kFuzzPly = false;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tissue;
  if (size < 1) return 0;
  if (data[0] % 4 == 2) {
    if (!kFuzzPly) return 0;
    if (hangs_assimp_ply(reinterpret_cast<const char*>(data + 1), size - 1)) return 0;
  }
  static const char* kExt[4] = {"obj", "stl", "ply", "off"};
  const std::string path = "/dev/shm/tissue-fuzz-" + std::to_string(getpid()) + "." + kExt[data[0] % 4];
  {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    f.write(reinterpret_cast<const char*>(data + 1), std::streamsize(size - 1));
  }
  try {
    io::SurfaceMesh s = io::load_surface(path, 1e-3);
    for (index_t v : s.triangles)
      if (v < 0 || v >= s.n_vertices()) __builtin_trap();
    (void)io::weld_vertices(s);
    io::check_closed(s, "fuzz");
    (void)io::enclosed_volume(s);
  } catch (const io::MeshError&) {
  }
  unlink(path.c_str());
  return 0;
}
