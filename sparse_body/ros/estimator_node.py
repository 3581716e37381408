"""The estimator as a lifecycle node.

configure: read parameters, load the sensor configuration and the estimator, create the
publishers and the TF input; activate: start estimating; deactivate: stop; cleanup: release
everything. Bad tracker input never stops the node: it is reported on /diagnostics, and the
outputs hold the last good pose, marked invalid on estimate_status.

Estimates are driven by the input: one is made as soon as every live tracker has a sample
newer than the last estimate's, stamped with the newest tracker stamp. A timer at
output_rate is only the fallback: it estimates from what is there when input is slow or
partial, and holds the pose (invalid) when no tracker sample has come for tracker_timeout.
Staleness is judged in the trackers' own time, so a starved CPU shows up as latency on
/diagnostics, not as invalid estimates.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.timer import Timer

from ..core.calibration import CalibrationError, person_body
from ..core.sensors import SensorConfigError, load_sensor_config
from ..core.skeleton import JOINT_NAMES
from ..core.types import BodyPose
from ..estimators.base import Estimator
from ..estimators.budget import BudgetedStep
from ..io.output import axis_link_name
from ..io.tf_cache import TfGuards
from ..io.topics import ROBOT_PREFIX
from ..methods.factory import create_estimator
from ..methods.kernels import compile_kernels
from ..methods.recommended import resolve_estimator
from .estimate_outputs import EstimateOutputs
from .estimate_stats import EstimateStats
from .estimator_parameters import (  # noqa: F401 - PARAMETERS, method_option_parameters: the node's schema, read here
    CHECKS,
    LIVE,
    PARAMETERS,
    RANGES,
    check_parameter,
    estimator_options,
    fallback_options,
    method_option_parameters,
)
from .live_step import LiveStep
from .parameters import declare, problems
from .spin import init, start_and_spin
from .tf_input import TfReader

# seconds a fallback tick may come later than its period before the node counts itself as
# stalled (not running) rather than the trackers as silent
STALL = 0.25


class EstimatorNode(LifecycleNode):
    NAME = "sparse_body_estimator"
    PARAMETERS = PARAMETERS
    RANGES = RANGES
    OUTPUTS = ""  # namespace of the output topics

    # Made in on_configure (timers in on_activate), destroyed in _release / _stop_timers.
    estimator: Estimator | None = None
    budgeted: BudgetedStep | None = None  # the estimator (and budget_fallback) as stepped live
    live: LiveStep | None = None  # a step of it and what estimate_status says of it
    tf_in: TfReader | None = None
    outputs: EstimateOutputs | None = None  # every publisher (and the live view)
    timer: Timer | None = None
    diag_timer: Timer | None = None

    def __init__(self, **kwargs) -> None:
        super().__init__(self.NAME, **kwargs)
        # (ros/parameters.py: a value given out of range at start-up is said by configure)
        self._refused_at_start = declare(self, self.PARAMETERS, self.RANGES)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        # counted from the start: inputs can fail before the first activate (the constraint
        # node's estimate input is subscribed at configure)
        self._stats = EstimateStats()
        self._release()

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        for prm in parameters:
            if prm.name not in self.PARAMETERS:
                continue
            reason = check_parameter(prm.name, prm.value, self.PARAMETERS[prm.name][0], self.RANGES)
            if reason is None and self.estimator is not None and prm.name not in LIVE:
                reason = f"{prm.name} takes effect at configure: deactivate and clean up the node first"
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        for prm in parameters:  # a value refused at start-up is replaced
            self._refused_at_start.pop(prm.name, None)
        if self.estimator is not None:  # configured: the live ones apply from the next estimate
            for prm in parameters:
                if prm.name in LIVE and prm.name in self.params:
                    self.params[prm.name] = prm.value
        return SetParametersResult(successful=True)

    # -- lifecycle -------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        p = {name: self.get_parameter(name).value for name in self.PARAMETERS}
        wrong = list(self._refused_at_start.values()) + problems(self.PARAMETERS, p, self.RANGES, **CHECKS)
        if wrong:
            self.get_logger().error(f"configure failed: {'; '.join(wrong)}")
            return TransitionCallbackReturn.FAILURE
        p = {name: float(v) if isinstance(self.PARAMETERS[name][0], float) else v for name, v in p.items()}
        try:
            sensors = load_sensor_config(p["sensors"])
            if p["fixed_frame"]:
                sensors = replace(sensors, fixed_frame=p["fixed_frame"])
            for key in ("estimator", "budget_fallback"):  # auto: the one recommended for the sensors
                if p.get(key):
                    p[key] = resolve_estimator(p[key], sensors.name)
            self.skeleton = person_body(p["calibration"], p["height"])
            if p["calibration"]:
                self.get_logger().info(f"the body of {p['calibration']}: {self.skeleton.height():.2f} m tall")
            self.estimator = self._make_estimator(p, sensors)
            self.budgeted = BudgetedStep(self.estimator, self._make_budget_fallback(p, sensors))
            # here, not at the first estimate: numba compiles (or loads) on first use
            compile_kernels(say=self.get_logger().info)
        except (SensorConfigError, CalibrationError, ValueError, FileNotFoundError) as err:
            self.get_logger().error(f"configure failed: {err}")
            self._release()
            return TransitionCallbackReturn.FAILURE
        except Exception as err:  # noqa: BLE001 - an unforeseen failure still fails configure, said
            self.get_logger().error(f"configure failed: {type(err).__name__}: {err}")
            self._release()
            return TransitionCallbackReturn.FAILURE
        self.sensors, self.params = sensors, p
        self.live = LiveStep(self.budgeted, lambda: self._stats, self._method(), self._step_budget())
        self._frames = [s.frame_id for s in sensors.sites]
        own = {p["frame_prefix"] + name for name in JOINT_NAMES}  # the body's links, as body_table names them
        own |= {axis_link_name(name, axis) for name in own for axis in ("z", "y")}  # and axis_link_table
        guards = TfGuards(
            clock_window=p["clock_window"], future_window=p["future_window"], play_radius=p["play_radius"]
        )
        self.tf_in = TfReader(
            self, set(self._frames), own, self._tracker_arrived, guards, also=self._looked_up_frames(p)
        )
        self._configure_inputs()
        from .live_view import LiveViewError

        try:
            self.outputs = EstimateOutputs(self, self.OUTPUTS, self.skeleton, sensors.fixed_frame, p)
        except LiveViewError as err:
            self.get_logger().error(f"configure failed: {err}")
            self._release()
            return TransitionCallbackReturn.FAILURE
        if self.outputs.live_view is not None:
            self.tf_in.forward = (ROBOT_PREFIX, self.outputs.log_robot_tf)  # a retargeted robot, shown too
            self.get_logger().info(
                f"live view: open ws://{p['foxglove_host']}:{self.outputs.live_view.port} in Foxglove"
            )
        self.get_logger().info(
            f"configured: {self._method()} on {sensors.name} ({', '.join(sensors.site_names)}) "
            f"in frame {sensors.fixed_frame!r}"
        )
        return TransitionCallbackReturn.SUCCESS

    def _make_estimator(self, p: dict, sensors):
        name, options, overridden = estimator_options(p)
        # a parameter set wins over the spec's same option: said, so the log shows what runs
        # (the spec's predict_ahead=0.2 was logged while the parameter's 0.1 stamped the poses)
        for key, value in overridden.items():
            said = f"the parameter sets {key} to {options[key]!r} over the estimator spec's {value!r}"
            self.get_logger().warning(said)
        return create_estimator(name, sensors, self.skeleton, fps=p["output_rate"], **options)

    def _make_budget_fallback(self, p: dict, sensors) -> Estimator | None:
        fallback = fallback_options(p)
        if fallback is None:
            return None
        return create_estimator(fallback[0], sensors, self.skeleton, fps=p["output_rate"], **fallback[1])

    def _step_budget(self) -> float:
        return self.params["step_budget"] or 0.75 / self.params["output_rate"]

    def _configure_inputs(self) -> None:
        """More inputs than the trackers' TF (the constraint node's estimate)."""

    def _looked_up_frames(self, p: dict) -> set[str]:
        """Frames besides the trackers this node looks up on /tf (kept, never drive estimates)."""
        return set()

    def _method(self) -> str:
        """What estimates, as diagnostics and the log name it."""
        return self.params["estimator"]

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        assert self.budgeted is not None  # activate follows a successful configure
        self.budgeted.reset()
        self._stats = EstimateStats()
        self._last_now: float | None = None
        self._last_input = -np.inf  # the newest tracker stamp the last estimate used
        self._last_step = -np.inf  # when it was made (monotonic)
        self._last_arrival = -np.inf  # when a new tracker sample last arrived (monotonic)
        self._last_tick = time.monotonic()  # when the fallback timer last ran (monotonic)
        self._silence_seen = False  # the last call found the trackers silent (see _estimate)
        self.timer = self.create_timer(1.0 / self.params["output_rate"], self._tick)
        self.diag_timer = self.create_timer(1.0, self._publish_diagnostics)
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_timers()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_timers()
        self._release()
        return TransitionCallbackReturn.SUCCESS

    on_shutdown = on_cleanup

    def _stop_timers(self) -> None:
        if self.timer is not None:
            self.destroy_timer(self.timer)
        if self.diag_timer is not None:
            self.destroy_timer(self.diag_timer)
        self.timer = self.diag_timer = None

    def _release(self) -> None:
        if self.outputs is not None:
            self.outputs.destroy()
        if self.tf_in is not None:
            self.tf_in.destroy()
        if self.budgeted is not None:
            self.budgeted.close()  # the late step, if any, ends first
        self.tf_in = self.estimator = self.budgeted = self.outputs = self.live = None
        self._ages: np.ndarray | None = None
        self._site_valid: np.ndarray | None = None

    # -- work --------------------------------------------------------------------------------
    def _tracker_arrived(self) -> None:
        """The TF reader took a new tracker sample: the trackers are alive (tracker_timeout)."""
        self._last_arrival = time.monotonic()
        self._on_tracker()

    def _on_tracker(self) -> None:
        """A tracker sample came: estimate now if every live tracker has moved since the last
        estimate. Bursts are coalesced: at most one estimate per half output period, the
        newest samples waiting in the cache (the fallback timer picks up what is left)."""
        if self.timer is None or time.monotonic() - self._last_step < 0.5 / self.params["output_rate"]:
            return
        assert self.tf_in is not None  # the timer exists only while the node is active
        stamps = np.array(self.tf_in.stamps(self._frames))
        dynamic = stamps[np.isfinite(stamps)]
        if not len(dynamic):
            return
        newest = dynamic.max()
        stale = self.params["stale_timeout"]
        budgets = np.array([self.tf_in.cache.budget(f, stale) for f in self._frames])
        live = np.isfinite(stamps) & (newest - stamps <= budgets)
        if np.all(stamps[live] > self._last_input):
            self._estimate(fallback=False)

    def _tick(self) -> None:
        now = time.monotonic()
        # A tick far later than its period: this node was not running (stopped, or starved of
        # CPU), so how long the trackers were silent meanwhile is unknown. Silence is counted
        # only while the node runs: the stall moves the last arrival forward.
        stall = now - self._last_tick - 1.0 / self.params["output_rate"]
        if stall > STALL:
            self._last_arrival = min(now, self._last_arrival + stall)
        self._last_tick = now
        if now - self._last_step >= 1.5 / self.params["output_rate"]:
            self._estimate(fallback=True)

    def _estimate(self, fallback: bool) -> None:
        """One estimate from the trackers' newest samples: gathered, stepped, published."""
        deadline = time.monotonic() + self._step_budget()  # for the step, counted from here
        now = self.get_clock().now().nanoseconds * 1e-9
        self._restart_on_jump_back(now)
        gathered = self._gather(now, fallback)
        if gathered is None:
            return
        frame, stamps, newest, no_input, silent = gathered
        assert self.live is not None
        pose, reason = self.live.step(frame, deadline)
        # Stamp the outputs with the newest tracker stamp used, so latency can be measured; with
        # a filter lag the pose is that much older, and so are its stamp and its latency; with
        # predict_ahead it is of a later time, and so is its stamp (latency: from the trackers).
        source_time = float(stamps[frame.valid].max()) if frame.valid.any() else now
        stamp = source_time + (pose.stamp - frame.stamp)
        source_time = min(source_time, stamp)
        if not pose.valid:
            self._stats.invalid += 1
            reason = reason or self._held_reason(frame, no_input, silent)
        self._publish(pose, stamp, reason)
        assert self.outputs is not None
        if self.outputs.live_view is not None:
            self.outputs.live_view.log_trackers(frame, self.sensors.fixed_frame, self._frames)
        self._last_step = time.monotonic()
        if not no_input:
            self._last_input = newest
        # latency to the moment the outputs left, the step and encoding included
        published = self.get_clock().now().nanoseconds * 1e-9
        self._stats.estimated(self._last_step, fallback, None if no_input else published - source_time)

    def _restart_on_jump_back(self, now: float) -> None:
        """A clock jump back (a looping bag, a restarted simulation): start afresh."""
        assert self.tf_in is not None and self.budgeted is not None  # estimates come only while active
        # `|`, not `or`: the reader's flag is taken (and cleared) whatever the clock did
        if (self._last_now is not None and now < self._last_now - 1.0) | self.tf_in.take_jump_back():
            self.budgeted.reset()
            self._last_input = -np.inf
            self._stats.resets += 1
        self._last_now = now

    def _gather(self, now: float, fallback: bool):
        """(frame, each tracker's sample stamp, the newest tracker stamp, no input, seconds
        silent) to estimate from, or None when there is nothing to do yet."""
        assert self.tf_in is not None
        # a tracker whose whole chain is static is current
        stamps = np.array([now if s == np.inf else s for s in self.tf_in.stamps(self._frames)])
        newest = stamps.max() if len(stamps) else -np.inf
        # the trackers stopped, not the node being late: judged by when samples last arrived, so
        # a starved node's estimates from fresh samples stay valid (it only gets slower)
        silent = time.monotonic() - self._last_arrival
        no_input = not silent <= self.params["tracker_timeout"] or not np.isfinite(newest)
        if no_input and np.isfinite(newest) and not self._silence_seen:
            # Silence is believed at its second sighting. After this node was stopped, starved
            # or busy, the executor runs the timer before the /tf messages that came meanwhile
            # (rclpy takes timers first); those are taken before the next call, so trackers
            # that are alive are seen alive by then.
            self._silence_seen = True
            return None
        self._silence_seen = no_input
        if fallback and not no_input and newest <= self._last_input:
            return None  # nothing new yet: wait for the trackers
        frame, stamps = self.tf_in.sample(self.sensors, now if no_input else newest, self.params["stale_timeout"])
        if no_input:
            frame.valid[:] = False
        self._ages, self._site_valid = now - stamps, frame.valid.copy()
        return frame, stamps, newest, no_input, silent if np.isfinite(newest) else np.inf

    def _held_reason(self, frame, no_input: bool, silent: float) -> str:
        if no_input:
            if np.isfinite(silent):
                return f"held: no tracker input for {silent:.1f} s"
            # "yet" may hide trackers that do arrive but are all refused (stamps far from this
            # node's clock, a play space they are outside): say so, or a user looks for a cable
            assert self.tf_in is not None
            refused = ", ".join(f"{reason} {n}" for reason, n in self.tf_in.rejected.items() if n)
            return "held: no tracker input yet" + (f" (/tf samples refused: {refused})" if refused else "")
        missing = [s for s, ok in zip(self.sensors.site_names, frame.valid, strict=True) if not ok]
        return f"held: no usable pose from {', '.join(missing)}" if missing else "held"

    def _publish(self, pose: BodyPose, stamp: float, reason: str) -> None:
        assert self.outputs is not None and self.tf_in is not None
        self.tf_in.published(self.outputs.publish(pose, stamp, reason))

    def _input_diagnostics(self) -> dict[str, str]:
        """What a node that reads more than trackers says of that input (the constraint node)."""
        return {}

    def _publish_diagnostics(self) -> None:
        assert self.tf_in is not None and self.outputs is not None  # the timer exists only while active
        rejected = self.tf_in.rejected
        level, message, values = self._stats.status(self.sensors.site_names, self._ages, self._site_valid, rejected)
        values["/tf messages caught up"] = str(self.tf_in.drained)  # taken at once by a node running behind
        values["own /tf messages skipped"] = str(self.tf_in.own_skipped)  # known by their bytes, not read
        values.update(self._input_diagnostics())
        status = DiagnosticStatus(
            level=bytes([level]),  # a `byte` field: an int there was sent as a random byte
            name=f"{self.get_name()}: estimator",
            message=message,
            hardware_id=self._method(),
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.outputs.publish_diagnostics(msg, self.get_clock().now().nanoseconds * 1e-9)


def main(args=None, node_class=None) -> None:
    init(args)  # from here a signal ends the node, also while it starts
    start_and_spin(node_class or EstimatorNode)


if __name__ == "__main__":
    main()
