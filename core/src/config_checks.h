// The one home of the config validators' range checks: each names the field it refuses as
// "Struct.field", so a bad parameters file says what to fix.
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>

namespace segmatch {
namespace detail {

inline void require_positive(double value, const char* owner, const char* field) {
  if (!(value > 0.0) || !std::isfinite(value))
    throw std::invalid_argument(std::string(owner) + "." + field + " must be finite and > 0");
}

}  // namespace detail
}  // namespace segmatch
