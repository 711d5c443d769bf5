#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Writes the test URDFs of tests/urdf (made up for the tests, no vendor files).

Each arm is given as its joint axes at q = 0 in the base link frame (a point, a
direction), the tip pose and per-link masses; the URDF frames are then chosen either
"friendly" (every joint frame parallel to the base) or "rotated" (each joint frame turned
by a random angle about its own axis, or fully at random): the converter must give the
same DH description either way. Seeded: rerunning writes the same files.
Run: python3 tests/urdf/data/make_urdfs.py (writes next to itself)."""
import math, os, random

rng = random.Random(42)
HERE = os.path.dirname(os.path.abspath(__file__))

def mat_mul(a, b): return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
def mat_t(a): return [[a[j][i] for j in range(3)] for i in range(3)]
def mat_vec(a, v): return [sum(a[i][k] * v[k] for k in range(3)) for i in range(3)]
def unit(v):
    n = math.sqrt(sum(x * x for x in v)); return [x / n for x in v]
def rot_axis(u, a):
    u = unit(u); c, s = math.cos(a), math.sin(a); x, y, z = u
    return [[c + x*x*(1-c), x*y*(1-c) - z*s, x*z*(1-c) + y*s],
            [y*x*(1-c) + z*s, c + y*y*(1-c), y*z*(1-c) - x*s],
            [z*x*(1-c) - y*s, z*y*(1-c) + x*s, c + z*z*(1-c)]]
I3 = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
def rpy(R):
    yaw = math.atan2(R[1][0], R[0][0])
    Q = mat_mul(rot_axis([0, 0, 1], -yaw), R)
    return [math.atan2(-Q[1][2], Q[1][1]), math.atan2(-Q[2][0], Q[0][0]), yaw]
def random_rot(): return rot_axis([rng.uniform(-1, 1) for _ in range(3)], rng.uniform(-math.pi, math.pi))
def f(x): return repr(float(x))
def origin(p, R): return '<origin xyz="%s" rpy="%s"/>' % (" ".join(map(f, p)), " ".join(map(f, rpy(R))))

def inertial():
    m = rng.uniform(0.3, 6.0)
    a, b = rng.uniform(0.002, 0.05), rng.uniform(0.002, 0.05)
    c = abs(a - b) + (a + b - abs(a - b)) * rng.uniform(0.1, 0.9)
    R = random_rot()
    return ('    <inertial>\n      %s\n      <mass value="%s"/>\n'
            '      <inertia ixx="%s" ixy="0" ixz="0" iyy="%s" iyz="0" izz="%s"/>\n    </inertial>\n') % (
        origin([rng.uniform(-0.08, 0.08) for _ in range(3)], R), f(m), f(a), f(b), f(c))

def write(name, joints, tip, frames="friendly", extra="", tool_links=(), comment=""):
    """joints: (name, type, point, direction, lower, upper); tip: (point, R) of the flange."""
    out = ['<?xml version="1.0"?>', '<!-- %s: test arm for tests/urdf (made up). %s -->' % (name, comment),
           '<robot name="%s">' % name, '  <link name="base_link">\n%s  </link>' % inertial()]
    parent, Fp, Fr = "base_link", [0, 0, 0], I3
    for k, (jn, jt, p, u, lo, hi) in enumerate(joints):
        if frames == "friendly": R = I3
        elif frames == "about_axis": R = rot_axis(u, rng.uniform(-math.pi, math.pi))
        else: R = random_rot()
        rel_p = mat_vec(mat_t(Fr), [p[i] - Fp[i] for i in range(3)])
        rel_R = mat_mul(mat_t(Fr), R)
        ax = mat_vec(mat_t(R), unit(u))
        child = "link_%d" % (k + 1)
        lim = ('    <limit lower="%s" upper="%s" effort="%s" velocity="%s"/>\n' % (f(lo), f(hi), f(rng.uniform(10, 300)), f(rng.uniform(1, 3)))
               if jt != "continuous" else '    <limit effort="%s" velocity="%s"/>\n' % (f(rng.uniform(10, 300)), f(rng.uniform(1, 3))))
        out.append('  <joint name="%s" type="%s">\n    <parent link="%s"/>\n    <child link="%s"/>\n    %s\n'
                   '    <axis xyz="%s"/>\n%s  </joint>' % (jn, jt, parent, child, origin(rel_p, rel_R), " ".join(map(f, ax)), lim))
        out.append('  <link name="%s">\n%s  </link>' % (child, inertial()))
        parent, Fp, Fr = child, p, R
    tp, tR = tip
    out.append('  <joint name="flange_joint" type="fixed">\n    <parent link="%s"/>\n    <child link="flange"/>\n    %s\n  </joint>'
               % (parent, origin(mat_vec(mat_t(Fr), [tp[i] - Fp[i] for i in range(3)]), mat_mul(mat_t(Fr), tR))))
    out.append('  <link name="flange"/>')
    for (ln, lp, lparent) in tool_links:
        out.append('  <joint name="%s_joint" type="fixed">\n    <parent link="%s"/>\n    <child link="%s"/>\n    %s\n  </joint>'
                   % (ln, lparent, ln, origin(lp, random_rot())))
        out.append('  <link name="%s">\n%s  </link>' % (ln, inertial()))
    out.append(extra + '</robot>\n')
    open(os.path.join(HERE, name + ".urdf"), "w").write("\n".join(out))

D = math.radians
ur = [("shoulder_pan", "revolute", [0, 0, 0.18], [0, 0, 1], -2*math.pi, 2*math.pi),
      ("shoulder_lift", "revolute", [0, 0.14, 0.18], [0, 1, 0], -2*math.pi, 2*math.pi),
      ("elbow", "revolute", [0.61, 0.02, 0.18], [0, 1, 0], -math.pi, math.pi),
      ("wrist_1", "revolute", [1.18, 0.02, 0.18], [0, 1, 0], -2*math.pi, 2*math.pi),
      ("wrist_2", "revolute", [1.18, 0.13, 0.18], [0, 0, -1], -2*math.pi, 2*math.pi),
      ("wrist_3", "revolute", [1.18, 0.13, 0.06], [0, 1, 0], -2*math.pi, 2*math.pi)]
ur_tip = ([1.18, 0.25, 0.06], rot_axis([1, 0, 0], -math.pi / 2))
write("ur_like", ur, ur_tip, comment="UR-type: axes 2-4 parallel, UR wrist.")
write("continuous", [(n, "continuous", p, u, 0, 0) for (n, t, p, u, a, b) in ur], ur_tip, frames="random",
      comment="UR-type with continuous joints and every joint frame turned at random.")
opw = [("j1", "revolute", [0, 0, 0.2], [0, 0, 1], D(-180), D(180)),
       ("j2", "revolute", [0.15, 0, 0.6], [0, 1, 0], D(-90), D(150)),
       ("j3", "revolute", [0.15, 0, 1.3], [0, 1, 0], D(-180), D(75)),
       ("j4", "revolute", [0.4, 0, 1.45], [1, 0, 0], D(-400), D(400)),
       ("j5", "revolute", [0.95, 0, 1.45], [0, 1, 0], D(-120), D(120)),
       ("j6", "revolute", [1.05, 0, 1.45], [1, 0, 0], D(-400), D(400))]
opw_tip = ([1.1, 0, 1.45], rot_axis([0, 1, 0], math.pi / 2))
write("opw_like", opw, opw_tip, comment="OPW-type industrial arm: shoulder offset, spherical wrist.")
write("rotated", opw, opw_tip, frames="about_axis",
      comment="the OPW arm with each joint frame turned by a random angle about its own axis.")
write("tool_beyond_flange", opw, opw_tip, tool_links=[("gripper_base", [0, 0, 0.05], "flange"), ("tool0", [0.02, -0.01, 0.18], "gripper_base"),
                                                      ("camera", [0.1, 0.05, 0.0], "link_3")],
      extra='''  <joint name="finger_left_joint" type="prismatic">
    <parent link="gripper_base"/><child link="finger_left"/>
    <origin xyz="0 0.02 0.08" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="20" velocity="0.1"/>
  </joint>
  <link name="finger_left"/>
  <joint name="finger_right_joint" type="prismatic">
    <parent link="gripper_base"/><child link="finger_right"/>
    <origin xyz="0 -0.02 0.08" rpy="0 0 0"/><axis xyz="0 -1 0"/>
    <limit lower="0" upper="0.04" effort="20" velocity="0.1"/>
    <mimic joint="finger_left_joint"/>
  </joint>
  <link name="finger_right"/>
''', comment="the OPW arm with a gripper and a tool link beyond the flange, a camera and two fingers off the chain.")
seven = [("a1", "revolute", [0, 0, 0.333], [0, 0, 1], -2.9, 2.9),
         ("a2", "revolute", [0, 0, 0.333], [0, 1, 0], -1.76, 1.76),
         ("a3", "revolute", [0, 0, 0.649], [0, 0, 1], -2.9, 2.9),
         ("a4", "revolute", [0.0825, 0, 0.649], [0, -1, 0], -3.07, -0.07),
         ("a5", "revolute", [0, 0, 1.033], [0, 0, 1], -2.9, 2.9),
         ("a6", "revolute", [0, 0, 1.033], [0, -1, 0], -0.02, 3.75),
         ("a7", "revolute", [0, 0, 1.033], [1, 0, 0], -2.9, 2.9)]
write("seven_dof", seven, ([0.107, 0, 1.033], rot_axis([0, 1, 0], math.pi / 2)), frames="random",
      comment="7 joints, elbow offsets, spherical wrist (axes 5-7 meet), frames at random.")
desk = [("base_yaw", "revolute", [0, 0, 0.05], [0, 0, 1], -2.0, 2.0),
        ("shoulder", "revolute", [0.03, 0, 0.12], [0, 1, 0], -1.7, 1.7),
        ("elbow", "revolute", [0.058, 0, 0.236], [0, 1, 0], -1.7, 1.6),
        ("wrist_pitch", "revolute", [0.19, 0, 0.22], [0, 1, 0], -1.8, 1.8),
        ("wrist_roll", "revolute", [0.25, 0, 0.22], [1, 0, 0], -2.8, 2.8)]
write("desktop5", desk, ([0.33, 0, 0.22], I3), comment="5-joint desktop arm (yaw, three pitches, roll).")
pris = [("rail", "prismatic", [0, 0, 0], [1, 0, 0], 0, 1.5),
        ("arm1", "revolute", [0.2, 0, 0.4], [0, 0, 1], -2.5, 2.5),
        ("arm2", "revolute", [0.55, 0.05, 0.4], [0, 0, 1], -2.5, 2.5),
        ("lift", "prismatic", [0.8, 0.05, 0.38], [0, 0, -1], 0, 0.2),
        ("spin", "revolute", [0.8, 0.05, 0.2], [0, 0, 1], -6.0, 6.0)]
write("prismatic", pris, ([0.8, 0.05, 0.15], rot_axis([1, 0, 0], math.pi)), frames="about_axis",
      comment="a SCARA on a linear rail: prismatic joints 1 and 4.")
