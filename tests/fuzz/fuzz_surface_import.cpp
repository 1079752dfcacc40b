// Fuzzes surface import (io/surface_import): our side of it -- walking
// Assimp's scene (node transforms, faces, index ranges), the unit scale,
// welding, dropping unused vertices, the closed-surface check and the
// enclosed volume. Assimp itself is a prebuilt library and is not
// instrumented. The first input byte picks the format (OBJ, STL, PLY,
// OFF), the rest is the file, written to a per-process file in /dev/shm
// (the importer reads files; its format comes from the extension). Only
// MeshError may escape; a surface that loads has every corner in range.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <fstream>
#include <string>

#include "io/surface_import.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tissue;
  if (size < 1) return 0;
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
