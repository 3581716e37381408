"""Each node's own parameters, one options dataclass a node (as every method has one): a field
is a parameter, declared once with its default, what it does and, for a number, its range;
ros/parameters.py turns a dataclass into the node's declared, described and checked
parameters, and a test holds config/*.yaml and the launch file's defaults equal to these.

The estimator node's table adds the tracker filter's, the shared estimator options it sets
itself and every method's (ros/estimator_parameters.py); the constraint node's is the estimator
node's less what chooses an estimator, plus its input's. No ROS import here: the docs and the
tests read these without rclpy.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..adapters.vmc import DEFAULT_PORT
from ..core.options import Options, option
from ..io.tf_cache import TfGuards
from .tracker_sources import SOURCES


@dataclass(frozen=True)
class EstimatorNodeOptions(Options):
    owner = "the estimator node"

    sensors: str = option("six_point", "sensor configuration: a name under config/sensors or a YAML path")
    # its help names every estimator: estimator_parameters.py fills it in from the registry
    estimator: str = option(
        "auto", "estimation method: auto (the one recommended for the sensors) or NAME:key=value,... (docs above)"
    )
    model_path: str = option("", "model file for learned estimators; empty: the shipped model")
    fixed_frame: str = option("", "frame the trackers are looked up in; empty: the sensor configuration's")
    height: float = option(
        1.75, "the tracked person's height in metres (scales the canonical body; unused with a calibration)", 0.5, 2.5
    )
    calibration: str = option(
        "",
        "T-pose calibration YAML (the tracker bridge's ~/calibrate writes one): the body it fitted "
        "is the one estimated and published; empty: the canonical body at height",
    )
    output_rate: float = option(
        60.0,
        "estimates per second when the trackers do not drive them (input slow, partial or "
        "absent); estimates driven by tracker input are limited to twice this",
        0.1,
        1000.0,
    )
    step_budget: float = option(
        0.0,
        "seconds an estimator's step may take before budget_fallback gives that frame's pose "
        "instead (flagged on estimate_status, counted on /diagnostics), so a slow step never puts "
        "the output behind the trackers; 0: three quarters of the output period (1/output_rate)",
        0.0,
        1.0,
    )
    budget_fallback: str = option(
        "ik",
        "the cheaper estimator whose pose is published for a frame the estimator's step has not "
        "given within step_budget; empty, or the estimator itself: every step is waited for",
    )
    stale_timeout: float = option(
        0.1,
        "a tracker's newest sample no longer counts when it is this many seconds (or three of "
        "the tracker's own sample intervals, if longer) behind the newest tracker sample",
        0.001,
        10.0,
    )
    tracker_timeout: float = option(
        1.0,
        "seconds in which no new tracker sample arrived after which the estimate is held, "
        "invalid: the trackers stopped (a node running late on a busy CPU stays valid)",
        0.01,
        60.0,
    )
    clock_window: float = option(
        TfGuards.clock_window,
        "a /tf stamp further than this many seconds from this node's clock is refused and counted "
        "(a frame stamped 0; a bag replayed with its recorded stamps without use_sim_time); 0: no check",
        0.0,
        1e9,
    )
    future_window: float = option(
        TfGuards.future_window,
        "a /tf stamp more than this many seconds ahead of this node's clock is refused and counted "
        "(a sender whose clock runs ahead: its estimates would be stamped in the future); only "
        "while clock_window is above 0",
        0.001,
        60.0,
    )
    play_radius: float = option(
        TfGuards.play_radius,
        "a tracker further than this many metres from the fixed frame's origin is refused",
        0.1,
        1e6,
    )
    frame_prefix: str = option("", "prefix of the body's TF frames")
    publish_link_tf: bool = option(True, "publish every body link on /tf (off when robot_state_publisher does)")
    autostart: bool = option(False, "configure and activate on start-up (without a lifecycle manager)")
    foxglove_port: int = option(
        0,
        "serve the outputs, the trackers and the URDF to the Foxglove app on this WebSocket port "
        "(open ws://foxglove_host:PORT; needs foxglove-sdk); 0: off",
        0,
        65535,
    )
    foxglove_host: str = option(
        "127.0.0.1", "address the Foxglove WebSocket server listens on (0.0.0.0: every network)"
    )


@dataclass(frozen=True)
class ConstraintNodeInputOptions(Options):
    """What the constraint node takes beside the estimator node's (less what chooses one)."""

    owner = "the constraint node"

    model_path: str = option("", "folder holding dragposer_encoder.onnx and dragposer_decoder.onnx; empty: the shipped")
    frame_prefix: str = option("refined/", "prefix of the refined body's TF frames")
    input_prefix: str = option("", "prefix of the input estimate's TF frames (its root is <input_prefix>pelvis)")
    input_timeout: float = option(0.2, "seconds after which the newest input estimate no longer counts", 0.01, 60.0)


