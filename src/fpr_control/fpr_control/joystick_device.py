"""Linux joystick API reader (``/dev/input/js*``, kernel Documentation/input/joydev/joystick-api.rst).

Each read returns 8-byte ``struct js_event { __u32 time (ms); __s16 value; __u8 type; __u8 number; }`` in the
machine's byte order (little-endian here). ``type``: 0x01 button, 0x02 axis, OR-ed with 0x80 for the initial
state events sent on open. Axis values are −32767..32767; like the ROS ``joy`` driver, they are published as
``−value / 32767`` (stick up / left = +1) unless ``invert_axes`` is False. No rclpy here.
"""

from __future__ import annotations

import errno
import os
import struct
from dataclasses import dataclass, field

JS_EVENT_FORMAT = "<IhBB"
JS_EVENT_SIZE = struct.calcsize(JS_EVENT_FORMAT)  # 8
JS_EVENT_BUTTON = 0x01
JS_EVENT_AXIS = 0x02
JS_EVENT_INIT = 0x80
#: Event numbers above this are treated as garbage (the kernel supports up to ABS_CNT axes / KEY_MAX buttons,
#: real pads have < 32 of each).
MAX_CONTROLS = 64


def pack_event(time_ms: int, value: int, event_type: int, number: int) -> bytes:
    """Bytes of one js_event (for tests and fake devices)."""
    return struct.pack(JS_EVENT_FORMAT, time_ms & 0xFFFFFFFF, value, event_type, number)


@dataclass
class JoystickState:
    """Decoded axes in [−1, 1] and buttons {0, 1}; grows to the highest event number seen."""

    invert_axes: bool = True
    axes: list[float] = field(default_factory=list)
    buttons: list[int] = field(default_factory=list)
    _buffer: bytes = b""
    garbage: int = 0

    def feed(self, data: bytes) -> int:
        """Decode whole events from ``data`` (partial events are kept for the next call); returns how many
        events changed the state."""
        self._buffer += data
        count = len(self._buffer) // JS_EVENT_SIZE
        changed = 0
        for k in range(count):
            _, value, event_type, number = struct.unpack_from(JS_EVENT_FORMAT, self._buffer, k * JS_EVENT_SIZE)
            kind = event_type & ~JS_EVENT_INIT
            if number >= MAX_CONTROLS or kind not in (JS_EVENT_AXIS, JS_EVENT_BUTTON):
                self.garbage += 1
                continue
            if kind == JS_EVENT_AXIS:
                _grow(self.axes, number, 0.0)
                scaled = max(-1.0, min(1.0, value / 32767.0))
                self.axes[number] = -scaled if self.invert_axes else scaled
            else:
                _grow(self.buttons, number, 0)
                self.buttons[number] = 1 if value else 0
            changed += 1
        self._buffer = self._buffer[count * JS_EVENT_SIZE:]
        return changed


def _grow(values: list, index: int, fill) -> None:
    if len(values) <= index:
        values.extend([fill] * (index + 1 - len(values)))


class JoystickDevice:
    """Non-blocking reader of a js device (or any file / FIFO holding js_event records)."""

    def __init__(self, path: str, invert_axes: bool = True) -> None:
        self.path = path
        self.state = JoystickState(invert_axes=invert_axes)
        self._fd: int | None = None

    @property
    def is_open(self) -> bool:
        return self._fd is not None

    def open(self) -> None:
        """Open the device (raises OSError if it is missing)."""
        self._fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)

    def close(self) -> None:
        if self._fd is not None:
            try:
                os.close(self._fd)
            finally:
                self._fd = None

    def poll(self) -> int:
        """Read everything available; returns the number of state changes. Raises OSError when the device
        went away (the caller closes and retries later)."""
        if self._fd is None:
            raise OSError(errno.EBADF, "joystick device not open")
        changed = 0
        while True:
            try:
                data = os.read(self._fd, 64 * JS_EVENT_SIZE)
            except BlockingIOError:
                break
            if not data:  # FIFO without writer, or end of a file: nothing more now
                break
            changed += self.state.feed(data)
        return changed
