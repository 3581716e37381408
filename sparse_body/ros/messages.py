"""Stamps <-> rclpy's builtin_interfaces/Time. The node's outputs are encoded by io/cdr.py,
the estimate bag's encoder, and published as bytes."""

from __future__ import annotations

from builtin_interfaces.msg import Time

from ..io.output import stamp_parts


def to_time(seconds: float) -> Time:
    sec, nanosec = stamp_parts(seconds)
    return Time(sec=sec, nanosec=nanosec)


def to_seconds(stamp: Time) -> float:
    return stamp.sec + stamp.nanosec * 1e-9
