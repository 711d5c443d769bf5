// Closed forms of seed 002 chapter 4 (planar RR/RRR/RLR, TRR, TRL:R, VVL:R).
#include "ik_detail.hpp"

namespace servoarm::kin::detail {

bool detect_reduced(IkModel&) { return false; }

void solve_reduced(const IkModel&, const Pose&, const JointVector*, IkResult& res) { res.count = 0; }

}  // namespace servoarm::kin::detail
