// The lane kernels tuned for a recent Xeon (cpu/CMakeLists.txt: -mtune=sapphirerapids),
// the ones an Intel CPU runs (lanes_tuning, element_lanes.hpp).
#define TISSUE_LANES_TUNING xeon
#include "cpu/element_lanes_kernels.inc"