@dataclass(frozen=True)
class TrackerBridgeOptions(Options):
    owner = "the tracker bridge"

    source: str = option("bag", "where tracker poses come from (ros/tracker_sources.py)", choices=tuple(SOURCES))
    sensors: str = option("six_point", "sensor configuration naming the body sites' TF frames and fixed frame")
    bag: str = option("", "source bag: rosbag2 directory (or .mcap / .db3 file) holding tracker /tf")
    rate: float = option(1.0, "source bag: playback speed factor", 0.01, 100.0)
    loop: bool = option(False, "source bag: start again at the end")
    restamp: bool = option(True, "source bag: stamp transforms with the current time instead of the recorded one")
    min_subscribers: int = option(1, "wait until this many /tf subscribers are matched before publishing", 0, 1000)
    wait_for_nodes: tuple[str, ...] = option(
        ("",),
        "names of nodes whose /tf subscription playback also waits for (the launch file names "
        "the nodes it starts that read /tf); empty: any subscribers count",
    )
    start_delay: float = option(0.5, "seconds to wait after that, so late subscribers can connect too", 0.0, 60.0)
    devices: tuple[str, ...] = option(
        ("",),
        "vmc / serial: PATTERN=SITE entries mapping device names (hmd:NAME, con:NAME, "
        "tra:NAME, serial:ID) to body sites; empty: hmd:*=head for vmc, serial:N = "
        "the N-th site of the sensor configuration for serial",
    )
    vmc_host: str = option("127.0.0.1", "vmc: address to listen on")
    vmc_port: int = option(DEFAULT_PORT, "vmc: UDP port to listen on", 1, 65535)
    serial_port: str = option("", "serial: device or pyserial URL (/dev/ttyUSB0, loop://, socket://host:port)")
    serial_baudrate: int = option(921600, "serial: baud rate", 300, 10_000_000)
    stale_after: float = option(
        0.25, "vmc / serial: samples older than this (s) when they arrive are dropped and counted", 0.001, 60.0
    )
    calibration: str = option(
        "", "T-pose calibration YAML: applied at start when it exists; where ~/calibrate saves by default"
    )
    calibration_dir: str = option(
        "",
        "folder under which a ~/calibrate request's save_path may write (it must exist); "
        "empty: requests cannot name a file, only the calibration parameter's is written",
    )
    autostart: bool = option(True, "configure and activate on start-up (false: wait for a lifecycle manager)")


@dataclass(frozen=True)
class RetargetOptions(Options):
    owner = "the retarget node"

    robot: str = option(
        "", "the robot's mapping YAML (config/robots/*.yaml): which robot links follow which human joints"
    )
    robot_urdf: str = option("", "the robot's URDF file; empty: the one the mapping names")
    fixed_frame: str = option("world", "the frame the body's root is looked up in and the robot's base is placed in")
    input_prefix: str = option("", "prefix of the body's TF frames (its root is <input_prefix>pelvis)")
    frame_prefix: str = option("robot/", "prefix of the robot's TF frames: its base link is <frame_prefix><base>")
    publish_link_tf: bool = option(True, "publish every robot link on /tf (off when robot_state_publisher does)")
    solve_budget: float = option(
        0.1, "seconds one robot pose's solve may take; past it the last robot pose is held, counted", 0.001, 10.0
    )
    warn_window: float = option(
        10.0, "seconds /diagnostics says WARN after an input was dropped, then OK again (the counts stay)", 0.1, 3600.0
    )
    autostart: bool = option(False, "configure and activate on start-up (without a lifecycle manager)")
