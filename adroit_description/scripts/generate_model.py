#!/usr/bin/python3
"""Generates every ADROIT model file from one kinematic description.

The kinematic tree below (bodies, joints, inertias, collision capsules, tendon routing) is the
single source of truth. From it this script writes
  mjcf/<scene>.xml           simulation model of each scene (MuJoCo 2.2)
  mjcf/<scene>_planning.xml  the same scene with the planning extras of thesis Table 6.1
                             (rest-pose springs, armature) and no joint friction loss
  urdf/<scene>.urdf          the robot of that scene for robot_state_publisher / rviz
so the two formats cannot drift apart. Numbers come from shared/reference/adroit-kinematics.md
(public ADROIT model facts) and the dissertation; the arm geometry is not published anywhere
and is our own assumption (documented in the package README).

Usage: generate_model.py <output_dir> [<catalogue_header.h>]
The cylinder catalogue and atmospheric pressure come from config/cylinders.yaml; with a second
argument the script also writes them as the C++ header adroit_description/cylinder_catalogue_data.h.
"""
import math
import os
import sys
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np
import yaml

# ----------------------------------------------------------------------------- math helpers

def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def quat_to_mat(q):
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def euler_xyz_to_quat(rx, ry, rz):
    """Quaternion of intrinsic x-y-z rotations (MuJoCo's default eulerseq 'xyz')."""
    def axis_quat(axis, a):
        s = math.sin(a / 2)
        return np.array([math.cos(a / 2)] + [s * c for c in axis])
    return quat_mul(quat_mul(axis_quat((1, 0, 0), rx), axis_quat((0, 1, 0), ry)), axis_quat((0, 0, 1), rz))


def quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])


def mat_to_rpy(m):
    """URDF roll-pitch-yaw (fixed-axis x, then y, then z) of a rotation matrix."""
    pitch = math.asin(max(-1.0, min(1.0, -m[2, 0])))
    if abs(math.cos(pitch)) > 1e-9:
        roll = math.atan2(m[2, 1], m[2, 2])
        yaw = math.atan2(m[1, 0], m[0, 0])
    else:  # gimbal lock: put everything into yaw
        roll = 0.0
        yaw = math.atan2(-m[0, 1], m[1, 1])
    return roll, pitch, yaw


def fmt(values, digits=9):
    out = []
    for v in np.atleast_1d(values):
        s = f"{float(v):.{digits}f}".rstrip("0").rstrip(".")
        out.append("0" if s in ("-0", "") else s)
    return " ".join(out)


def rotation_z_to(direction):
    """Quaternion turning +z onto `direction` (for URDF cylinders along a capsule axis)."""
    d = unit(direction)
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(z, d))
    if c > 1 - 1e-12:
        return np.array([1.0, 0, 0, 0])
    if c < -1 + 1e-12:
        return np.array([0.0, 1, 0, 0])
    axis = unit(np.cross(z, d))
    a = math.acos(c)
    return np.concatenate([[math.cos(a / 2)], math.sin(a / 2) * axis])

# ----------------------------------------------------------------------------- model data

SUPPLY = 620e3          # Pa absolute, thesis fig. 5.9

# Cylinder catalogue and atmospheric pressure: config/cylinders.yaml is their one source. This
# script reads it for the model and writes it out as a C++ header for the C++ libraries
# (see write_catalogue_header), so Python and C++ cannot disagree.
CATALOGUE_FIELDS = ("type", "bore_diameter", "stroke", "dead_volume", "leak_diameter", "valve", "valve_scale")


def find_catalogue():
    """config/cylinders.yaml beside the source tree's scripts/ or in the installed share/."""
    here = os.path.dirname(os.path.abspath(__file__))
    for path in (os.path.join(here, "..", "config", "cylinders.yaml"),
                 os.path.join(here, "..", "..", "share", "adroit_description", "config", "cylinders.yaml")):
        if os.path.exists(path):
            return os.path.normpath(path)
    sys.exit("generate_model.py: config/cylinders.yaml not found beside scripts/ nor in share/")


def load_catalogue(path):
    """(atmospheric pressure [Pa], {type: entry dict}) from the YAML file, checked."""
    with open(path) as f:
        data = yaml.safe_load(f)
    atm = float(data["atmospheric_pressure"])
    if not atm > 0:
        raise ValueError(f"{path}: atmospheric_pressure must be > 0")
    catalogue = {}
    for entry in data["cylinders"]:
        missing = [k for k in CATALOGUE_FIELDS if k not in entry]
        if missing or entry["type"] in catalogue:
            raise ValueError(f"{path}: cylinder {entry.get('type')}: missing {missing} or duplicate type")
        for k in ("bore_diameter", "stroke", "dead_volume", "leak_diameter", "valve_scale"):
            entry[k] = float(entry[k])
            if not entry[k] > 0:
                raise ValueError(f"{path}: cylinder {entry['type']}: {k} must be > 0")
        catalogue[str(entry["type"])] = entry
    return atm, catalogue


ATM, CYLINDER_CATALOGUE = load_catalogue(find_catalogue())
# bore diameter, stroke [m] per type: what the model itself carries (actuator user data).
CYLINDERS = {t: (c["bore_diameter"], c["stroke"]) for t, c in CYLINDER_CATALOGUE.items()}


def write_catalogue_header(path):
    """The catalogue as C++ constants (included by adroit_description/cylinder_catalogue.h)."""
    rows = [f'    CylinderType{{"{t}", {c["bore_diameter"]!r}, {c["stroke"]!r}, {c["dead_volume"]!r}, '
            f'{c["leak_diameter"]!r}, {int(c["valve"])}, {c["valve_scale"]!r}}},'
            for t, c in CYLINDER_CATALOGUE.items()]
    text = "\n".join([
        "// GENERATED by adroit_description/scripts/generate_model.py from config/cylinders.yaml: do not edit.",
        "// Included by adroit_description/cylinder_catalogue.h, which declares CylinderType.",
        "#pragma once",
        "",
        "namespace adroit {",
        "namespace description {",
        "",
        f"constexpr double kAtmosphericPressure = {ATM!r};  // Pa absolute",
        "",
        f"constexpr CylinderType kCylinderCatalogue[{len(rows)}] = {{",
        *rows,
        "};",
        "",
        "}  // namespace description",
        "}  // namespace adroit",
        ""])
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)


def max_tension(cyl):
    bore, _ = CYLINDERS[cyl]
    return (SUPPLY - ATM) * math.pi * bore * bore / 4


