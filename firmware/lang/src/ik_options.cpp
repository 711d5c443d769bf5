// SPDX-License-Identifier: Apache-2.0
#include "servoarm/lang/ik_options.hpp"

namespace servoarm::fw {

kin::IkSolverOptions firmware_ik_options(const kin::IkModel* model) {
  kin::IkSolverOptions o;
  o.allow_out_of_limits = false;
  o.closed_form = true;
  o.fallback = kin::IkFallback::numeric;
  if (model == nullptr || model->method == kin::IkMethod::none) {
    o.closed_form = false;
    o.fallback = kin::IkFallback::newton;
  }
  return o;
}

kin::IkSolver firmware_ik_solver(const kin::IkModel* model) {
  // IkFallback::newton does not read the model (motion_ik.hpp): without one, its fn alone.
  if (model == nullptr) return kin::IkSolver{&kin::ik_nearest_newton, nullptr};
  return kin::make_ik_solver(*model, firmware_ik_options(model));
}

}  // namespace servoarm::fw
