"""What the TF input refuses (io/tf_cache.py says why each guard is there). A module of its
own, without numpy, so that the command line can give the defaults in --help at no cost."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TfGuards:
    """What the TF input refuses; the node's parameters and `process`'s options set them."""

    jump_back: float = 1.0  # s: further back than this a frame starts again; less is out of order
    clock_window: float = 10.0  # s: dynamic stamps further behind the clock are refused; 0: no check
    future_window: float = 0.5  # s: dynamic stamps further ahead of the clock are refused (if clock_window > 0)
    play_radius: float = 100.0  # m: trackers further from the fixed frame's origin are refused
    max_depth: int = 16  # transforms from a tracker up to the fixed frame; longer chains are refused
    other_frames: int = 256  # frames neither tracker nor ancestor kept (newest set), in case one becomes an ancestor
