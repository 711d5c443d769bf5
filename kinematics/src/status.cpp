// SPDX-License-Identifier: Apache-2.0
#include "servoarm/kinematics/status.hpp"

namespace servoarm::kin {

const char* to_string(Status s) {
  switch (s) {
    case Status::ok: return "ok";
    case Status::singular: return "singular";
    case Status::out_of_limits: return "out_of_limits";
    case Status::not_converged: return "not_converged";
    case Status::bad_input: return "bad_input";
    case Status::wrong_size: return "wrong_size";
    case Status::unreachable: return "unreachable";
    case Status::capacity: return "capacity";
    case Status::unsupported: return "unsupported";
  }
  return "unknown";
}

}  // namespace servoarm::kin
