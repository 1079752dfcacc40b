// The lane kernels' entry points: each calls the compilation of the kernel
// that lanes_tuning() names (element_lanes_xeon.cpp or element_lanes_generic.cpp,
// the same source, cpu/element_lanes_kernels.inc).
#include "cpu/element_lanes.hpp"

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>

namespace tissue::cpu {

namespace xeon {
#include "cpu/element_lanes_api.inc"
}
namespace generic {
#include "cpu/element_lanes_api.inc"
}

namespace {

/// The default: TISSUE_CPU_TUNING (xeon | generic) where set, else by the
/// CPU's vendor.
LanesTuning initial_tuning() {
  if (const char* e = std::getenv("TISSUE_CPU_TUNING")) {
    if (std::strcmp(e, "xeon") == 0) return LanesTuning::Xeon;
    if (std::strcmp(e, "generic") == 0) return LanesTuning::Generic;
    throw std::invalid_argument(std::string("TISSUE_CPU_TUNING=") + e + ": not xeon or generic");
  }
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
  __builtin_cpu_init();
  if (__builtin_cpu_is("intel")) return LanesTuning::Xeon;
#endif
  return LanesTuning::Generic;
}

std::atomic<LanesTuning>& tuning() {
  static std::atomic<LanesTuning> t{initial_tuning()};
  return t;
}

bool xeon_tuned() { return tuning().load(std::memory_order_relaxed) == LanesTuning::Xeon; }

}  // namespace

LanesTuning lanes_tuning() { return tuning().load(std::memory_order_relaxed); }

void set_lanes_tuning(LanesTuning t) { tuning().store(t, std::memory_order_relaxed); }

const char* to_string(LanesTuning t) { return t == LanesTuning::Xeon ? "xeon" : "generic"; }

template <class T>
void lanes_corner_u(const T* u, index_t n, const index_t* en, index_t ne, T (&out)[12][kLanes]) {
  xeon_tuned() ? xeon::lanes_corner_u(u, n, en, ne, out) : generic::lanes_corner_u(u, n, en, ne, out);
}

template <class T>
void lanes_pbar(const T* node_p, const index_t* en, index_t ne, T (&pbar)[kLanes]) {
  xeon_tuned() ? xeon::lanes_pbar(node_p, en, ne, pbar) : generic::lanes_pbar(node_p, en, ne, pbar);
}

template <class T>
void lanes_pressure(ElementLanes<T>& b) {
  xeon_tuned() ? xeon::lanes_pressure(b) : generic::lanes_pressure(b);
}

template <class T, bool kIanp>
void lanes_forces(ElementLanes<T>& b) {
  xeon_tuned() ? xeon::lanes_forces<T, kIanp>(b) : generic::lanes_forces<T, kIanp>(b);
}

template <class T, bool kIanp, class Terms>
void lanes_forces_law(ElementLanes<T>& b, LawLanes<T>& w) {
  xeon_tuned() ? xeon::lanes_forces_law<T, kIanp, Terms>(b, w) : generic::lanes_forces_law<T, kIanp, Terms>(b, w);
}

template <class T, bool kIanp>
void lanes_energy(ElementLanes<T>& b) {
  xeon_tuned() ? xeon::lanes_energy<T, kIanp>(b) : generic::lanes_energy<T, kIanp>(b);
}

template <class T, bool kIanp>
void lanes_energy_fibre(ElementLanes<T>& b, const LawLanes<T>& w) {
  xeon_tuned() ? xeon::lanes_energy_fibre<T, kIanp>(b, w) : generic::lanes_energy_fibre<T, kIanp>(b, w);
}

template <class T, bool kIanp>
void lanes_prony_energy(ElementLanes<T>& b, const LawLanes<T>& w, const T (&g)[kMaxProny][kLanes],
                        const T (&tau)[kMaxProny][kLanes], T (&power)[kLanes], T (&stored)[kLanes]) {
  xeon_tuned() ? xeon::lanes_prony_energy<T, kIanp>(b, w, g, tau, power, stored)
               : generic::lanes_prony_energy<T, kIanp>(b, w, g, tau, power, stored);
}

#include "cpu/element_lanes_instances.inc"

}  // namespace tissue::cpu
