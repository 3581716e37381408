"""Serial tracker devices with pyserial: read, decode, map device time, reconnect.

The port is anything pyserial's serial_for_url opens: /dev/ttyUSB0, a pseudo-terminal,
loop:// or socket://host:port. When the device goes away (unplugged, the port vanishes)
the reader keeps trying to open it again every reconnect_interval seconds.
"""

from __future__ import annotations

import contextlib
import threading
import time

from .device_clock import DeviceClock
from .sample import TrackerSample
from .serial_protocol import FrameDecoder


class SerialTrackerReader:
    def __init__(
        self, port: str, on_samples, baudrate: int = 921600, reconnect_interval: float = 0.5, clock_window: float = 5.0
    ) -> None:
        if not port:
            raise ValueError("no serial port given")
        self.port, self.baudrate, self.reconnect_interval = port, baudrate, reconnect_interval
        self.decoder = FrameDecoder()
        self.clocks: dict[int, DeviceClock] = {}
        self._clock_window = clock_window
        self._on_samples = on_samples
        self.connects = 0
        self.disconnects = 0
        self.last_error = ""
        self.connected = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="serial-trackers", daemon=True)
        self._thread.start()

    def _open(self):
        import serial

        try:
            return serial.serial_for_url(self.port, baudrate=self.baudrate, timeout=0.05)
        except (serial.SerialException, OSError, ValueError) as err:
            self.last_error = str(err)
            return None

    def _run(self) -> None:
        import serial

        while not self._stop.is_set():
            port = self._open()
            if port is None:
                self._stop.wait(self.reconnect_interval)
                continue
            self.connects += 1
            self.connected.set()
            self.decoder.discard()
            try:
                while not self._stop.is_set():
                    data = port.read(port.in_waiting or 1)
                    if data:
                        self._handle(data, time.time())
            except (serial.SerialException, OSError, TypeError) as err:
                # TypeError: some pyserial versions fail this way when the fd vanishes mid-read
                self.last_error = str(err)
                self.disconnects += 1
            finally:
                self.connected.clear()
                with contextlib.suppress(Exception):  # closing a dead port may fail in any way
                    port.close()
            self._stop.wait(self.reconnect_interval)

    def _handle(self, data: bytes, arrival: float) -> None:
        samples = []
        for frame in self.decoder.feed(data):
            clock = self.clocks.setdefault(frame.device_id, DeviceClock(self._clock_window))
            stamp = clock.to_host(frame.device_time_us, arrival)
            samples.append(TrackerSample(f"serial:{frame.device_id}", stamp, frame.orientation, frame.position))
        if samples:
            self._on_samples(samples)

    def diagnostics(self) -> tuple[str | None, dict[str, str]]:
        """(the problem, if any; figures) for the bridge's diagnostic status."""
        st = self.decoder.stats
        values = {
            "frames": str(st.frames),
            "garbage bytes": str(st.garbage_bytes),
            "bad checksums": str(st.bad_checksums),
            "bad values": str(st.bad_values),
            "connects": str(self.connects),
            "disconnects": str(self.disconnects),
        }
        return (None if self.connected.is_set() else f"{self.port} not open: {self.last_error}"), values

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