@dataclass
class Joint:
    name: str
    axis: Tuple[float, float, float]
    range: Tuple[float, float]
    moment_arm: float = 0.0          # tendon moment arm [m]; 0 = not actuated (coupled DIP)
    cylinder: str = "M9"
    flex_sign: int = 1               # +1: flexion is the positive direction; THJ0 flexes negative
    kind: str = "bend"               # bend: axis across the segment; roll: axis along it
    damping: float = 0.05
    armature: float = 0.001
    frictionloss: float = 0.001
    plan_spring: float = 0.0         # thesis Table 6.1 spring constant [N m / rad]
    plan_armature: float = 0.06      # thesis Table 6.1 armature [kg m^2]
    rest: float = 0.0                # rest pose of the planning springs [rad]


@dataclass
class Capsule:
    name: str
    p1: Tuple[float, float, float]
    p2: Tuple[float, float, float]
    radius: float
    condim: int = 3


@dataclass
class Box:
    name: str
    pos: Tuple[float, float, float]
    half: Tuple[float, float, float]


@dataclass
class Site:
    name: str
    pos: Tuple[float, float, float]
    half: Optional[Tuple[float, float, float]] = None   # box touch zone when set


@dataclass
class Body:
    name: str
    pos: Tuple[float, float, float]
    quat: Tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    joint: Optional[Joint] = None
    mass: float = 0.0
    com: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: Tuple[float, float, float] = (1e-5, 1e-5, 1e-5)
    geoms: List[object] = field(default_factory=list)
    sites: List[Site] = field(default_factory=list)
    children: List["Body"] = field(default_factory=list)
    segment: Tuple[float, float, float] = (0.0, 0.0, 1.0)   # direction of the link, body frame
    rgba: str = "0.75 0.75 0.78 1"


def capsule_z(name, radius, half, centre_z, condim=3):
    return Capsule(name, (0, 0, centre_z - half), (0, 0, centre_z + half), radius, condim)


WRIST = dict(damping=0.5, armature=0.005, frictionloss=0.001)


def finger(prefix, knuckle_pos, metacarpal=False):
    """FF/MF/RF pattern (LF adds the metacarpal). Returns the top body."""
    p = prefix.upper()
    distal = Body(f"{prefix}distal", (0, 0, 0.025),
                  joint=Joint(f"{p}J0", (1, 0, 0), (0, 1.571), plan_spring=0.15, rest=0.3),
                  mass=0.010, com=(0, 0, 0.015),
                  geoms=[capsule_z(f"C_{prefix}distal", 0.00705, 0.012, 0.012, condim=6)],
                  sites=[Site(f"S_{prefix}tip", (0, 0, 0.026)),
                         Site(f"Tch_{prefix}tip", (0, -0.004, 0.018), (0.009, 0.004, 0.013))])
    middle = Body(f"{prefix}middle", (0, 0, 0.045),
                  joint=Joint(f"{p}J1", (1, 0, 0), (0, 1.571), moment_arm=0.00805,
                              plan_spring=0.10, rest=0.3),
                  mass=0.012, com=(0, 0, 0.011 if prefix == "ff" else 0.012),
                  geoms=[capsule_z(f"C_{prefix}middle", 0.00805, 0.0125, 0.0125)],
                  sites=[Site(f"Tch_{prefix}middle", (0, -0.007, 0.013), (0.009, 0.002, 0.007))],
                  children=[distal])
    proximal = Body(f"{prefix}proximal", (0, 0, 0),
                    joint=Joint(f"{p}J2", (1, 0, 0), (0, 1.571), moment_arm=0.010,
                                plan_spring=0.05, rest=0.3),
                    mass=0.014, com=(0, 0, 0.023),
                    geoms=[capsule_z(f"C_{prefix}proximal", 0.010, 0.0225, 0.0225)],
                    sites=[Site(f"Tch_{prefix}proximal", (0, -0.007, 0.022), (0.009, 0.004, 0.012))],
                    children=[middle])
    knuckle = Body(f"{prefix}knuckle", knuckle_pos,
                   joint=Joint(f"{p}J3", (0, 1, 0), (-0.436, 0.436), moment_arm=0.010,
                               plan_spring=0.20),
                   mass=0.008, children=[proximal])
    return knuckle


def little_finger():
    knuckle = finger("lf", (-0.017, 0, 0.044))
    return Body("lfmetacarpal", (-0.017, 0, 0.044),
                joint=Joint("LFJ4", tuple(unit((0.571, 0, 0.821))), (0, 0.698), moment_arm=0.010,
                            plan_spring=0.15),
                mass=0.075, com=(-0.014, 0.001, 0.014),
                geoms=[Box("C_lfmetacarpal", (-0.0165, 0, 0.010), (0.0095, 0.0111, 0.025))],
                sites=[Site("Tch_lfmetacarpal", (-0.016, -0.008, 0.017), (0.009, 0.004, 0.014))],
                segment=(-0.017, 0, 0.044), children=[knuckle])


def thumb():
    thdistal = Body("thdistal", (0, 0, 0.032),
                    joint=Joint("THJ0", (0, 1, 0), (-1.571, 0), moment_arm=0.009, flex_sign=-1,
                                plan_spring=0.15, rest=-0.3),
                    mass=0.016, com=(0, 0, 0.016),
                    geoms=[capsule_z("C_thdistal", 0.00918, 0.013, 0.013, condim=6)],
                    sites=[Site("S_thtip", (0, 0, 0.0275)),
                           Site("Tch_thtip", (-0.005, 0, 0.020), (0.005, 0.011, 0.016))])
    thmiddle = Body("thmiddle", (0, 0, 0),
                    joint=Joint("THJ1", (0, 1, 0), (-0.524, 0.524), moment_arm=0.011,
                                plan_spring=0.15),
                    mass=0.016, com=(0, 0, 0.016),
                    geoms=[capsule_z("C_thmiddle", 0.011, 0.016, 0.016)],
                    sites=[Site("Tch_thmiddle", (-0.008, 0, 0.018), (0.005, 0.011, 0.011))],
                    children=[thdistal])
    thhub = Body("thhub", (0, 0, 0.038),
                 joint=Joint("THJ2", (1, 0, 0), (-0.262, 0.262), moment_arm=0.011,
                             plan_spring=0.15),
                 mass=0.002, children=[thmiddle])
    thproximal = Body("thproximal", (0, 0, 0),
                      joint=Joint("THJ3", (1, 0, 0), (0, 1.309), moment_arm=0.010,
                                  plan_spring=0.05, rest=0.3),
                      mass=0.016, com=(0, 0, 0.017),
                      geoms=[capsule_z("C_thproximal", 0.013, 0.019, 0.019)],
                      sites=[Site("Tch_thproximal", (-0.008, 0, 0.022), (0.005, 0.011, 0.011))],
                      children=[thhub])
    return Body("thbase", (0.034, -0.009, 0.029), quat=tuple(euler_xyz_to_quat(0, 0.785, 0)),
                joint=Joint("THJ4", (0, 0, -1), (-1.047, 1.047), moment_arm=0.01636, kind="roll",
                            plan_spring=0.05),
                mass=0.010, children=[thproximal])


