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
from typing import TYPE_CHECKING

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleNode, LifecyclePublisher, LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.timer import Timer
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from sparse_body.msg import EstimateStatus, FootContacts

from ..core.calibration import CalibrationError, person_body
from ..core.rotations import matrix_to_quat
from ..core.sensors import SensorConfigError, load_sensor_config
from ..core.skeleton import JOINT_NAMES, standing_pose
from ..core.tracker_filter import PREFIX as FILTER
from ..core.types import BodyPose, BodyPoses
from ..estimators.base import Estimator, parse_estimator_spec
from ..estimators.budget import BudgetedStep
from ..io import cdr
from ..io.output import HELD, axis_link_name, axis_link_table, body_table, joint_angles
from ..io.tf_cache import TfGuards
from ..io.urdf import body_urdf
from ..methods.factory import create_estimator
from ..methods.kernels import compile_kernels
from ..methods.recommended import resolve_estimator
from .estimate_stats import EstimateStats
from .estimator_parameters import (  # noqa: F401 - PARAMETERS, method_option_parameters: the node's schema, read here
    LIVE,
    METHOD_OPTIONS,
    PARAMETERS,
    RANGES,
    check_parameter,
    method_option_parameters,
)
from .parameters import declare
from .spin import init, start_and_spin
from .tf_input import TfReader

if TYPE_CHECKING:
    from .live_view import LiveView


