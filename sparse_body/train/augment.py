"""Augmentation of training motions, one implementation for every trainer.

42 minutes of CMU is little, and the test people move and are built differently from the
train people. Each augmentation makes a new Motion from a train clip (local rotations, root,
skeleton), from which a trainer derives its inputs and targets as it does for the clip:

- mirror: the motion reflected left-right (the person's left arm does what the right did);
- speed: played 0.8-1.25 times as fast (resampled, then read at the original rate);
- proportions: arms, legs and torso lengthened or shortened, each segment by its own factor,
  5 % standard deviation: the spread of the 25 CMU bodies relative to their height (arm
  3.5 %, leg 2.4 %, torso 5.5 %, upper arm / forearm split 5 %; measured on their ASFs);
- splice: the head and arms of another train clip (a donor) on this clip's pelvis, spine and
  legs, so that a model cannot read the legs off what the hands do: dance arms over walking
  legs, a reach over a squat. The spine stays with the legs because its lean carries the
  weight the feet balance, so the feet still allow the body above them; only the neck, head,
  collars and arms (local rotations, each on its own parent) come from the donor. The
  copy is as long as the shorter of the two. `splice=S` splices that share of the random
  variants (default 1/2).
- tilt: the whole body turned off its feet in its own frame, about a horizontal axis of any
  direction by 20 to 100 degrees, held where the clip starts and laid on the floor
  (data/floor.laid, as the floor selection part lays its clips at 90 degrees exactly): 42
  minutes of CMU hold two dive-rolls and nothing else off the feet, and another lab's lying on
  the floor broke every regressor trained on them (issue 73). `tilt=S` tilts that share of the
  random variants (default 1/4).

'all' names every kind; a report written before splice existed that says 'all' means the first
three, and one before tilt the first four (every shipped model's command names its kinds).

No random heading (tilt turns the body off its feet, which changes what a model sees; a turn
about the vertical does not): every model here sees the body in a heading-free frame (LoBSTr's
pelvis-yaw reference, DragPoser's heading-split pose), so turning the clip changes nothing
they see. Tracker noise and limb noise stay with the trainers that already add them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..core.skeleton import JOINT_INDEX, JOINT_NAMES, Skeleton
from ..data.motion import Motion

_ARM_ENDS = ("_collar", "_shoulder", "_elbow", "_wrist")
KINDS = ("mirror", "speed", "proportions", "splice", "tilt")
SPEED_RANGE = (0.8, 1.25)
SPLICE_SHARE = 0.5  # of the random variants, when the spec says plain 'splice'
TILT_SHARE = 0.25  # of the random variants, when the spec says plain 'tilt'
TILT_RANGE = (20.0, 100.0)  # degrees off upright
PROPORTION_STD = 0.05

# the mirror image of each joint: left <-> right
MIRROR = np.array(
    [JOINT_INDEX[n.replace("left_", "@").replace("right_", "left_").replace("@", "right_")] for n in JOINT_NAMES]
)
# segments scaled together (their offsets: the joint at the segment's far end), both sides alike
SEGMENTS = {
    "thigh": ("left_knee", "right_knee"),
    "shin": ("left_ankle", "right_ankle"),
    "upper_arm": ("left_elbow", "right_elbow"),
    "forearm": ("left_wrist", "right_wrist"),
    "clavicle": ("left_shoulder", "right_shoulder"),
    "torso": ("spine2", "spine3", "neck", "left_collar", "right_collar", "head"),
    "hips": ("left_hip", "right_hip"),
}
# what a splice takes from its donor: everything above spine3
SPLICED = np.array([JOINT_INDEX[n] for n in JOINT_NAMES if n in ("neck", "head") or n.endswith(_ARM_ENDS)])


@dataclass(frozen=True)
class Augmentation:
    """Which augmentations a trainer applies, and how many variants of each clip it adds."""

    kinds: tuple[str, ...] = KINDS
    variants: int = 3  # augmented copies per train clip, besides the clip itself
    splice_share: float = SPLICE_SHARE  # of the random variants, spliced
    tilt_share: float = TILT_SHARE  # of the random variants, tilted off the feet

    @classmethod
    def parse(cls, spec: str, variants: int = 3) -> Augmentation:
        """'mirror,speed,proportions,splice,tilt' (any subset), 'all' or 'none'; 'splice=S'
        splices a share S in [0, 1] of the random variants instead of half, 'tilt=S' tilts
        that share instead of a quarter."""
        spec = spec.strip()
        words = KINDS if spec == "all" else () if spec in ("none", "") else tuple(s.strip() for s in spec.split(","))
        shares = {"splice": SPLICE_SHARE, "tilt": TILT_SHARE}
        kinds = []
        for word in words:
            kind, _, value = word.partition("=")
            if value and kind in shares:
                try:
                    shares[kind] = float(value)
                except ValueError:
                    shares[kind] = float("nan")  # refused as a share out of range is
                if not 0.0 <= shares[kind] <= 1.0:
                    raise ValueError(f"{kind}={value}: the share must be a number from 0 to 1")
            elif value:
                raise ValueError(f"augmentation {kind} takes no value ({word})")
            kinds.append(kind)
        unknown = [k for k in kinds if k not in KINDS]
        if unknown:
            raise ValueError(f"unknown augmentation {', '.join(unknown)}; known: {', '.join(KINDS)}, all, none")
        return cls(tuple(k for k in KINDS if k in kinds), variants if kinds else 0, shares["splice"], shares["tilt"])

    def without(self, kind: str) -> Augmentation:
        """The same augmentation (variants, splice share) with one kind left out."""
        return replace(self, kinds=tuple(k for k in self.kinds if k != kind))

    @property
    def spec(self) -> str:
        shares = {"splice": (self.splice_share, SPLICE_SHARE), "tilt": (self.tilt_share, TILT_SHARE)}
        words = [f"{k}={shares[k][0]:g}" if k in shares and shares[k][0] != shares[k][1] else k for k in self.kinds]
        return ",".join(words) or "none"


NO_AUGMENTATION = Augmentation((), 0)


def mirrored(motion: Motion) -> Motion:
    """The motion reflected in its x-z plane (REP-103: y is left): a rotation R becomes
    S R S with S = diag(1, -1, 1), i.e. quaternion (x, y, z, w) -> (-x, y, -z, w), and each
    joint takes its mirror joint's rotation and offset."""
    q = motion.local_quats[:, MIRROR] * np.array([-1.0, 1.0, -1.0, 1.0])
    offsets = motion.skeleton.offsets[MIRROR] * np.array([1.0, -1.0, 1.0])
    root = motion.root_positions * np.array([1.0, -1.0, 1.0])
    return Motion(motion.name + "/mirror", motion.fps, Skeleton(offsets), q, root)