def forearm(with_roll_joint):
    palm = Body("palm", (0, 0, 0.034),
                joint=Joint("WRJ0", (1, 0, 0), (-0.785, 0.611), moment_arm=0.018, cylinder="M16",
                            plan_spring=0.05, **WRIST),
                mass=0.3, com=(0.006, 0, 0.036), inertia=(0.001, 0.001, 0.001),
                geoms=[Box("C_palm0", (0.011, 0, 0.038), (0.032, 0.0111, 0.049)),
                       Box("C_palm1", (-0.032, 0, 0.014), (0.011, 0.0111, 0.025))],
                sites=[Site("S_grasp", (0.007, -0.05, 0.07)),
                       Site("Tch_palm", (0.011, -0.008, 0.050), (0.030, 0.004, 0.035))],
                children=[finger("ff", (0.033, 0, 0.095)), finger("mf", (0.011, 0, 0.099)),
                          finger("rf", (-0.011, 0, 0.095)), little_finger(), thumb()])
    wrist = Body("wrist", (0, 0, 0.256),
                 joint=Joint("WRJ1", (0, 1, 0), (-0.524, 0.175), moment_arm=0.018, cylinder="M16",
                             plan_spring=0.05, **WRIST),
                 mass=0.3, com=(0.003, 0, 0.016), inertia=(0.001, 0.001, 0.001),
                 geoms=[Capsule("C_wrist", (0, -0.010, 0), (0, 0.010, 0), 0.015)],
                 children=[palm])
    # Elbow roll turns the forearm about its own long axis (arm-hand variant only).
    roll = (Joint("ARJ0", (0, 0, 1), (-1.3, 1.3), moment_arm=0.020, cylinder="M24", kind="roll",
                  damping=2.0, armature=0.01, plan_armature=0.03)
            if with_roll_joint else None)
    return Body("forearm", (0, 0, 0), joint=roll, mass=4.0, com=(0.001, -0.002, 0.20),
                inertia=(0.01, 0.01, 0.0075),
                geoms=[capsule_z("C_forearm", 0.040, 0.070, 0.13)], children=[wrist],
                rgba="0.35 0.38 0.42 1")


# Teleop scenes: the hand base's free joint and the mocap body it is welded to.
HAND_BASE_JOINT = "hand_base"
HAND_BASE_TARGET = "hand_base_target"

# Forearm orientations in the world (euler xyz): the forearm's +z points along world +y.
PALM_DOWN = (-1.5708, 0, 3.14159)
PALM_UP = (-1.5708, 0, 0)
PALM_UP_TILTED_30 = (-1.5708 - math.radians(30), 0, 0)   # thesis 8.4.2: the rotation tasks' hand
# Thesis 10.2: the hand mounted about 30 degrees to the horizontal, fingers pointing down
# towards the table, palm down over the tube.
PALM_DOWN_TILTED_30 = (-1.5708 - math.radians(30), 0, 3.14159)


def arm_and_hand(forearm_euler=PALM_DOWN):
    """4-DOF arm (thesis Table 6.1 joint names) carrying the hand. Link lengths are ours.
    forearm_euler: how the hand is mounted on the elbow roll (palm down or up at ARJ0 = 0)."""
    fa = forearm(with_roll_joint=True)
    fa.pos = (0, 0.05, 0)
    fa.quat = tuple(euler_xyz_to_quat(*forearm_euler))
    elbow = Body("arm_elbow", (0, 0.30, 0),
                 joint=Joint("ARJ1", (1, 0, 0), (-1.0, 1.0), moment_arm=0.040, cylinder="M40",
                             damping=5.0, armature=0.05, plan_armature=0.45),
                 mass=0.5, com=(0, 0.025, 0), inertia=(5e-4, 5e-4, 5e-4),
                 geoms=[Capsule("C_arm_elbow", (-0.03, 0, 0), (0.03, 0, 0), 0.035)],
                 segment=(0, 1, 0), children=[fa], rgba="0.35 0.38 0.42 1")
    upper = Body("arm_upper", (0, 0, 0.30),
                 joint=Joint("ARJ2", (1, 0, 0), (-0.9, 0.6), moment_arm=0.055, cylinder="M24x5",
                             damping=5.0, armature=0.05, plan_armature=2.40),
                 mass=2.0, com=(0, 0.15, 0), inertia=(0.016, 0.002, 0.016),
                 geoms=[Capsule("C_arm_upper", (0, 0.04, 0), (0, 0.26, 0), 0.045)],
                 segment=(0, 1, 0), children=[elbow], rgba="0.35 0.38 0.42 1")
    trunk = Body("arm_trunk", (0, 0, 0.05),
                 joint=Joint("ARJ3", (0, 0, 1), (-1.3, 1.3), moment_arm=0.022, cylinder="M24",
                             kind="roll", damping=5.0, armature=0.05, plan_armature=0.60),
                 mass=3.0, com=(0, 0, 0.15), inertia=(0.03, 0.03, 0.006),
                 geoms=[capsule_z("C_arm_trunk", 0.05, 0.11, 0.15)],
                 children=[upper], rgba="0.35 0.38 0.42 1")
    return Body("arm_base", (0, 0, 0), mass=2.0, inertia=(0.01, 0.01, 0.01),
                geoms=[Box("C_arm_base", (0, 0, 0.025), (0.07, 0.07, 0.025))],
                children=[trunk], rgba="0.35 0.38 0.42 1")


def walk(body, parent=None):
    yield body, parent
    for c in body.children:
        yield from walk(c, body)

# ----------------------------------------------------------------------------- tendon routing

@dataclass
class Tendon:
    name: str            # T_<joint>_<role>
    joint: str
    role: str            # flex | ext
    cylinder: str
    path: list           # [("site", name) | ("geom", name, sidesite)]
    spans: list          # [(joint name, moment arm)] the tendon acts on


