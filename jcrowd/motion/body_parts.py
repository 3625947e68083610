"""Parts of the body and the joint names each is known by, for binding a body to a skeleton.

Step 1 of :func:`~jcrowd.motion.body.bind_body` (:func:`~jcrowd.motion.body.map_bones`): a
skeleton joint belongs to the part its name says under any convention in :data:`PART_NAMES`
(case, separators and a ``prefix:`` ignored; right-side names are the left ones mirrored).
"""

from __future__ import annotations

import re

__all__ = ["ALL_PARTS", "PART_NAMES", "REQUIRED_PARTS", "part_of_joint"]

# Part of the body → rig bone names (CMU MotionBuilder, the shipped rig) and the joint names
# other conventions use for it, left side; right-side entries are made by mirroring.
PART_NAMES: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "pelvis": (("Hips",), ("hips", "pelvis", "root", "hip")),
    "left_hip": (("LHipJoint",), ("lhipjoint", "lefthipjoint")),
    "left_thigh": (
        ("LeftUpLeg",),
        ("leftupleg", "lfemur", "leftthigh", "thighl", "lthigh", "leftupperleg", "upperlegl"),
    ),
    "left_shin": (
        ("LeftLeg",),
        (
            "leftleg",
            "ltibia",
            "leftshin",
            "calfl",
            "lshin",
            "leftlowerleg",
            "lowerlegl",
            "leftknee",
        ),
    ),
    "left_foot": (("LeftFoot",), ("leftfoot", "lfoot", "footl", "leftankle")),
    "left_toes": (("LeftToeBase",), ("lefttoebase", "ltoes", "lefttoe", "balll", "toesl", "ltoe")),
    "spine": (
        ("LowerBack", "Spine", "Spine1"),
        (
            "lowerback",
            "upperback",
            "spine",
            "spine1",
            "spine2",
            "spine3",
            "thorax",
            "chest",
            "abdomen",
            "torso",
            "spine01",
            "spine02",
            "spine03",
            "upperchest",
        ),
    ),
    "head": (
        ("Neck", "Neck1", "Head"),
        ("neck", "neck1", "lowerneck", "upperneck", "neck01", "head"),
    ),
    "left_collar": (("LeftShoulder",), ("leftshoulder", "lclavicle", "claviclel", "leftcollar")),
    "left_upper_arm": (
        ("LeftArm",),
        ("leftarm", "lhumerus", "upperarml", "leftupperarm", "lshoulder", "luparm"),
    ),
    "left_forearm": (
        ("LeftForeArm",),
        ("leftforearm", "lradius", "lowerarml", "leftlowerarm", "lforearm", "leftelbow"),
    ),
    "left_hand": (
        ("LeftHand", "LeftFingerBase"),
        ("lefthand", "lwrist", "lhand", "handl", "leftwrist", "leftfingerbase"),
    ),
    "left_fingers": (
        ("LeftHandFinger1",),
        ("lefthandindex1", "lfingers", "lefthandfinger1", "indexl", "lindex"),
    ),
    "left_thumb": (("LThumb",), ("lthumb", "lefthandthumb1", "thumbl", "leftthumb")),
}

REQUIRED_PARTS = (
    "pelvis",
    "left_thigh",
    "left_shin",
    "left_foot",
    "right_thigh",
    "right_shin",
    "right_foot",
    "left_upper_arm",
    "left_forearm",
    "right_upper_arm",
    "right_forearm",
    "head",
)
"""Parts a skeleton must have for a body to follow it."""


def _mirror(name: str) -> str:
    """A left-side name turned right (``Left…``, ``L…``, ``l…``, ``…l``)."""
    if name.startswith("Left"):
        return "Right" + name[4:]
    if name.startswith("left"):
        return "right" + name[4:]
    if name.startswith("L") and name[1:2].isupper():
        return "R" + name[1:]
    if name.startswith("l"):
        return "r" + name[1:]
    if name.endswith("l"):
        return name[:-1] + "r"
    return name


def _parts() -> dict[str, tuple[tuple[str, ...], tuple[str, ...]]]:
    out: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {}
    for part, (bones, names) in PART_NAMES.items():
        out[part] = (bones, names)
        if part.startswith("left_"):
            right = "right_" + part[5:]
            out[right] = (tuple(_mirror(b) for b in bones), tuple(_mirror(n) for n in names))
    return out


ALL_PARTS = _parts()
"""Every part, left and right, → (rig bone names, joint names it is known by)."""


def _normal_name(name: str) -> str:
    """Lower case, a ``prefix:`` and separators dropped."""
    return re.sub(r"[^a-z0-9]", "", name.split(":")[-1].lower())


def part_of_joint(name: str) -> str | None:
    """The part a joint named ``name`` moves, under any convention known; ``None`` if none."""
    n = _normal_name(name)
    for part, (_, names) in ALL_PARTS.items():
        if n in names:
            return part
    return None
