// Must NOT compile: a length plus a force. Built by try_compile in tests/shared/CMakeLists.txt.
#include "palpa/fixed/units.h"

int main() {
  palpa::fixed::Voxels x{palpa::fixed::Q16::FromInt(1)};
  palpa::fixed::Newtons f{palpa::fixed::Q16::FromInt(1)};
  auto bad = x + f;
  (void)bad;
  return 0;
}
