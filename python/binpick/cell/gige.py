"""A GigE Vision camera as a frame source, through Aravis (:class:`GigEVisionCamera`).

Aravis is a C library with GObject introspection; binpick reaches it through PyGObject
(``pip install "binpick[gige]"``) and Debian's ``gir1.2-aravis-0.8`` (``aravis-tools`` brings
``arv-fake-gv-camera-0.8``, a GigE Vision camera in software, to try it on 127.0.0.1).

Each grab takes one whole frame exposed after the call: with the software trigger (the default)
binpick triggers the exposure once the laser motor has stopped; free-running, it drops the
frames queued before the call and waits for the next. Nothing goes by unnoticed: a frame that
arrives incomplete (lost packets the resends did not recover) raises DeviceError naming it, a
frame that never comes raises DeviceTimeout, and a gap in the frame ids of a triggered camera
raises DeviceError naming the frames lost. Each frame's camera timestamp (ns) and id are kept
(:attr:`GigEVisionCamera.timestamps_ns`, :attr:`GigEVisionCamera.frame_ids`).
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from .._validate import choice, positive
from ..errors import DeviceError, DeviceTimeout
from .frames import FrameSource

__all__ = ["GigEVisionCamera", "load_aravis"]

#: GigE Vision 1.x block ids count 1..65535 and wrap past 0.
_MAX_BLOCK_ID = 0xFFFF


def load_aravis() -> Any:
    """The Aravis 0.8 module; DeviceError saying what to install when it is missing."""
    try:
        import gi

        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis
    except (ImportError, ValueError):
        raise DeviceError(
            "camera: GigE Vision needs Aravis 0.8 through PyGObject: on Debian or Ubuntu, "
            "`apt install gir1.2-aravis-0.8 libgirepository1.0-dev libcairo2-dev` and "
            '`pip install "binpick[gige]"` (aravis-tools adds the fake camera arv-fake-gv-camera-0.8)'
        ) from None
    return Aravis


class GigEVisionCamera(FrameSource):
    """A GigE Vision camera opened with Aravis (see the module docstring).

    Args:
        device_id: Aravis's id of the camera (``Vendor-Model-Serial`` as ``arv-tool-0.8`` lists
            it, or its IP address); None opens the first camera found.
        exposure_us: exposure time, µs (None: the camera's own).
        gain_db: gain, dB (None: the camera's own).
        trigger: ``"software"`` (a frame per grab, exposed on binpick's trigger) or ``"free"``
            (free-running at the camera's frame rate).
        timeout_s: longest wait for one frame, s.
        buffers: frame buffers queued to the stream.
        packet_resend: ask the camera to resend lost packets (GigE Vision's resend requests).
    """

    def __init__(
        self,
        device_id: Optional[str] = None,
        *,
        exposure_us: Optional[float] = None,
        gain_db: Optional[float] = None,
        trigger: str = "software",
        timeout_s: float = 2.0,
        buffers: int = 8,
        packet_resend: bool = True,
    ) -> None:
        self.trigger = choice(trigger, "trigger", ("software", "free"))
        self.timeout_s = positive(timeout_s, "timeout_s", "s")
        Aravis = self._aravis = load_aravis()
        try:
            self._camera = Aravis.Camera.new(device_id)
        except Exception as exc:  # GLib.Error: no such camera, or it answered nothing
            raise DeviceError(
                f"camera: cannot open the GigE Vision camera {device_id or '(the first found)'} ({exc}); "
                "check that it is powered and on this network (arv-tool-0.8 lists the cameras Aravis sees)"
            ) from None
        cam = self._camera
        self.device_id = cam.get_device_id()
        try:
            if cam.is_gv_device():
                # Loopback and most NICs deliver packets to a socket; the packet socket needs a real link.
                cam.gv_set_stream_options(Aravis.GvStreamOption.PACKET_SOCKET_DISABLED)
            if exposure_us is not None:
                cam.set_exposure_time(positive(exposure_us, "exposure_us", "µs"))
            if gain_db is not None:
                cam.set_gain(float(gain_db))
            cam.set_acquisition_mode(Aravis.AcquisitionMode.CONTINUOUS)
            if self.trigger == "software":
                cam.set_trigger("Software")
            else:
                cam.clear_triggers()
            self.pixel_format = cam.get_pixel_format_as_string()
            self._stream = cam.create_stream(None, None)
            if cam.is_gv_device():
                self._stream.set_property("socket-buffer", Aravis.GvStreamSocketBuffer.AUTO)
                self._stream.set_property(
                    "packet-resend",
                    Aravis.GvStreamPacketResend.ALWAYS if packet_resend else Aravis.GvStreamPacketResend.NEVER,
                )
            payload = cam.get_payload()
            for _ in range(max(2, int(buffers))):
                self._stream.push_buffer(Aravis.Buffer.new_allocate(payload))
            cam.start_acquisition()
        except Exception as exc:
            raise DeviceError(f"camera: the GigE Vision camera {self.device_id} refused its settings ({exc})") from None
        self.exposure_us = float(cam.get_exposure_time())
        self.timestamps_ns: list[int] = []
        self.frame_ids: list[int] = []
        self.dropped_before_grab = 0
        self._last_id: Optional[int] = None
        self._prime()

    #: Frames taken and dropped at most when the stream starts, waiting for a whole one.
    PRIME_FRAMES = 5

    def _prime(self) -> None:
        """Takes frames until a whole one arrives: the first after the stream starts may have
        been in flight already (its first packets sent before binpick listened) or exposed
        before the settings took effect. Its id starts the sequence the grabs check."""
        for _ in range(self.PRIME_FRAMES):
            self._drain()
            if self.trigger == "software":
                self._camera.software_trigger()
            buffer = self._stream.timeout_pop_buffer(int(self.timeout_s * 1e6))
            if buffer is None:
                continue
            ok = buffer.get_status() == self._aravis.BufferStatus.SUCCESS
            frame_id = int(buffer.get_frame_id())
            self._stream.push_buffer(buffer)
            if ok:
                self._last_id = frame_id
                return
        raise DeviceError(
            f"camera {self.device_id}: no whole frame in its first {self.PRIME_FRAMES}; check the link, the NIC's "
            "buffers and the packet size"
        )

    def _drain(self) -> int:
        """Returns the queued frames to the stream (frames exposed before the call); how many."""
        n = 0
        while True:
            buffer = self._stream.try_pop_buffer()
            if buffer is None:
                return n
            self._stream.push_buffer(buffer)
            n += 1

    def grab(self) -> np.ndarray:
        """One whole frame exposed after the call, uint8 BGR (H, W, 3)."""
        Aravis = self._aravis
        stale = self._drain()
        if self.trigger == "software":
            self.dropped_before_grab += stale  # a triggered camera sends nothing unasked
            self._camera.software_trigger()
        buffer = self._stream.timeout_pop_buffer(int(self.timeout_s * 1e6))
        if buffer is None:
            raise DeviceTimeout(f"camera {self.device_id}: no frame within {self.timeout_s:g} s")
        try:
            frame_id, status = int(buffer.get_frame_id()), buffer.get_status()
            if status != Aravis.BufferStatus.SUCCESS:
                self._last_id = frame_id
                raise DeviceError(
                    f"camera {self.device_id}: frame {frame_id} arrived incomplete ({status.value_nick}); "
                    "its lost packets were not resent — check the link, the NIC's buffers and the packet size"
                )
            self._check_sequence(frame_id, stale)
            image = self._image(buffer)
            self.timestamps_ns.append(int(buffer.get_timestamp()))
            self.frame_ids.append(frame_id)
            return image
        finally:
            self._stream.push_buffer(buffer)

    def _check_sequence(self, frame_id: int, stale: int) -> None:
        last, self._last_id = self._last_id, frame_id
        if self.trigger != "software" or last is None:
            return
        expected = last + 1 + stale
        expected = (expected - 1) % _MAX_BLOCK_ID + 1 if frame_id <= _MAX_BLOCK_ID else expected
        if frame_id != expected:
            raise DeviceError(
                f"camera {self.device_id}: frame {frame_id} came after frame {last}: the frames between were lost"
            )

    def _image(self, buffer: Any) -> np.ndarray:
        w, h = int(buffer.get_image_width()), int(buffer.get_image_height())
        data = np.frombuffer(buffer.get_data(), dtype=np.uint8)
        fmt = self.pixel_format
        if fmt == "Mono8" and data.size >= w * h:
            gray = data[: w * h].reshape(h, w)
            return np.repeat(gray[:, :, None], 3, axis=2)
        if fmt == "Mono16" and data.size >= 2 * w * h:
            gray = (data[: 2 * w * h].view("<u2").reshape(h, w) >> 8).astype(np.uint8)
            return np.repeat(gray[:, :, None], 3, axis=2)
        if fmt in ("RGB8", "BGR8") and data.size >= 3 * w * h:
            img = data[: 3 * w * h].reshape(h, w, 3)
            return np.ascontiguousarray(img[:, :, ::-1] if fmt == "RGB8" else img)
        raise DeviceError(
            f"camera {self.device_id}: pixel format {fmt} ({data.size} bytes for {w}×{h}) is not one binpick reads; "
            "set the camera to Mono8, Mono16, RGB8 or BGR8"
        )

    def close(self) -> None:
        try:
            self._camera.stop_acquisition()
        except Exception:  # the camera may be gone already; nothing to release then
            pass
