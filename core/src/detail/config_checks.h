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

// `what_zero_means`, if given, is appended: e.g. "(0: off)".
inline void require_non_negative(double value, const char* owner, const char* field,
                                 const char* what_zero_means = nullptr) {
  if (!(value >= 0.0) || !std::isfinite(value))
    throw std::invalid_argument(std::string(owner) + "." + field + " must be finite and >= 0" +
                                (what_zero_means ? std::string(" ") + what_zero_means : std::string()));
}

inline void require_fraction(double value, const char* owner, const char* field) {
  if (!(value >= 0.0 && value <= 1.0))
    throw std::invalid_argument(std::string(owner) + "." + field + " must be in 0..1");
}

}  // namespace detail
}  // namespace segmatch