def route_tendons(root):
    """Adds routing sites and wrap cylinders to the bodies and returns the tendons.

    Every actuated joint gets an antagonistic pair. A tendon runs from a site on the parent
    link, around a wrapping cylinder coaxial with the joint (radius = moment arm), to a site on
    the child link, so MuJoCo computes a near-constant moment arm with the right sign:
      bend joints (axis across the link): both tendons pull back along the link, on opposite
        sides of the axis; the flexor sits on the side the joint's positive rotation moves to.
      roll joints (axis along the link): both wind around the axis in opposite senses.
    The finger J1 tendons continue over the DIP (J0) to the distal link, as in the hand.
    """
    bodies = {b.name: (b, p) for b, p in walk(root)}
    tendons = []

    def lever(r):
        # Routing sites sit well away from the wrap cylinder (>= 2.5 r from the pivot): close
        # to it, MuJoCo's choice of wrapping side stops following the side site.
        return max(0.012, 2.5 * r)

    def add_wrap(body, joint, r):
        existing = [g for g in body.geoms if g.name == f"W_{joint.name}"]
        if existing:  # the J0 wrap is shared by the flexor and the extensor of J1
            return existing[0].name
        a = np.asarray(joint.axis, float)
        geom = Capsule(f"W_{joint.name}", tuple(-0.004 * a), tuple(0.004 * a), r)
        geom.wrap = True
        body.geoms.append(geom)
        return geom.name

    def add_site(body, name, pos_in_body):
        body.sites.append(Site(name, tuple(np.round(pos_in_body, 6))))
        return name

    def to_parent(child, p):
        """Point given in the child frame at zero pose -> parent body frame."""
        return np.asarray(child.pos) + quat_to_mat(child.quat) @ np.asarray(p)

    def bend_frame(body, joint):
        a = unit(joint.axis)
        s = np.asarray(body.segment, float)
        s = unit(s - np.dot(s, a) * a)
        n = unit(np.cross(a, s))          # positive rotation moves the link towards n
        return a, s, n

    for body, parent in walk(root):
        j = body.joint
        if j is None or j.moment_arm == 0:
            continue
        r = j.moment_arm
        wrap = add_wrap(body, j, r)
        for role, sign in (("flex", j.flex_sign), ("ext", -j.flex_sign)):
            tname = f"T_{j.name}_{role}"
            spans = [(j.name, r)]
            if j.kind == "bend":
                a, s, n = bend_frame(body, j)
                side = sign * n
                start = add_site(parent, f"R_{j.name}_{role}0", to_parent(body, side * 0.8 * r - lever(r) * s))
                sidesite = add_site(body, f"R_{j.name}_{role}_side", side * 2.0 * r)
                path = [("site", start), ("geom", wrap, sidesite)]
                if j.name.endswith("J1") and j.name[:2] in ("FF", "MF", "RF", "LF"):
                    # continue over the DIP: a site on the middle link, wrap at J0, end on distal
                    distal = body.children[0]
                    j0 = distal.joint
                    r0 = 0.00705
                    wrap0 = add_wrap(distal, j0, r0)
                    mid = add_site(body, f"R_{j.name}_{role}1",
                                   side * 0.8 * r0 + (np.asarray(distal.pos) - 0.5 * np.asarray(distal.pos)))
                    side0 = add_site(distal, f"R_{j.name}_{role}_side0", side * 2.0 * r0)
                    end = add_site(distal, f"R_{j.name}_{role}2", side * 0.8 * r0 + lever(r0) * s)
                    path += [("site", mid), ("geom", wrap0, side0), ("site", end)]
                    spans.append((j0.name, r0))
                else:
                    end = add_site(body, f"R_{j.name}_{role}1", side * 0.8 * r + lever(r) * s)
                    path.append(("site", end))
            else:  # roll
                a = unit(j.axis)
                helper = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
                n = unit(np.cross(a, helper))          # tangent point (lever) direction
                e2 = unit(np.cross(a, n))              # positive rotation turns n towards e2
                # The tendon leaves the cylinder tangentially at n towards the parent site and is
                # pre-wound around the cylinder to the child site, by more than the joint can
                # unwind it, so the moment arm stays r over the whole range. MuJoCo follows the
                # side site reliably only for wrap arcs of about 0.4 to 3.4 rad, so a roll joint's
                # range must stay within about 2.8 rad (hence the +-1.3 rad arm roll joints).
                limit = j.range[1] if sign > 0 else -j.range[0]
                wound = limit + 0.5

                def around(angle, radius):
                    return radius * (math.cos(angle) * n + math.sin(angle) * e2)
                end = add_site(body, f"R_{j.name}_{role}1", around(-sign * wound, 1.05 * r))
                start = add_site(parent, f"R_{j.name}_{role}0", to_parent(body, r * n + sign * 0.06 * e2))
                sidesite = add_site(body, f"R_{j.name}_{role}_side", around(-sign * wound / 2, 2.0 * r))
                path = [("site", start), ("geom", wrap, sidesite), ("site", end)]
            tendons.append(Tendon(tname, j.name, role, j.cylinder, path, spans))
    return tendons

# ----------------------------------------------------------------------------- scenes

@dataclass
class Scene:
    name: str
    description: str
    arm: bool
    mount_pos: Tuple[float, float, float]
    mount_euler: Tuple[float, float, float]
    objects: str = ""             # extra worldbody XML
    object_qpos: List[float] = field(default_factory=list)
    table_touches_hand: bool = True
    extra_custom: str = ""
    plan_objects: str = ""        # the planning model's objects, when they differ
    forearm_euler: Tuple[float, float, float] = PALM_DOWN  # arm scenes: the hand's mount on the elbow roll
    # Teleop (thesis 9.2.3): the hand's base is free and follows a mocap body through a soft
    # weld, so a motion-capture stream moves it while contacts and joint limits keep priority.
    free_base: bool = False
    # Planning model: > 0 replaces Table 6.1's armature of every joint by this (kg m^2; at least
    # the joint's physical armature), and
    # plan_springs=False leaves its rest-pose springs out (see the keypad scene).
    plan_joint_armature: float = 0.0
    plan_springs: bool = True


FREE_OBJECT_JOINT = '<freejoint name="object_root"/>'


def object_body(pos, inner, quat=(1, 0, 0, 0)):
    return (f'<body name="object" pos="{fmt(pos)}" quat="{fmt(quat)}">{FREE_OBJECT_JOINT}{inner}'
            f'<site name="S_object" pos="0 0 0" size="0.005" rgba="1 0 0 1" group="3"/></body>')


KEY_ARMATURE = 0.001
# Planning variant: the key spring (100 N/m on 5 g + 1 g armature, omega = 129 rad/s) is
# integrated explicitly, which is unstable for omega * dt > 2; at the typing planner's 20 ms
# knots (thesis Table 6.3) omega * dt = 2.6 and a released key gains x3.6 per knot. 50 g of
# armature gives omega * dt = 0.85 (as the hand joints get Table 6.1 armature for the planner).
KEY_PLAN_ARMATURE = 0.05


