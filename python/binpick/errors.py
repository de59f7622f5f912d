"""The exceptions binpick raises.

``BinpickError`` is the base of all of them. Invalid input raises a subclass of both
``BinpickError`` and ``ValueError``; device faults raise ``DeviceError`` and its subclasses;
motion outside the cell's limits raises ``SafetyError`` before anything is sent. Ctrl-C during a
pick run raises ``RunInterrupted``, a KeyboardInterrupt that keeps the picks finished.
"""

from __future__ import annotations

from typing import Optional

__all__ = [
    "BinpickError",
    "InvalidInputError",
    "InvalidTypeError",
    "ShapeError",
    "DTypeError",
    "NonFiniteError",
    "TooFewPointsError",
    "DegenerateCloudError",
    "UnknownUnitError",
    "UnitError",
    "MeshFileError",
    "MeshFileNotFoundError",
    "FileWriteError",
    "CalibrationError",
    "UntrustedCalibrationError",
    "NoObjectFound",
    "DeviceError",
    "DeviceTimeout",
    "ProtocolError",
    "ChecksumError",
    "DeviceFault",
    "PortClosedError",
    "SafetyError",
    "InternalError",
    "ScanFormatError",
    "SingularGeometryError",
    "DegenerateModelWarning",
    "UntrustedCalibrationWarning",
]


class BinpickError(Exception):
    """Base class of every error binpick raises on purpose."""

    #: The message as a user of the ``binpick`` command reads it, where it names a Python fix
    #: (``unit="m"``) that the command spells as a flag (``--unit m``); None: ``str(error)`` reads
    #: the same to both. The commands print it in place of the message.
    cli_message: Optional[str] = None


class InvalidInputError(BinpickError, ValueError):
    """An argument is wrong: its message names the argument, the problem and the fix."""


class InvalidTypeError(InvalidInputError, TypeError):
    """An argument has the wrong Python type (a string or a bool where a number is expected)."""


class ShapeError(InvalidInputError):
    """An array has the wrong shape (for example not ``(N, 3)``)."""


class DTypeError(InvalidInputError, TypeError):
    """An array's dtype cannot be converted to float64 (strings, objects, complex)."""


class NonFiniteError(InvalidInputError):
    """An array holds NaN or infinity."""


class TooFewPointsError(InvalidInputError):
    """A cloud has fewer points than the method needs."""


class DegenerateCloudError(InvalidInputError):
    """A cloud's points are all equal, collinear, or otherwise span too few dimensions."""


class UnknownUnitError(InvalidInputError):
    """A length unit binpick does not know; use mm, cm, m or in."""


class UnitError(InvalidInputError):
    """A length no bin-picking cell can mean as given, most often a file read in the wrong unit: a
    part in metres read as millimetres is a fraction of a millimetre across, a scene in metres is a
    speck beside its part. The message says which size is off, against what, and, where a unit
    explains it, that unit and how to pass it (:mod:`binpick._sizes`)."""


class MeshFileError(InvalidInputError):
    """A mesh or point-cloud file is corrupt, empty or of an unsupported format."""


class MeshFileNotFoundError(MeshFileError, FileNotFoundError):
    """A mesh or point-cloud file does not exist or cannot be opened."""


class FileWriteError(BinpickError, OSError):
    """A result file could not be written."""


class CalibrationError(InvalidInputError):
    """A calibration file or calibration data is missing, inconsistent or insufficient."""


class UntrustedCalibrationError(CalibrationError):
    """A calibration was made but cannot be trusted (too few views, too alike, too little of the
    image covered, a large residual or an uncertain focal length); the message names each cause
    and its fix. ``quality`` holds the figures, ``calibration`` the result refused."""

    def __init__(self, message: str, calibration: object = None) -> None:
        super().__init__(message)
        self.calibration = calibration
        self.quality = getattr(calibration, "quality", None)


class NoObjectFound(BinpickError):
    """No object in the scene matches the model well enough; binpick never returns a guess."""


class DeviceError(BinpickError):
    """A device (robot, motor, gripper, camera) failed or answered something unusable."""


class DeviceTimeout(DeviceError, TimeoutError):
    """A device did not answer within the allowed time."""


class ProtocolError(DeviceError):
    """A device's reply is garbled, truncated or not what the protocol allows."""


class ChecksumError(ProtocolError):
    """A reply's checksum or CRC does not match its content."""


class DeviceFault(DeviceError):
    """The device answered with an error of its own (for example the robot controller's QeR)."""


class PortClosedError(DeviceError):
    """The serial port is closed or disappeared."""


class SafetyError(BinpickError):
    """A motion would leave the cell's limits; nothing was sent to the device."""


class InternalError(BinpickError, RuntimeError):
    """A bug in binpick's native core was caught before it could crash Python; please report it."""


class ScanFormatError(InvalidInputError):
    """A scan folder's scan.json is missing, corrupt or of a version this binpick does not read."""


class SingularGeometryError(InvalidInputError):
    """The geometry has no unique answer: a camera ray parallel to the laser plane, a point behind
    the camera, calibration poses that do not constrain the unknowns."""


class TruncatedReplyError(ProtocolError):
    """A device's reply stopped part-way: some bytes arrived, the rest never did."""


class UnknownReplyError(ProtocolError):
    """A device answered with a well-formed reply that the protocol does not define for the request."""


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped :meth:`binpick.cell.Cell.run`: a KeyboardInterrupt (so that it stops a program
    as Ctrl-C does) carrying the :class:`~binpick.cell.RunReport` of the picks finished before it
    (``report``), for the caller to keep."""

    def __init__(self, report: object) -> None:
        super().__init__("interrupted (Ctrl-C)")
        self.report = report


__all__ += ["TruncatedReplyError", "UnknownReplyError", "RunInterrupted"]


class UntrustedCalibrationWarning(UserWarning):
    """A calibration that cannot be trusted was kept on request (``accept_untrusted=True``);
    the warning names each cause."""


class DegenerateModelWarning(UserWarning):
    """A part's surface cannot be located along some motion (``Model.degenerate``): one face of a
    box slides in its own plane, a tube without ends along its axis. Its poses come back with
    confidence 0."""