def played_at(motion: Motion, speed: float) -> Motion:
    """The motion `speed` times as fast, at its own frame rate."""
    faster = motion.resampled(motion.fps / speed)
    return Motion(f"{motion.name}/x{speed:.2f}", motion.fps, motion.skeleton, faster.local_quats, faster.root_positions)


def with_proportions(motion: Motion, factors: dict[str, float]) -> Motion:
    """The same rotations on a body whose SEGMENTS are scaled by factors; the root path is
    scaled by the legs' change, so that the feet still reach the floor and strides fit."""
    offsets = motion.skeleton.offsets.copy()
    for segment, factor in factors.items():
        offsets[[JOINT_INDEX[j] for j in SEGMENTS[segment]]] *= factor
    skeleton = Skeleton(offsets)
    legs = skeleton.leg_length() / motion.skeleton.leg_length()
    return Motion(motion.name + "/body", motion.fps, skeleton, motion.local_quats, motion.root_positions * legs)


def tilted(motion: Motion, degrees: float, towards: float) -> Motion:
    """The motion's body turned `degrees` off upright about the horizontal axis at `towards`
    radians from its forward direction (in its own frame), laid on the floor."""
    from scipy.spatial.transform import Rotation

    from ..data.floor import laid

    axis = np.array([np.cos(towards), np.sin(towards), 0.0])
    turn = Rotation.from_rotvec(axis * np.radians(degrees))
    return laid(motion, turn, f"{motion.name}/tilt{degrees:.0f}")


def spliced(motion: Motion, donor: Motion) -> Motion:
    """motion's pelvis, spine and legs under donor's neck, head and arms (SPLICED), for the
    frames both have; motion's skeleton."""
    T = min(len(motion), len(donor))
    q = motion.local_quats[:T].copy()
    q[:, SPLICED] = donor.local_quats[:T, SPLICED]
    return Motion(f"{motion.name}/arms:{donor.name}", motion.fps, motion.skeleton, q, motion.root_positions[:T])


def random_variant(
    motion: Motion, augmentation: Augmentation, rng: np.random.Generator, donors: Sequence[Motion] = ()
) -> Motion:
    """One augmented copy: each kind applied at random (mirror with probability 1/2, splice
    with the augmentation's splice_share, the donor drawn from donors, the other clips of the
    split; tilt with its tilt_share, last, so the body is laid as the rest made it)."""
    kinds = augmentation.kinds
    if "mirror" in kinds and rng.random() < 0.5:
        motion = mirrored(motion)
    if "splice" in kinds and rng.random() < augmentation.splice_share:
        if not donors:
            raise ValueError("the splice augmentation needs at least two train clips")
        motion = spliced(motion, donors[int(rng.integers(len(donors)))])
    if "proportions" in kinds:
        draws = np.clip(rng.normal(0.0, PROPORTION_STD, len(SEGMENTS)), -2 * PROPORTION_STD, 2 * PROPORTION_STD)
        motion = with_proportions(motion, {s: 1.0 + d for s, d in zip(SEGMENTS, draws, strict=True)})
    if "speed" in kinds and len(motion) > 2:
        lo, hi = np.log(SPEED_RANGE)
        motion = played_at(motion, float(np.exp(rng.uniform(lo, hi))))
    if "tilt" in kinds and rng.random() < augmentation.tilt_share:
        motion = tilted(motion, float(rng.uniform(*TILT_RANGE)), float(rng.uniform(0.0, 2.0 * np.pi)))
    return motion


def variants(
    motion: Motion, augmentation: Augmentation, rng: np.random.Generator, donors: Sequence[Motion] = ()
) -> list[Motion]:
    """The clip and its augmented copies; with mirroring, the first copy is the plain mirror
    image, so that both sides are always seen. donors: the other clips, whose arms a splice takes."""
    out = [motion]
    for k in range(augmentation.variants):
        if k == 0 and "mirror" in augmentation.kinds:
            out.append(mirrored(motion))
        else:
            out.append(random_variant(motion, augmentation, rng, donors))
    return out


def augmented(motions: Sequence[Motion], augmentation: Augmentation, rng: np.random.Generator) -> list[Motion]:
    """Every clip of a split with its variants, in order; each other clip may be a splice's
    donor. Without splice the draws are those of variants() clip by clip."""
    out = []
    for k, motion in enumerate(motions):
        donors = [*motions[:k], *motions[k + 1 :]] if "splice" in augmentation.kinds else ()
        out += variants(motion, augmentation, rng, donors)
    return out
