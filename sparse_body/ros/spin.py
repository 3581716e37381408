"""Running a node until Ctrl-C or shutdown, the same way for every node's main()."""
from __future__ import annotations

import rclpy
from rclpy.executors import ExternalShutdownException


def spin_until_shutdown(node, threads: int = 1) -> None:
    """Spin until SIGINT / SIGTERM (rclpy's handlers shut the context down) and end without a
    traceback: an error raised by a callback that raced the shutdown (its context already
    gone) is part of stopping, not a failure. threads > 1: a multi-threaded executor, so a
    callback in its own group can wait without stopping the others."""
    try:
        if threads > 1:
            from rclpy.executors import MultiThreadedExecutor
            rclpy.spin(node, executor=MultiThreadedExecutor(num_threads=threads))
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:  # noqa: BLE001 - re-raised unless the context was shut down under it
        if rclpy.ok():
            raise
    finally:
        try:
            node.destroy_node()
        except Exception:  # noqa: BLE001 - destroying after the context went away
            pass
        rclpy.try_shutdown()
