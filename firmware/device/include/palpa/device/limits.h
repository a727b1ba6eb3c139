// What a haptic device can render: palpad refuses a stiffness k or a force clamp above these at
// start-up and in --check-config (issue 18, finding 3). Each backend states its own, with its
// source, next to its class.
#pragma once

namespace palpa::device {

struct DeviceLimits {
  const char* name = "";             ///< the device, for messages ("Novint Falcon")
  double max_stiffness_n_per_m = 0;  ///< highest stiffness k the device renders stably, N/m
  double max_force_n = 0;            ///< force rating: the largest force clamp accepted, N
  const char* source = "";           ///< where the two figures come from, for messages and docs
};

}  // namespace palpa::device
