// The lane kernels under the compiler's generic tuning, the ones every other
// CPU runs (lanes_tuning, element_lanes.hpp).
#define TISSUE_LANES_TUNING generic
#include "cpu/element_lanes_kernels.inc"
