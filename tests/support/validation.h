// What a config's validate() says: the message it throws, or "" when it accepts the config.
// Tests check that a bad value is refused by the name of its field.
#pragma once

#include <stdexcept>
#include <string>

namespace segmatch::test {

template <typename Config>
std::string validation_message(const Config& config) {
  try {
    config.validate();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return {};
}

}  // namespace segmatch::test