KEY_PITCH = 0.022  # m between key centres
# y of the row nearest the hand (keys 1 2 3). Every key within the middle three fingertips'
# reach at press height: sampled over the finger joint ranges, the far row (bs 0 ent) was out
# of reach at -0.115 (fingertips reach y <= -0.075 there); 5 cm nearer, each key is reached by
# its column's finger in 65 or more of 600000 configurations, the near row in 260 or more.
KEYPAD_NEAR_ROW_Y = -0.165
# Height of the key centres: the keys sit 7.5 mm above the base, which stands on the table.
KEY_Z = 0.0495
# x of the middle column (2 5 8 0): the columns under the first, middle and ring fingertips
# as they hang at the rest keyframe (x -0.033, -0.011, 0.011).
KEYPAD_MIDDLE_X = -0.011


def keypad_xml(planning=False):
    """A 4 x 3 numeric keypad with spring-loaded keys (thesis 6.5): 6 mm travel, a press
    registers only at >= 5.5 mm (custom numeric keypad_press_depth)."""
    armature = KEY_PLAN_ARMATURE if planning else KEY_ARMATURE
    labels = ["1", "2", "3", "4", "5", "6", "7", "8", "9", "bs", "0", "ent"]
    keys = []
    for i, label in enumerate(labels):
        row, col = divmod(i, 3)
        x = KEYPAD_MIDDLE_X + (col - 1) * KEY_PITCH
        y = KEYPAD_NEAR_ROW_Y + row * KEY_PITCH
        keys.append(
            f'<body name="key_{label}" pos="{fmt((x, y, KEY_Z))}">'
            f'<joint name="KEY_{label}" type="slide" axis="0 0 1" range="-0.006 0" stiffness="100" '
            f'springref="0.004" damping="0.05" armature="{fmt(armature)}"/>'
            f'<geom name="C_key_{label}" type="box" size="0.009 0.009 0.004" mass="0.005" '
            f'rgba="0.9 0.9 0.85 1" contype="1" conaffinity="1" condim="3"/></body>')
    base_y = KEYPAD_NEAR_ROW_Y + 1.5 * KEY_PITCH  # under the middle of the four rows
    base_half_height = (KEY_Z - 0.0115) / 2
    base = ('<body name="keypad" pos="0 0 0"><geom name="C_keypad" type="box" '
            f'pos="{fmt((KEYPAD_MIDDLE_X, base_y, base_half_height))}" '
            f'size="{fmt((0.042, 0.052, base_half_height))}" rgba="0.2 0.2 0.22 1" contype="1" conaffinity="1"/>'
            + "".join(keys) + "</body>")
    return base, labels


# The tube scene's tube at rest on the table, under the proximal phalanges of the palm-up
# zero-pose hand (the rotation tasks start it elsewhere, in the hand).
ROTATION_TUBE_ON_TABLE = (0.0, -0.23, 0.022)

# The pickup scene (thesis 10.2, 11.3): the tube lies on the table under the palm, and its
# initial orientation varies over 180 degrees about its centre, so the zero-pose hand must clear
# a 28 cm tube lying at every yaw. A hand low enough to touch the tube clears it only along x
# (its fingertips hang 7-13 mm above the table at a 25 cm mount); at a 30 cm mount the zero-pose
# hand clears the tube by >= 7.5 mm at every yaw for centres between y -0.20 and -0.29
# (fingertips 6 cm above the table), and the hand reaches it by flexing the wrist (WRJ0) and
# fingers; finger-table contact is off, so the fingers can dig under the tube (10.2).
TUBE_MOUNT = (0, -0.55, 0.30)
# Centre of the tube: under the palm, where the flexed wrist brings the fingertips down in front
# of it and the thumb behind it (the expert's clamp; adroit_teleop pickup_expert).
TUBE_ON_TABLE = (0.0, -0.289, 0.022)
# A coffee-bean tube rolls badly: the beans shift and damp it. Modelled as rolling and torsional
# friction (condim 6); a frictionless-rolling capsule rolled out of every grasp the fingers
# started, pushed away by the first touch.
TUBE_GEOM = ('<geom name="C_object" type="capsule" size="0.022 0.12" quat="0.70711 0 0.70711 0" '
             'mass="0.30" rgba="0.45 0.3 0.15 1" contype="3" conaffinity="3" condim="6" friction="1 0.01 0.01"/>')


