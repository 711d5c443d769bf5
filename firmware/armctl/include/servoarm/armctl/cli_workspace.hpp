// SPDX-License-Identifier: Apache-2.0
#pragma once
// armctl kin workspace: the region the tool point reaches in a plane through the base
// (joint limits respected), its area, a CSV of the region and an SVG drawing of it with
// the arm in a reference pose (V. Carrara, Apostila de Robótica, §3.8: manufacturers give the workspace as the
// reach in one or more planes). Non-real-time: allocates.
//
// How: the joints are gridded and the image of each small joint-space cell of the two
// joints that move the tool point most (a quadrilateral in the plane) is filled into a
// raster of square cells; the other joints are stepped. Two kinds of arm:
//   planar   every tool point lies in one base plane (the seeds' rr, rrr, rlr arms): the
//            region in that plane; other planes hold only a line and are refused.
//   turning  joint 1 turns the tool point about the base z axis (checked numerically):
//            joint 1 is solved for, not gridded -- a point at radius rho and height z is
//            in the xz plane at x = +rho / -rho (yz: y = +rho / -rho) when joint 1 can
//            bring it there within its limits; the xy plane (z = 0) is the ring of radii
//            reached at height 0, over the azimuths joint 1 reaches.
// Other arms are refused (exit 1) naming why.
#include <cstdint>
#include <string>
#include <vector>

#include "servoarm/kinematics/chain.hpp"

namespace servoarm::fw {

struct WorkspaceOptions {
  std::string plane;         ///< "xz", "xy", "yz"; empty: the planar arm's plane, else xz
  int grid = 400;            ///< raster cells along the longer side of the region
  std::vector<double> pose;  ///< reference pose drawn (description units); empty: 0 clamped to the limits
};

struct WorkspaceResult {
  int status = 0;       ///< 0 ok, 1 the arm has no workspace area in that plane / unsupported, 2 bad input
  std::string error;    ///< one line when status != 0
  std::string plane;    ///< "xz", ...
  char u = 'x', v = 'z';
  double level = 0;     ///< the plane's offset along its normal, m (0: through the base)
  std::string method;   ///< "planar" or "turning"
  double u0 = 0, v0 = 0, cell = 0;  ///< m: lower-left corner of cell (0, 0), cell size
  int nu = 0, nv = 0;
  std::vector<std::uint8_t> on;     ///< nu * nv, row-major by v: 1 reachable
  double area = 0;                  ///< m^2
  long evaluations = 0;             ///< forward kinematics evaluated
  kin::JointVector pose;            ///< reference pose, SI
  bool at(int i, int j) const { return on[static_cast<std::size_t>(j) * nu + i] != 0; }
  double uc(int i) const { return u0 + (i + 0.5) * cell; }
  double vc(int j) const { return v0 + (j + 0.5) * cell; }
};

/// The workspace of `chain` in a plane (see the file comment).
WorkspaceResult compute_workspace(const kin::Chain& chain, const WorkspaceOptions& options);

/// armctl kin workspace --robot NAME|FILE [--plane xz|xy|yz] [--grid N] [--pose q1..qn]
///                      [--svg FILE] [--csv FILE]
/// argv[0] is "workspace". Exit: 0 ok, 1 no area in that plane / arm not supported, 2 bad usage.
int cli_kin_workspace(int argc, char** argv);

}  // namespace servoarm::fw
