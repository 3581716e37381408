"""Robot commands a controller can follow: every published joint command within the URDF's
position and velocity limits (and an acceleration limit where the mapping gives one), eased
from where the robot is after a start or a hold.

The solver (robot/retarget.py) finds the pose a person means, frame by frame; a robot cannot
jump to it. Live, H1's knees went from 117 degrees to 0 in one frame (about 120 rad/s; their
limit is 14) and G1's from 0 to 165 (a full squat), at start-up. So the commands pass through
here: after a start or a hold (the solver's fresh solve) they ramp over the mapping's `ramp`
seconds from the last command given (the neutral pose before any), and each joint moves no
faster than its limit since the last command. The solver goes on from its own solution, so a
joint held back catches up on the next frames.
"""

from __future__ import annotations

import numpy as np

NOMINAL_DT = 1.0 / 60.0  # s: the step assumed where time stood still or went back
GAP = 0.1  # s: a longer time between commands moves as far as this one would (as the solver's GAP)


class CommandLimiter:
    """Joint commands eased and held to the robot's limits; `limited` counts the commands in
    which a joint was held to its velocity or acceleration limit."""

    def __init__(
        self,
        lower: np.ndarray,
        upper: np.ndarray,
        max_velocity: np.ndarray,
        start: np.ndarray,
        ramp: float = 0.5,
        max_acceleration: float | None = None,
    ) -> None:
        self.lower, self.upper = np.asarray(lower, float), np.asarray(upper, float)
        self.max_velocity = np.asarray(max_velocity, float)
        self.start, self.ramp, self.max_acceleration = np.asarray(start, float), ramp, max_acceleration
        self.limited = 0
        self.reset()

    def reset(self) -> None:
        """The robot back at its start pose, at rest (a new run)."""
        self._given: tuple[float, np.ndarray, np.ndarray] | None = None  # stamp, command, velocity
        self._ramp: tuple[float, np.ndarray] | None = None  # a ramp's start: stamp, the command it left

    def __call__(self, stamp: float, target: np.ndarray, fresh: bool) -> tuple[np.ndarray, np.ndarray]:
        """(the command, its velocity) for the solver's pose `target` at `stamp`; fresh: the
        solver started over (a start, after a hold or a gap, a jump): ramp from where the robot is."""
        if self._given is None:
            self._given = (stamp - NOMINAL_DT, self.start.copy(), np.zeros_like(self.start))
        last_stamp, last_q, last_v = self._given
        dt = stamp - last_stamp
        if dt <= 0.0:  # (time stood still or went back)
            dt = NOMINAL_DT
        # over a gap, no more than GAP's worth of motion: a controller given no command for a
        # while moves to the next at once. Reset to NOMINAL_DT instead, a starved node's 8
        # commands a second each moved a sixtieth of a second's worth, and the robot fell ever
        # further behind the body
        dt = min(dt, GAP)
        if fresh and self.ramp > 0:
            self._ramp = (stamp - dt, last_q.copy())
        goal = np.asarray(target, float)
        if self._ramp is not None:
            share = (stamp - self._ramp[0]) / self.ramp
            if share >= 1.0:
                self._ramp = None
            else:
                share = max(share, 0.0)
                eased = share * share * (3.0 - 2.0 * share)  # smoothstep: leaves and arrives at rest
                goal = self._ramp[1] + eased * (goal - self._ramp[1])
        wanted = goal - last_q
        speed = np.clip(wanted / dt, -self.max_velocity, self.max_velocity)
        if self.max_acceleration is not None:
            accel = self.max_acceleration
            # no faster than can stop at the goal (slowing by accel * dt a step), and no more
            # change of speed than accel allows
            per_step = accel * dt * dt
            stopping = accel * dt * (np.sqrt(0.25 + 2.0 * np.abs(wanted) / per_step) - 0.5)
            speed = np.clip(speed, -stopping, stopping)
            speed = np.clip(speed, last_v - accel * dt, last_v + accel * dt)
        step = speed * dt
        if np.any(np.abs(step - wanted) > 1e-12):
            self.limited += 1
        command = np.clip(last_q + step, self.lower, self.upper)
        velocity = (command - last_q) / dt
        self._given = (stamp, command, velocity)
        return command, velocity


def limiter_for(retarget) -> CommandLimiter:
    """The limiter of a HumanoidRetarget: its URDF's limits, its neutral pose, its mapping's
    ramp and max_acceleration."""
    return CommandLimiter(
        retarget.lower,
        retarget.upper,
        retarget.model.velocity_limits(),
        retarget.neutral_q,
        retarget.mapping.ramp,
        retarget.mapping.max_acceleration,
    )