def scenes():
    pad, _ = keypad_xml()
    plan_pad, _ = keypad_xml(planning=True)
    return [
        Scene("hand", "hand-only, table mounted palm down, no object", False,
              (0, -0.55, 0.15), PALM_DOWN),
        Scene("arm_hand", "28-DOF arm-hand on the table, no object", True,
              (0, -0.85, 0.0), (0, 0, 0)),
        Scene("tube", "in-hand rotation of a heavy coffee-bean tube (thesis 8.4.2); hand mounted "
              "about 30 deg to the horizontal, palm up; finger-table contact disabled",
              False, (0, -0.55, 0.25), PALM_UP_TILTED_30,
              objects=object_body(ROTATION_TUBE_ON_TABLE,
                                  '<geom name="C_object" type="capsule" size="0.022 0.12" '
                                  'quat="0.70711 0 0.70711 0" mass="0.30" rgba="0.45 0.3 0.15 1" '
                                  'contype="3" conaffinity="3" condim="3"/>'),
              object_qpos=list(ROTATION_TUBE_ON_TABLE) + [1, 0, 0, 0], table_touches_hand=False),
        Scene("pickup", "pickup of a heavy coffee-bean tube from the table at any yaw (thesis 10.2, 11.3); "
              "hand mounted about 30 deg to the horizontal, palm down; finger-table contact disabled",
              False, TUBE_MOUNT, PALM_DOWN_TILTED_30, objects=object_body(TUBE_ON_TABLE, TUBE_GEOM),
              object_qpos=list(TUBE_ON_TABLE) + [1, 0, 0, 0], table_touches_hand=False),
        Scene("bottle", "dynamic manipulation: a bottle dropped onto the palm-up hand", False,
              (0, -0.55, 0.20), PALM_UP,
              objects=object_body((0.007, -0.19, 0.31),
                                  '<geom name="C_object" type="cylinder" size="0.03 0.08" '
                                  'quat="0.70711 0 0.70711 0" mass="0.25" rgba="0.2 0.5 0.8 1" '
                                  'contype="1" conaffinity="1" condim="3"/>'),
              object_qpos=[0.007, -0.19, 0.31, 1, 0, 0, 0]),
        # Relocation starts as a dynamic stabilisation (thesis 6.5): the ball is dropped into
        # the hand. The elbow roll (+-1.3 rad; pi would need more than the M24's stroke) cannot
        # turn the palm up, so this scene mounts the hand palm up on the forearm.
        Scene("ball", "object relocation with the arm: a ball dropped into the palm-up hand", True,
              (0, -0.85, 0.0), (0, 0, 0), forearm_euler=PALM_UP,
              objects=object_body((0.007, -0.14, 0.48),
                                  '<geom name="C_object" type="sphere" size="0.035" mass="0.18" '
                                  'rgba="0.85 0.3 0.2 1" contype="1" conaffinity="1" condim="3"/>')
              + '<site name="S_target" pos="0 0 0.2" size="0.035" rgba="0 1 0 0.3" group="2"/>',
              object_qpos=[0.007, -0.14, 0.48, 1, 0, 0, 0]),
        Scene("keypad", "typing on a numeric keypad with spring-loaded keys (thesis 6.5)", False,
              (0, -0.55, 0.12), PALM_DOWN, objects=pad,
              extra_custom='<numeric name="keypad_press_depth" data="0.0055"/>', plan_objects=plan_pad,
              # The planner's fingers must move like the simulated ones to land on a 22 mm key:
              # with Table 6.1's armature (60 times the physical 0.001) and springs, tensions
              # planned for heavy sprung fingers flung the light ones into the neighbouring keys
              # (0 of 30 keys; 29 of 30 against a world that runs the planning model). Light
              # fingers need the typing planner's 10 ms knots (adroit_mpc README, typing).
              plan_joint_armature=0.003, plan_springs=False),
        # Glove teleop (thesis ch. 9, 10.3): the hand hangs palm down over the object, its base
        # welded to the mocap body hand_base_target; the operator reaches, grasps and lifts.
        Scene("teleop_tube", "glove teleop: free hand base on a mocap weld, the tube lying on the table",
              False, (0, -0.55, 0.15), PALM_DOWN, free_base=True,
              objects=object_body((0, -0.16, 0.022),
                                  '<geom name="C_object" type="capsule" size="0.022 0.12" '
                                  'quat="0.70711 0 0.70711 0" mass="0.30" rgba="0.45 0.3 0.15 1" '
                                  'contype="3" conaffinity="3" condim="3"/>'),
              object_qpos=[0, -0.16, 0.022, 1, 0, 0, 0]),
        Scene("teleop_ball", "glove teleop: free hand base on a mocap weld, a ball resting on the table",
              False, (0, -0.55, 0.15), PALM_DOWN, free_base=True,
              objects=object_body((0.0, -0.17, 0.035),
                                  '<geom name="C_object" type="sphere" size="0.035" mass="0.18" '
                                  'rgba="0.85 0.3 0.2 1" contype="1" conaffinity="1" condim="3"/>'),
              object_qpos=[0.0, -0.17, 0.035, 1, 0, 0, 0]),
    ]

# ----------------------------------------------------------------------------- MJCF writer

SELF_PAIRS = [  # explicit inter-finger contacts, condim 1 (thesis 6.4.3)
    ("C_thdistal", "C_ffdistal"), ("C_thdistal", "C_ffmiddle"), ("C_thdistal", "C_ffproximal"),
    ("C_thdistal", "C_mfproximal"), ("C_thdistal", "C_mfdistal"), ("C_thdistal", "C_rfdistal"),
    ("C_thdistal", "C_lfdistal"), ("C_thdistal", "C_palm0"),
    ("C_ffdistal", "C_mfdistal"), ("C_mfdistal", "C_rfdistal"), ("C_rfdistal", "C_lfdistal"),
    ("C_ffproximal", "C_mfproximal"), ("C_mfproximal", "C_rfproximal"),
    ("C_rfproximal", "C_lfproximal"), ("C_lfdistal", "C_mfdistal"), ("C_lfdistal", "C_rfmiddle"),
    ("C_lfmiddle", "C_rfdistal"), ("C_lfmiddle", "C_rfmiddle"),
]