# how estimate_status begins for a valid pose made by budget_fallback (the step over its budget)
OVER_BUDGET = "over budget:"
# how it begins for a valid pose of a frame the estimator says lay outside the motion it knows
# (Estimator.out_of_depth: upright's torso tilted past upright_within), the share following
OUT_OF_DEPTH = "out of depth"
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
    tf_in: TfReader | None = None
    pub_joints: LifecyclePublisher | None = None
    pub_contacts: LifecyclePublisher | None = None
    pub_status: LifecyclePublisher | None = None
    live_view: LiveView | None = None
    pub_tf: LifecyclePublisher | None = None
    pub_diag: LifecyclePublisher | None = None
    pub_description: Publisher | None = None
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
        problems = list(self._refused_at_start.values()) + [
            r
            for name, (default, _) in self.PARAMETERS.items()
            if (r := check_parameter(name, p[name], default, self.RANGES))
        ]
        if problems:
            self.get_logger().error(f"configure failed: {'; '.join(problems)}")
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
        overrides = QoSOverridingOptions.with_default_policies()
        from tf2_msgs.msg import TFMessage  # here, not at import: the stand-in exists only after setup

        ns = self.OUTPUTS
        # one profile object per publisher: rclpy's QoS overrides change the object they are given
        self.pub_joints = self.create_lifecycle_publisher(
            JointState, ns + "joint_states", QoSProfile(depth=10), qos_overriding_options=overrides
        )
        self.pub_contacts = self.create_lifecycle_publisher(
            FootContacts, ns + "foot_contacts", QoSProfile(depth=10), qos_overriding_options=overrides
        )
        self.pub_status = self.create_lifecycle_publisher(
            EstimateStatus, ns + "estimate_status", QoSProfile(depth=10), qos_overriding_options=overrides
        )
        self.pub_tf = self.create_lifecycle_publisher(TFMessage, "/tf", QoSProfile(depth=100))
        self.pub_diag = self.create_lifecycle_publisher(DiagnosticArray, "/diagnostics", QoSProfile(depth=10))
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_description = self.create_publisher(String, ns + "robot_description", latched)
        self.pub_description.publish(String(data=body_urdf(self.skeleton)))
        if p["foxglove_port"]:
            from .live_view import LiveView, LiveViewError

            try:
                self.live_view = LiveView(p["foxglove_host"], p["foxglove_port"], body_urdf(self.skeleton))
            except LiveViewError as err:
                self.get_logger().error(f"configure failed: {err}")
                self._release()
                return TransitionCallbackReturn.FAILURE
            self.get_logger().info(f"live view: open ws://{p['foxglove_host']}:{self.live_view.port} in Foxglove")
        self.get_logger().info(
            f"configured: {self._method()} on {sensors.name} ({', '.join(sensors.site_names)}) "
            f"in frame {sensors.fixed_frame!r}"
        )
        return TransitionCallbackReturn.SUCCESS

    def _make_estimator(self, p: dict, sensors):
        """One merge order for the filter and the method's options: their defaults, then the
        spec string's options, then the filter_* and NAME.<field> parameters a user set (those
        not at their defaults); the estimator applies them (create_estimator), so nothing sets
        its filter a second time."""
        name, spec = parse_estimator_spec(p["estimator"])
        options = dict(spec)
        options.update(self._method_options(p, name))
        if p["model_path"]:
            options["model_path"] = p["model_path"]
        options.update(self._shared_options(p))
        # a parameter set wins over the spec's same option: said, so the log shows what runs
        # (the spec's predict_ahead=0.2 was logged while the parameter's 0.1 stamped the poses)
        for key, value in spec.items():
            if key in options and options[key] != value:
                self.get_logger().warning(
                    f"the parameter sets {key} to {options[key]!r} over the estimator spec's {value!r}"
                )
        return create_estimator(name, sensors, self.skeleton, fps=p["output_rate"], **options)

    def _method_options(self, p: dict, method: str) -> dict:
        """The NAME.<field> parameters of a method that a user set (not at their defaults):
        given over the spec's NAME:key=value options, as the filter_* parameters are."""
        return {
            key.partition(".")[2]: p[key]
            for key, option in METHOD_OPTIONS.items()
            if key.partition(".")[0] == method and p[key] != option.default
        }

    def _make_budget_fallback(self, p: dict, sensors) -> Estimator | None:
        """The estimator for frames the estimator's step misses its budget on (None: none), with
        the same filter parameters, so both see the trackers alike."""
        name, options = parse_estimator_spec(p["budget_fallback"]) if p["budget_fallback"] else ("", {})
        if not name or name == parse_estimator_spec(p["estimator"])[0]:
            return None
        options.update(self._method_options(p, name))
        options.update(self._shared_options(p))
        return create_estimator(name, sensors, self.skeleton, fps=p["output_rate"], **options)

    def _shared_options(self, p: dict) -> dict:
        """What the estimator and its budget fallback are both given, so that their poses are
        alike: the filter_* parameters a user set, foot_lock and predict_ahead."""
        shared = {k: p[k] for k, (default, _) in self.PARAMETERS.items() if k.startswith(FILTER) and p[k] != default}
        if p.get("predict_ahead"):
            shared["predict_ahead"] = p["predict_ahead"]
        shared["foot_lock"] = bool(p["foot_lock"])
        return shared

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

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_timers()
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _stop_timers(self) -> None:
        if self.timer is not None:
            self.destroy_timer(self.timer)
        if self.diag_timer is not None:
            self.destroy_timer(self.diag_timer)
        self.timer = self.diag_timer = None

    def _release(self) -> None:
        for pub in (self.pub_joints, self.pub_contacts, self.pub_status, self.pub_tf, self.pub_diag):
            if pub is not None:
                self.destroy_lifecycle_publisher(pub)
        if self.pub_description is not None:
            self.destroy_publisher(self.pub_description)
        if self.tf_in is not None:
            self.tf_in.destroy()
        if self.live_view is not None:
            self.live_view.close()
            self.live_view = None
        if self.budgeted is not None:
            self.budgeted.close()  # the late step, if any, ends first
        self.tf_in = self.estimator = self.budgeted = None
        self.pub_joints = self.pub_contacts = self.pub_status = self.pub_tf = self.pub_diag = None
        self.pub_description = None
        self._last_good: BodyPose | None = None
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
        pose, reason = self._step(frame, deadline)
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
        if self.live_view is not None:
            self.live_view.log_trackers(frame, self.sensors.fixed_frame, self._frames)
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

    def _step(self, frame, deadline: float) -> tuple[BodyPose, str]:
        """The estimator's pose for frame, or budget_fallback's where the step is not done by
        the deadline (finite: a failure holds the last good pose), and what estimate_status
        says of it: why it is held, or that the fallback made it."""
        assert self.budgeted is not None
        try:
            pose, over_budget = self.budgeted.step(frame, deadline)
            if not pose.is_finite():
                raise FloatingPointError("estimator returned non-finite values")
        except Exception as err:  # noqa: BLE001 - a failing step must not take the node down
            self._stats.error(f"{type(err).__name__}: {err}")
            self.budgeted.reset()
            return self._held(frame.stamp), "estimator error; held"
        if over_budget:
            self._stats.over_budget += 1
        if pose.valid:
            self._last_good = pose
        if over_budget and pose.valid:  # a held one says why it is held
            assert self.budgeted.fallback is not None
            return pose, (
                f"{OVER_BUDGET} {self.budgeted.fallback.name}'s pose: {self._method()} took over "
                f"{self._step_budget() * 1000:.1f} ms"
            )
        depth = self.budgeted.estimator.out_of_depth() if pose.valid else None
        if depth is not None and depth[0] > 0.0:
            return pose, f"{OUT_OF_DEPTH} {depth[0]:.2f}: {depth[1]}"
        return pose, ""

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
        assert self.pub_joints and self.pub_contacts and self.pub_status and self.pub_tf and self.tf_in
        frame_id, p = self.sensors.fixed_frame, self.params
        # the estimate bag's encoder (io/cdr.py), one pose at a time: the same bytes live and
        # offline, without building a Python message object per field
        quats, root = pose.local_quats[None], pose.root_position[None]
        angles = joint_angles(quats)  # once: the JointState and the URDF's massless links
        (joints,), (contacts,), (status,) = cdr.estimate_messages(
            BodyPoses.of([pose]),
            self.skeleton,
            frame_id,
            reason or HELD,
            stamps=[stamp],
            angles=angles,
            valid_message=reason,
        )
        self.pub_joints.publish(joints)
        self.pub_contacts.publish(contacts)
        self.pub_status.publish(status)
        links = body_table(quats, root, self.skeleton, frame_id, p["frame_prefix"], p["publish_link_tf"])
        if p["publish_link_tf"]:  # the URDF's massless links too: RViz finds every link it draws
            links = links + axis_link_table(angles, self.skeleton, p["frame_prefix"])
        tf = cdr.tf_messages([stamp], links.parents, links.children, links.values)[0]
        self.pub_tf.publish(tf)
        self.tf_in.published(tf)
        if self.live_view is not None:
            for topic, data in (("/joint_states", joints), ("/foot_contacts", contacts), ("/estimate_status", status)):
                self.live_view.log(topic, data, stamp)
            self.live_view.log("/tf", tf, stamp)

    def _held(self, stamp: float) -> BodyPose:
        if self._last_good is None:
            return BodyPose(stamp, matrix_to_quat(standing_pose()), np.zeros(3), valid=False)
        return self._last_good.held(stamp)

    def _input_diagnostics(self) -> dict[str, str]:
        """What a node that reads more than trackers says of that input (the constraint node)."""
        return {}

    def _publish_diagnostics(self) -> None:
        assert self.tf_in is not None and self.pub_diag is not None  # the timer exists only while active
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
        self.pub_diag.publish(msg)
        if self.live_view is not None:
            from rclpy.serialization import serialize_message

            now = self.get_clock().now().nanoseconds * 1e-9
            self.live_view.log_description(now)
            self.live_view.log("/diagnostics", serialize_message(msg), now)


def main(args=None, node_class=None) -> None:
    init(args)  # from here a signal ends the node, also while it starts
    start_and_spin(node_class or EstimatorNode)


if __name__ == "__main__":
    main()
