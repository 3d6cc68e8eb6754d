#pragma once
// Numbers in messages as a person writes them: 6, 0.25, 1e+07, not std::to_string's 6.000000.
#include <sstream>
#include <string>

namespace brainshift {

/// `value` with up to six significant digits and no trailing zeros (std::ostream's default).
inline std::string numberText(double value)
{
  std::ostringstream text;
  text << value;
  return text.str();
}

} // namespace brainshift