class Mjcf:
    def __init__(self, scene: Scene, planning: bool):
        self.scene = scene
        self.planning = planning
        if scene.arm:
            self.root = arm_and_hand(scene.forearm_euler)
        else:
            self.root = forearm(with_roll_joint=False)
        self.root.pos = scene.mount_pos
        self.root.quat = tuple(euler_xyz_to_quat(*scene.mount_euler))
        self.tendons = route_tendons(self.root)
        self.joints = [b.joint for b, _ in walk(self.root) if b.joint]

    def joint_xml(self, j: Joint):
        damping, armature = j.damping, (j.plan_armature if self.planning else j.armature)
        if self.planning and self.scene.plan_joint_armature > 0:  # never lighter than the physical joint
            armature = max(j.armature, self.scene.plan_joint_armature)
        # The planning model has no friction loss: each joint's loss is a constraint row of its
        # own in every step, and the finite-difference derivatives of a step with contacts cost
        # three times as much with them (typing: 85 against 29 ms per iteration) for a torque of
        # 0.001 N m, against tendon torques of up to 0.3 N m.
        frictionloss = 0.0 if self.planning else j.frictionloss
        attrs = (f'name="{j.name}" type="hinge" axis="{fmt(j.axis)}" range="{fmt(j.range)}" '
                 f'damping="{fmt(damping)}" armature="{fmt(armature)}" '
                 f'frictionloss="{fmt(frictionloss)}" margin="0.01"')
        if self.planning and self.scene.plan_springs and j.plan_spring > 0:
            attrs += f' stiffness="{fmt(j.plan_spring)}" springref="{fmt(j.rest)}"'
        return f"<joint {attrs}/>"

    def body_xml(self, b: Body, depth):
        ind = "  " * depth
        hand_collision = 'contype="1" conaffinity="0"'
        out = [f'{ind}<body name="{b.name}" pos="{fmt(b.pos)}" quat="{fmt(b.quat)}">']
        out.append(f'{ind}  <inertial pos="{fmt(b.com)}" mass="{fmt(b.mass)}" diaginertia="{fmt(b.inertia)}"/>')
        if b is self.root and self.scene.free_base:
            out.append(f'{ind}  <freejoint name="{HAND_BASE_JOINT}"/>')
        if b.joint:
            out.append(f"{ind}  {self.joint_xml(b.joint)}")
        for g in b.geoms:
            if getattr(g, "wrap", False):
                out.append(f'{ind}  <geom name="{g.name}" type="cylinder" fromto="{fmt(g.p1)} {fmt(g.p2)}" '
                           f'size="{fmt(g.radius)}" contype="0" conaffinity="0" group="4" mass="0" '
                           f'rgba="0.9 0.7 0.2 0.4"/>')
            elif isinstance(g, Capsule):
                out.append(f'{ind}  <geom name="{g.name}" type="capsule" fromto="{fmt(g.p1)} {fmt(g.p2)}" '
                           f'size="{fmt(g.radius)}" {hand_collision} condim="{g.condim}" rgba="{b.rgba}"/>')
            else:
                out.append(f'{ind}  <geom name="{g.name}" type="box" pos="{fmt(g.pos)}" size="{fmt(g.half)}" '
                           f'{hand_collision} condim="3" rgba="{b.rgba}"/>')
        for s in b.sites:
            if s.half:
                out.append(f'{ind}  <site name="{s.name}" type="box" pos="{fmt(s.pos)}" size="{fmt(s.half)}" '
                           f'group="3" rgba="0.2 0.8 0.2 0.3"/>')
            elif s.name.startswith("R_"):
                out.append(f'{ind}  <site name="{s.name}" pos="{fmt(s.pos)}" size="0.0015" group="4" rgba="0.9 0.7 0.2 1"/>')
            else:
                out.append(f'{ind}  <site name="{s.name}" pos="{fmt(s.pos)}" size="0.004" group="3" rgba="0.9 0.2 0.2 1"/>')
        for c in b.children:
            out.extend(self.body_xml(c, depth + 1))
        out.append(f"{ind}</body>")
        return out

    def keyframe_qpos(self, robot_q):
        """qpos of a keyframe: the hand base's free joint (teleop scenes), the robot's joints,
        then the object's free joint, then keys."""
        base = (list(self.scene.mount_pos) + list(euler_xyz_to_quat(*self.scene.mount_euler))
                if self.scene.free_base else [])
        q = base + list(robot_q) + list(self.scene.object_qpos)
        if self.scene.name == "keypad":
            q += [0.0] * 12
        return q

    def write(self):
        s = self.scene
        table_contact = 'contype="1" conaffinity="1"' if s.table_touches_hand else 'contype="2" conaffinity="2"'
        if not self.planning:
            variant = "simulation model"
        elif s.plan_joint_armature > 0:
            variant = (f"planning model (joint armature {fmt(s.plan_joint_armature)}"
                       f"{'' if s.plan_springs else ', no springs'}, no friction loss)")
        else:
            variant = "planning model (thesis Table 6.1 springs and armature, no friction loss)"
        lines = [
            f"<!-- GENERATED by adroit_description/scripts/generate_model.py: do not edit. -->",
            f'<mujoco model="adroit_{s.name}{"_planning" if self.planning else ""}">',
            f"  <!-- {s.description}; {variant} -->",
            '  <compiler angle="radian" autolimits="true"/>',
            '  <option timestep="0.002" iterations="20" cone="pyramidal" impratio="1"/>',
            '  <size nuser_actuator="2"/>',
            '  <statistic center="0 -0.25 0.15" extent="0.35"/>',
            '  <visual><headlight ambient="0.4 0.4 0.4" diffuse="0.6 0.6 0.6"/><quality shadowsize="2048"/></visual>',
            "  <default>",
            '    <geom friction="1 0.005 0.001" margin="0.0005" solref="0.01 1"/>',
            "  </default>",
            "  <worldbody>",
            '    <light name="top" pos="0 -0.3 1.5" dir="0 0 -1" directional="true"/>',
            '    <geom name="floor" type="plane" pos="0 0 -0.75" size="2 2 0.1" rgba="0.6 0.6 0.6 1" contype="1" conaffinity="1"/>',
            f'    <geom name="table" type="box" pos="0 0 -0.025" size="0.45 0.45 0.025" rgba="0.55 0.45 0.35 1" {table_contact} condim="3"/>',
        ]
        if s.arm:
            lines.append(f'    <geom name="C_pedestal" type="box" pos="{fmt((s.mount_pos[0], s.mount_pos[1], -0.375))}" '
                         'size="0.08 0.08 0.375" rgba="0.3 0.3 0.32 1" contype="0" conaffinity="0"/>')
        lines.extend(self.body_xml(self.root, 2))
        objects = s.plan_objects if self.planning and s.plan_objects else s.objects
        if objects:
            lines.append("    " + objects)
        if s.free_base:
            lines.append(f'    <body name="{HAND_BASE_TARGET}" mocap="true" pos="{fmt(s.mount_pos)}" '
                         f'quat="{fmt(euler_xyz_to_quat(*s.mount_euler))}">'
                         '<site name="S_hand_base_target" size="0.01" rgba="0 0.8 0.2 0.5" group="2"/></body>')
        lines.append("  </worldbody>")
        if s.free_base:
            # A soft weld (time constant 20 ms, twice the contacts' 10 ms): the base follows the
            # mocap body closely, but contacts win when the operator pushes the hand into the table.
            lines.append("  <equality>")
            lines.append(f'    <weld name="hand_base_weld" body1="{HAND_BASE_TARGET}" body2="{self.root.name}" '
                         'solref="0.02 1"/>')
            lines.append("  </equality>")

        lines.append("  <contact>")
        for a, b in SELF_PAIRS:
            lines.append(f'    <pair geom1="{a}" geom2="{b}" condim="1"/>')
        lines.append("  </contact>")

        lines.append("  <tendon>")
        for f in ("FF", "MF", "RF", "LF"):
            # DIP-PIP coupling (thesis 6.3): J0 stays within a band around 1.14 * J1.
            lines.append(f'    <fixed name="T_{f}J1c" limited="true" range="-0.001 0.001">'
                         f'<joint joint="{f}J0" coef="0.00705"/><joint joint="{f}J1" coef="-0.00805"/></fixed>')
        for t in self.tendons:
            parts = []
            for p in t.path:
                if p[0] == "site":
                    parts.append(f'<site site="{p[1]}"/>')
                else:
                    parts.append(f'<geom geom="{p[1]}" sidesite="{p[2]}"/>')
            lines.append(f'    <spatial name="{t.name}" width="0.001" rgba="0.9 0.7 0.2 1">{"".join(parts)}</spatial>')
        lines.append("  </tendon>")

        # Pull-only cylinders: ctrl is the tendon tension [N]; gear -1 makes a positive
        # tension shorten the tendon. user = bore diameter, stroke [m].
        lines.append("  <actuator>")
        for t in self.tendons:
            fmax = max_tension(t.cylinder)
            bore, stroke = CYLINDERS[t.cylinder]
            lines.append(f'    <general name="A_{t.name[2:]}" tendon="{t.name}" gear="-1" gainprm="1" '
                         f'ctrlrange="0 {fmt(fmax, 3)}" forcerange="0 {fmt(fmax, 3)}" '
                         f'user="{fmt(bore)} {fmt(stroke)}"/>')
        lines.append("  </actuator>")

        lines.append("  <sensor>")
        for j in self.joints:
            lines.append(f'    <jointpos name="JP_{j.name}" joint="{j.name}"/>')
        for j in self.joints:
            lines.append(f'    <jointvel name="JV_{j.name}" joint="{j.name}"/>')
        for t in self.tendons:
            lines.append(f'    <tendonpos name="TL_{t.name[2:]}" tendon="{t.name}"/>')
        for t in self.tendons:
            lines.append(f'    <tendonvel name="TV_{t.name[2:]}" tendon="{t.name}"/>')
        for t in self.tendons:
            lines.append(f'    <actuatorfrc name="AF_{t.name[2:]}" actuator="A_{t.name[2:]}"/>')
        for b, _ in walk(self.root):
            for site in b.sites:
                if site.half:
                    lines.append(f'    <touch name="ST_{site.name[4:]}" site="{site.name}"/>')
        for b, _ in walk(self.root):
            for site in b.sites:
                if site.name.startswith("S_") and site.name.endswith("tip"):
                    lines.append(f'    <framepos name="FP_{site.name[2:]}" objtype="site" objname="{site.name}"/>')
        if s.name == "keypad":
            for label in keypad_xml()[1]:
                lines.append(f'    <jointpos name="KP_{label}" joint="KEY_{label}"/>')
        lines.append("  </sensor>")

        lines.append("  <custom>")
        for t in self.tendons:
            lines.append(f'    <text name="cylinder_A_{t.name[2:]}" data="{t.cylinder}"/>')
        lines.append(f'    <text name="adroit_scene" data="{s.name}"/>')
        if s.extra_custom:
            lines.append("    " + s.extra_custom)
        lines.append("  </custom>")

        lines.append("  <keyframe>")
        lines.append(f'    <key name="home" qpos="{fmt(self.keyframe_qpos([0.0] * len(self.joints)))}"/>')
        lines.append(f'    <key name="rest" qpos="{fmt(self.keyframe_qpos([j.rest for j in self.joints]))}"/>')
        lines.append("  </keyframe>")
        lines.append("</mujoco>")
        return "\n".join(lines) + "\n"

