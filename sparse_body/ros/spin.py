"""Starting and running a node until SIGINT / SIGTERM, the same way for every node's main().

rclpy's own signal handlers shut the context down from the signal, while the executor may be
taking a message: that race ended nodes with `RuntimeError: Unable to convert call argument`
and exit status 1. Here the signals only set a flag; the spin loop sees it within a tenth of
a second and the node is destroyed and the context shut down in order, from the main thread.

While the node starts (its constructor, then configure: models loaded, kernels compiled or
loaded) there is no spin loop to look at the flag, and a start could take a minute after a
fresh install: there the signal interrupts the start itself, and the process ends at once
with exit code 0, as a stop while spinning does (issue 52: Ctrl-C during the first start
waited for it, and `ros2 launch` escalated to SIGKILL).
"""

from __future__ import annotations

import _thread
import contextlib
import os
import signal
import sys
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions

_STOP = threading.Event()
_STARTING = threading.Event()  # set from init() until the node spins
_REPEATING = threading.Event()


def _on_signal(signum, frame) -> None:
    _STOP.set()
    if _STARTING.is_set():  # handlers run in the main thread, the one starting the node
        _keep_interrupting()
        raise KeyboardInterrupt


def _keep_interrupting() -> None:
    """An interrupt raised inside a C callback (numba's compiler is called back from LLVM) is
    dropped there: until the start has ended, raise it again every 0.2 s."""
    if _REPEATING.is_set():
        return
    _REPEATING.set()

    def repeat() -> None:
        while _STARTING.is_set():
            time.sleep(0.2)
            if _STARTING.is_set():
                _thread.interrupt_main(signal.SIGINT)  # runs _on_signal in the main thread

    threading.Thread(target=repeat, name="interrupt_start", daemon=True).start()


def _quiet_dropped_interrupts(unraisable) -> None:
    """Where a C callback dropped our interrupt, Python prints it as "Exception ignored"
    with a traceback; the start is being stopped, so that is not news. Nor is the failing
    __del__ of an llvmlite object whose construction the interrupt cut short (numba was
    compiling: it has no handle to free, and says so as it is collected)."""
    dropped = isinstance(unraisable.exc_value, KeyboardInterrupt)
    half_built = type(unraisable.object).__module__.startswith("llvmlite") or getattr(
        unraisable.object, "__module__", ""
    ).startswith("llvmlite")
    if not (_STOP.is_set() and (dropped or half_built)):
        sys.__unraisablehook__(unraisable)


def init(args=None) -> None:
    """rclpy.init without rclpy's signal handlers; SIGINT and SIGTERM ask spin_until_shutdown
    (or stop_requested()) to end."""
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _on_signal)
    sys.unraisablehook = _quiet_dropped_interrupts
    _STARTING.set()


def stop_requested() -> bool:
    return _STOP.is_set()


def start_and_spin(make_node, threads: int = 1) -> None:
    """A lifecycle node's main: make it (make_node: its class), configure and activate it when
    its autostart parameter says so (a configure that fails ends the process with exit code
    1, its reason logged by the node), then spin_until_shutdown. A signal before spinning
    ends the process with exit code 0."""
    from rclpy.lifecycle import TransitionCallbackReturn

    node = None
    try:
        node = make_node()
        if node.get_parameter("autostart").value:
            if node.trigger_configure() != TransitionCallbackReturn.SUCCESS:
                if _STOP.is_set():  # the signal cut numba's compile short, which made it its own error
                    raise KeyboardInterrupt
                node.get_logger().fatal("configure failed; exiting")
                node.destroy_node()
                rclpy.try_shutdown()
                sys.exit(1)
            node.trigger_activate()
        _STARTING.clear()
    except KeyboardInterrupt:
        while _STARTING.is_set():  # a repeated interrupt may land here, before the clear
            with contextlib.suppress(KeyboardInterrupt):
                _STARTING.clear()
        _ignore_signals()
        if node is not None:
            node.get_logger().info("stopped while starting")
            with contextlib.suppress(Exception):  # half made: what is there goes with the process
                node.destroy_node()
        rclpy.try_shutdown()
        _exit_now()
    spin_until_shutdown(node, threads)


def _exit_now() -> None:
    """Exit code 0 without Python's finalisation: the interrupt may have cut numba's compile
    short inside LLVM, and collecting those half-built objects at exit crashed the process
    (exit code -11, once in CI after "stopped while starting"). The node and the context are
    already gone; only the output is left to flush."""
    import ctypes

    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    with contextlib.suppress(Exception):  # rcutils logs through C's stdio
        ctypes.CDLL(None).fflush(None)
    os._exit(0)


def _ignore_signals() -> None:
    """The node is stopping: a second signal has nothing left to ask. A terminal's Ctrl-C
    reaches every process of a launch and launch then sends its own SIGINT; Python's
    finalisation puts the default handlers back, so that second SIGINT killed the exiting
    node (exit code -2, "process has died"). Ignored signals stay ignored."""
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)


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
        _ignore_signals()
