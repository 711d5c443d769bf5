// SPDX-License-Identifier: Apache-2.0
#pragma once
// The firmware's motion IK: one function, used by the console (movel / G0 / G1 path
// check, and the control thread's Cartesian samples, which run the IkSolver the console
// put in the queued motion) and by `armctl plan movel`, so that what armctl previews is
// the firmware's own path (tests/armctl/test_plan_preview.cpp compares the samples).
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/motion_ik.hpp"

namespace servoarm::fw {

/// The options make_ik_solver() gets in the firmware: the nearest solution within the
/// joint limits (never one outside them: nothing outside the limits is commanded), from
/// the model's closed form; where the model has none (or there is no model), the
/// damped-Newton fallback on the full pose error (movel's path check refuses what it
/// finds outside the limits).
kin::IkSolverOptions firmware_ik_options(const kin::IkModel* model);

/// make_ik_solver(*model, firmware_ik_options(model)); `model` may be nullptr (a chain
/// ik_prepare could not analyse): the Newton fallback, which needs no model.
/// The model must outlive the solver.
kin::IkSolver firmware_ik_solver(const kin::IkModel* model);

}  // namespace servoarm::fw