# ----------------------------------------------------------------------------- URDF writer

def urdf_origin(pos, quat):
    return f'<origin xyz="{fmt(pos)}" rpy="{fmt(mat_to_rpy(quat_to_mat(quat)))}"/>'


def urdf_shapes(tag, b: Body):
    """Collision/visual shapes of a body: capsules become a cylinder and two spheres."""
    out = []
    color = f'<material name="{b.name}_color"><color rgba="{b.rgba}"/></material>' if tag == "visual" else ""
    for g in b.geoms:
        if getattr(g, "wrap", False):
            continue
        if isinstance(g, Capsule):
            p1, p2 = np.asarray(g.p1, float), np.asarray(g.p2, float)
            mid, axis = (p1 + p2) / 2, p2 - p1
            out.append(f'<{tag}>{urdf_origin(mid, rotation_z_to(axis))}<geometry><cylinder radius="{fmt(g.radius)}" '
                       f'length="{fmt(np.linalg.norm(axis))}"/></geometry>{color}</{tag}>')
            for end in (p1, p2):
                out.append(f'<{tag}><origin xyz="{fmt(end)}"/><geometry><sphere radius="{fmt(g.radius)}"/>'
                           f'</geometry>{color}</{tag}>')
        else:
            out.append(f'<{tag}><origin xyz="{fmt(g.pos)}"/><geometry><box size="{fmt(2 * np.asarray(g.half))}"/>'
                       f'</geometry>{color}</{tag}>')
    return out


def write_urdf(model: Mjcf):
    s = model.scene
    lines = ['<?xml version="1.0"?>',
             "<!-- GENERATED by adroit_description/scripts/generate_model.py: do not edit. -->",
             f'<robot name="adroit_{s.name}">', '  <link name="world"/>']
    efforts = {t.joint: max_tension(t.cylinder) * dict(t.spans)[t.joint] for t in model.tendons}
    for b, parent in walk(model.root):
        lines.append(f'  <link name="{b.name}">')
        lines.append(f'    <inertial><origin xyz="{fmt(b.com)}"/><mass value="{fmt(max(b.mass, 1e-6))}"/>'
                     f'<inertia ixx="{fmt(b.inertia[0], 9)}" ixy="0" ixz="0" iyy="{fmt(b.inertia[1], 9)}" iyz="0" '
                     f'izz="{fmt(b.inertia[2], 9)}"/></inertial>')
        for shape in urdf_shapes("visual", b) + urdf_shapes("collision", b):
            lines.append("    " + shape)
        lines.append("  </link>")
        parent_name = parent.name if parent else "world"
        if b.joint:
            j = b.joint
            effort = efforts.get(j.name, 0.0)
            lines.append(f'  <joint name="{j.name}" type="revolute"><parent link="{parent_name}"/>'
                         f'<child link="{b.name}"/>{urdf_origin(b.pos, b.quat)}<axis xyz="{fmt(j.axis)}"/>'
                         f'<limit lower="{fmt(j.range[0])}" upper="{fmt(j.range[1])}" effort="{fmt(effort, 3)}" '
                         f'velocity="20"/><dynamics damping="{fmt(j.damping)}" friction="{fmt(j.frictionloss)}"/></joint>')
        elif parent is None and s.free_base:
            # robot_state_publisher skips floating joints: the driver broadcasts world -> base.
            lines.append(f'  <joint name="{HAND_BASE_JOINT}" type="floating"><parent link="world"/>'
                         f'<child link="{b.name}"/></joint>')
        else:
            lines.append(f'  <joint name="{b.name}_fixed" type="fixed"><parent link="{parent_name}"/>'
                         f'<child link="{b.name}"/>{urdf_origin(b.pos, b.quat)}</joint>')
    lines.append("</robot>")
    return "\n".join(lines) + "\n"

# ----------------------------------------------------------------------------- main

def main(out_dir):
    os.makedirs(os.path.join(out_dir, "mjcf"), exist_ok=True)
    os.makedirs(os.path.join(out_dir, "urdf"), exist_ok=True)
    names = []
    for scene in scenes():
        for planning in (False, True):
            model = Mjcf(scene, planning)
            suffix = "_planning" if planning else ""
            with open(os.path.join(out_dir, "mjcf", f"{scene.name}{suffix}.xml"), "w") as f:
                f.write(model.write())
        with open(os.path.join(out_dir, "urdf", f"{scene.name}.urdf"), "w") as f:
            f.write(write_urdf(Mjcf(scene, False)))
        names.append(scene.name)
    with open(os.path.join(out_dir, "scenes.txt"), "w") as f:
        f.write("\n".join(names) + "\n")


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3):
        sys.exit("usage: generate_model.py <output_dir> [<catalogue_header.h>]")
    if len(sys.argv) == 3:
        write_catalogue_header(sys.argv[2])
    main(sys.argv[1])
