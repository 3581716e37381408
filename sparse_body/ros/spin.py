"""Starting and running a node until SIGINT / SIGTERM, the same way for every node's main().

rclpy's own signal handlers shut the context down from the signal, while the executor may be
taking a message: that race ended nodes with `RuntimeError: Unable to convert call argument`
and exit status 1. Here the signals only set a flag; the spin loop sees it within a tenth of
a second and the node is destroyed and the context shut down in order, from the main thread.
"""

from __future__ import annotations

import signal
import sys
import threading

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions

_STOP = threading.Event()


def _on_signal(signum, frame) -> None:
    _STOP.set()


def init(args=None) -> None:
    """rclpy.init without rclpy's signal handlers; SIGINT and SIGTERM ask spin_until_shutdown
    (or stop_requested()) to end."""
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _on_signal)


def stop_requested() -> bool:
    return _STOP.is_set()


def start_and_spin(node, threads: int = 1) -> None:
    """A lifecycle node's main: configure and activate it when its autostart parameter says so
    (a configure that fails ends the process with exit code 1, its reason logged by the node),
    then spin_until_shutdown."""
    from rclpy.lifecycle import TransitionCallbackReturn

    if node.get_parameter("autostart").value:
        if node.trigger_configure() != TransitionCallbackReturn.SUCCESS:
            node.get_logger().fatal("configure failed; exiting")
            node.destroy_node()
            rclpy.try_shutdown()
            sys.exit(1)
        node.trigger_activate()
    spin_until_shutdown(node, threads)


def spin_until_shutdown(node, threads: int = 1) -> None:
    """Spin until a signal (or an external shutdown), then destroy the node and shut down.
    threads > 1: a multi-threaded executor, so a callback in its own group can wait without
    stopping the others. An error raised while stopping is part of stopping, not a failure."""
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor

    executor = MultiThreadedExecutor(num_threads=threads) if threads > 1 else SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while not _STOP.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:  # noqa: BLE001 - re-raised unless the node was being stopped
        if not _STOP.is_set() and rclpy.ok():
            raise
    finally:
        try:
            executor.shutdown(timeout_sec=1.0)
            node.destroy_node()
        except Exception:  # noqa: BLE001 - destroying after the context went away
            pass
        rclpy.try_shutdown()
        # The node is stopping: a second signal has nothing left to ask. A terminal's Ctrl-C
        # reaches every process of a launch and launch then sends its own SIGINT; Python's
        # finalisation puts the default handlers back, so that second SIGINT killed the
        # exiting node (exit code -2, "process has died"). Ignored signals stay ignored.
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, signal.SIG_IGN)
