#include "BrainShiftErrors.h"

#include <iostream>

namespace brainshift {

void warn(Warnings* warnings, const std::string& message)
{
  if (warnings) {
    warnings->push_back(message);
  } else {
    std::cerr << "warning: " << message << '\n';
  }
}

} // namespace brainshift
