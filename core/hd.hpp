// Host/device annotation shared by core math. Core headers compile with any
// C++20 compiler; under nvcc the same inline functions become device code.
#pragma once

#if defined(__CUDACC__)
#define TISSUE_HD __host__ __device__ __forceinline__
#define TISSUE_UNROLL _Pragma("unroll")
#elif defined(__GNUC__)
// Always inlined on the host too: the cpu backend's element loops vectorise
// across elements only when the whole per-element math is inlined into them.
#define TISSUE_HD inline __attribute__((always_inline))
#define TISSUE_UNROLL _Pragma("GCC unroll 16")
#else
#define TISSUE_HD inline
#define TISSUE_UNROLL
#endif

#include <cstdint>

namespace tissue {

/// Index type for nodes, elements and triangles (meshes stay below 2^31).
using index_t = std::int32_t;

/// Run-time precision of a backend's store and arithmetic.
enum class Precision { Float, Double };

inline const char* to_string(Precision p) { return p == Precision::Float ? "float" : "double"; }

}  // namespace tissue
