"""LoBSTr's options (estimator.py says what each part does)."""

from __future__ import annotations

from dataclasses import dataclass

from ...estimators.options import EstimatorOptions, floor_height, max_gap, model_path, option, threads

# metres: the IK's soft reach leaves an end at most 0.63 cm short; beyond 2 cm the predicted
# torso put a tracker out of the arm's or the spine's reach (0.4 % of the validation frames)
REACHED = 0.02


@dataclass(frozen=True)
class LobstrOptions(EstimatorOptions):
    model_path: str | None = model_path()
    ensemble_path: str | None = option(
        None,
        "a second LoBSTr model stepped beside the first, their outputs averaged (null: the first alone)",
        experiment=True,  # docs/experiments/lobstr-seeds.md: two seeds averaged did not win
    )
    contact_ik: bool = option(True, "hold a foot in contact where it touched down (the paper's contact IK)")
    contact_threshold: float = option(
        0.5, "the contact probability from which a foot is held (with toe_contacts=false)", 0.0, 1.0
    )
    # chosen on the kinds of motion no train clip has: the network's contacts were right in 56 %
    # of their (frame, foot) states, the rule on its own toes in 72 %, with 18 % less skate
    toe_contacts: bool = option(
        True, "contacts from the predicted toes by the other methods' live rule (false: the network's, the paper's)"
    )
    release_frames: int = option(10, "frames over which a held foot is let go", 0, 600, "frames")
    floor_height: float = floor_height()
    max_gap: float = max_gap()
    learned_upper: bool = option(True, "the network's upper body, brought onto the trackers (false: the paper's IK)")
    # at the IK's 5 mm the spine flipped between the network's curve and a uniform bend, and
    # validation jitter was 22.8 against 16.6 at 15 mm (models/lobstr.runtime.json)
    spine_tolerance: float = option(
        0.015,
        "metres the predicted spine may leave the head off the headset and be kept",
        0.0,
        REACHED - 1e-4,
        "metres",
    )
    threads: int = threads()
