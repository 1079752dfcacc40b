// Host/device annotation shared by core math. Core headers compile with any
// C++20 compiler; under nvcc the same inline functions become device code.
#pragma once

#if defined(__CUDACC__)
#define TISSUE_HD __host__ __device__ __forceinline__
#define TISSUE_UNROLL _Pragma("unroll")
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
