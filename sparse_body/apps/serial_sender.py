"""A reference sender of the serial tracker protocol: what a microcontroller tracker does,
in Python, for testing a setup without hardware and for the end-to-end tests.

    python -m sparse_body.apps.serial_sender --pty /tmp/ttyTRACKERS --rate 200
    python -m sparse_body.apps.serial_sender --port /dev/ttyUSB0 --sensors four_point

It plays a motion's virtual trackers (the synthetic walk, or a motion file) at --rate Hz,
one device per tracker site (ids 1, 2, ... in the sensor configuration's order; sites the
configuration measures as orientation send orientation-only frames). --pty makes a
pseudo-terminal and links its device to the given path; --disconnect-at closes it for
--offline seconds and opens a fresh one under the same path, as an unplugged USB device
would. --garbage, --bad-crc and --split disturb the byte stream on purpose.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from ..adapters.serial_protocol import encode_frame


class PtyPort:
    """The master side of a pseudo-terminal whose slave device is linked at a path."""

    def __init__(self, link: Path) -> None:
        import tty

        self.link = Path(link)
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tmp = self.link.with_name(self.link.name + ".new")
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(os.ttyname(self.slave))
        os.replace(tmp, self.link)

    def write(self, data: bytes) -> None:
        os.write(self.master, data)

    def close(self) -> None:
        self.link.unlink(missing_ok=True)
        os.close(self.master)
        os.close(self.slave)


def open_port(args):
    if args.pty:
        return PtyPort(Path(args.pty))
    import serial

    return serial.serial_for_url(args.port, baudrate=args.baudrate)


def main(argv=None) -> int:
    from ..core.sensors import load_sensor_config
    from ..data.catalog import load_motion_file
    from ..data.synthetic import synthetic_walk
    from ..data.virtual_trackers import synthesize_trackers

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--port", help="a serial port or pyserial URL to write to")
    where.add_argument("--pty", help="create a pseudo-terminal and link its device here")
    p.add_argument("--baudrate", type=int, default=921600)
    p.add_argument("--sensors", default="four_point")
    p.add_argument("--motion", help="a motion file (default: the synthetic walk)")
    p.add_argument("--rate", type=float, default=200.0, help="frames per second per device")
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--start-us", type=int, default=0, help="device clock at the start (wraps at 2^32)")
    p.add_argument("--garbage", type=float, default=0.0, help="probability of random bytes before a frame")
    p.add_argument("--bad-crc", type=float, default=0.0, help="probability of a corrupted frame")
    p.add_argument("--split", action="store_true", help="write each frame in two pieces, 1 ms apart")
    p.add_argument("--disconnect-at", type=float, default=-1.0, help="seconds in: close the port")
    p.add_argument("--offline", type=float, default=1.0, help="seconds the port stays away")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)

    config = load_sensor_config(args.sensors)
    motion = (
        load_motion_file(Path(args.motion), args.rate) if args.motion else synthetic_walk(args.seconds, fps=args.rate)
    )
    stream = synthesize_trackers(motion, config)
    rng = np.random.default_rng(args.seed)
    port = open_port(args)
    print(f"sending {len(config.sites)} devices at {args.rate:g} Hz to {args.pty or args.port}", flush=True)
    start = time.monotonic()
    disconnected = False
    try:
        for i in range(min(len(stream), int(args.seconds * args.rate))):
            target = start + i / args.rate
            time.sleep(max(0.0, target - time.monotonic()))
            if not disconnected and 0 <= args.disconnect_at <= i / args.rate:
                port.close()
                print("disconnected", flush=True)
                time.sleep(args.offline)
                port = open_port(args)
                print("reconnected", flush=True)
                disconnected = True
            device_us = args.start_us + int(round((time.monotonic() - start) * 1e6))
            for s, site in enumerate(config.sites):
                position = stream.positions[i, s] if site.has_position else None
                frame = encode_frame(s + 1, device_us, stream.orientations[i, s], position)
                if rng.random() < args.bad_crc:
                    broken = bytearray(frame)
                    broken[12] ^= 0xFF
                    frame = bytes(broken)
                if rng.random() < args.garbage:
                    frame = bytes(rng.integers(0, 256, size=int(rng.integers(1, 40)), dtype=np.uint8)) + frame
                if args.split:
                    cut = int(rng.integers(1, len(frame)))
                    port.write(frame[:cut])
                    time.sleep(0.001)
                    frame = frame[cut:]
                port.write(frame)
    except (BrokenPipeError, OSError) as err:
        print(f"serial_sender: {err}", file=sys.stderr)
        return 1
    finally:
        port.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
