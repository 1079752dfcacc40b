// The hot loop's bad-element flag (STYLE.md: inside the loop, flags; checked
// once per tick). Pass 3 records every element whose J is <= 0 or not
// finite; the flag keeps the lowest element index (and that element's J)
// seen since the last take(), so the report does not depend on thread order.
#pragma once

#include <atomic>
#include <bit>
#include <cstdint>

#include "core/hd.hpp"

namespace tissue::cpu {

/// Lock-free "lowest bad element" flag: one 64-bit word packing the element
/// index (high 32 bits) and its J as a float (low 32 bits), lowered with a
/// compare-and-swap minimum. Recording is rare (only bad elements), so
/// contention does not matter.
class BadElementFlag {
 public:
  /// Records element e (0 <= e < 2^31) with Jacobian J (dimensionless).
  void record(index_t e, double J) {
    const std::uint64_t v = (std::uint64_t(std::uint32_t(e)) << 32) | std::bit_cast<std::uint32_t>(float(J));
    std::uint64_t cur = packed_.load(std::memory_order_relaxed);
    while (v < cur && !packed_.compare_exchange_weak(cur, v, std::memory_order_relaxed)) {
    }
  }

  /// Reads and clears the flag. Returns the lowest recorded element (-1 if
  /// none) and writes its J (as recorded, float-rounded) to *J.
  index_t take(double* J) {
    const std::uint64_t v = packed_.exchange(kNone, std::memory_order_relaxed);
    if (v == kNone) return -1;
    *J = std::bit_cast<float>(std::uint32_t(v & 0xffffffffu));
    return index_t(v >> 32);
  }

 private:
  static constexpr std::uint64_t kNone = ~std::uint64_t(0);
  std::atomic<std::uint64_t> packed_{kNone};
};

}  // namespace tissue::cpu
