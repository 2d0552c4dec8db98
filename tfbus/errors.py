"""The whole exception tree of tfbus, in one module (httpx's ``_exceptions.py`` style).

The transform family keeps tf2's names (``tf2/exceptions.h``, ``tf2_py``); recordings,
the wire format and transports add their own branches under one base::

    TfbusError                         base of every error tfbus raises on purpose
    ├── TransformException             base of everything about transforms (tf2's)
    │   ├── LookupException            a frame id is unknown, or the tree has a loop
    │   ├── ConnectivityException      both frames known, but in different trees
    │   ├── ExtrapolationException     a link on the path has no data at that time
    │   ├── InvalidArgumentException   malformed input: bad frame id, NaN, ±Inf, bad quaternion
    │   ├── TimeoutException           an awaited transform did not arrive in time (also
    │   │                              TimeoutError)
    │   └── BufferClosedException      a wait ended because its Buffer closed or lost its feed
    ├── SimTimeStalled                 no /clock came for a SimClock's wall_timeout while
    │                                  waiting on simulated time (also TimeoutError)
    ├── URDFError                      a robot description cannot be used (also ValueError)
    ├── JointStateError                a JointState cannot become transforms (also ValueError)
    ├── BagError                       a recording cannot be read or written (``path``)
    │   ├── BagNotFoundError           the path does not exist (also FileNotFoundError)
    │   ├── BagFormatError             not a bag format tfbus reads (also ValueError)
    │   └── BagReadError               truncated or corrupt: reading stopped part-way
    │                                  (ScanError: its internal signal inside tfbus.bag)
    ├── WireError                      a payload cannot be encoded/decoded (also ValueError)
    │   ├── WireDecodeError            not a well-formed tfbus message
    │   ├── WireVersionError           another wire format version
    │   ├── WireLimitError             over a size/count/length bound
    │   └── WireEncodeError            the message cannot be put on the wire
    └── TransportError                 a transport cannot start or run (session, endpoint,
                                       middleware errors mapped from Zenoh, DDS, ROS 1)

Messages follow tf2's wording character for character where tf2 defines them.
Code catching ``Exception`` from older tfbus versions keeps working: every class here is
still an ``Exception`` (and the bag/wire ones keep their ``FileNotFoundError`` /
``ValueError`` mix-ins).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from enum import IntEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .time import Time, format_stamp

if TYPE_CHECKING:
    from .messages import TransformStamped

__all__ = [
    "TF2_ERROR_CLASSES",
    "BackwardExtrapolationException",
    "BagError",
    "BagFormatError",
    "BagNotFoundError",
    "BagReadError",
    "BufferClosedException",
    "ConnectivityException",
    "ExtrapolationException",
    "ForwardExtrapolationException",
    "InvalidArgumentException",
    "JointStateError",
    "LookupException",
    "LoopThreadError",
    "MissingExtraError",
    "NoDataForExtrapolationException",
    "SimTimeStalled",
    "TF2Error",
    "TfbusError",
    "TimeoutException",
    "TransformException",
    "TransportError",
    "URDFError",
    "WireDecodeError",
    "WireEncodeError",
    "WireError",
    "WireLimitError",
    "WireVersionError",
    "tf2_error",
    "tf2_error_code",
    "tf2_error_of",
]


class TfbusError(Exception):
    """Base of every error tfbus raises on purpose (transforms, bags, wire, transports)."""


class TransformException(TfbusError):
    """Base class of every transform error (``tf2::TransformException``)."""


class LookupException(TransformException):
    """A frame id does not exist, or the tf tree contains a loop (``tf2::LookupException``)."""


class ConnectivityException(TransformException):
    """The two frames are not part of the same tree (``tf2::ConnectivityException``)."""


class ExtrapolationException(TransformException):
    """A link on the path has no data at the requested time (``tf2::ExtrapolationException``).

    tf2 never extrapolates, not even by 1 ns.
    """


class BackwardExtrapolationException(ExtrapolationException):
    """The requested time is before the oldest sample of a link with two or more samples
    (ROS 2 tf2's ``BackwardExtrapolationException``: rolling ``tf2/src/cache.cpp``
    ``createExtrapolationException3``, ``TF2_BACKWARD_EXTRAPOLATION_ERROR``)."""


class ForwardExtrapolationException(ExtrapolationException):
    """The requested time is after the newest sample of a link with two or more samples
    (ROS 2 tf2's ``ForwardExtrapolationException``: rolling ``tf2/src/cache.cpp``
    ``createExtrapolationException2``, ``TF2_FORWARD_EXTRAPOLATION_ERROR``)."""


class NoDataForExtrapolationException(ExtrapolationException):
    """A link has no sample to interpolate from: it is empty, or holds one sample at
    another time (ROS 2 tf2's ``NoDataForExtrapolationException``: rolling
    ``tf2/src/cache.cpp`` ``findClosest`` and ``createExtrapolationException1``,
    ``TF2_NO_DATA_FOR_EXTRAPOLATION_ERROR``)."""


def extrapolation_exception(message: str) -> ExtrapolationException:
    """The ROS 2 class of an extrapolation failure whose ``message`` starts with tf2's
    detail for the failing link (``"Lookup would require extrapolation ..."``, tf2 0.7.6's
    wording, kept): ``... into the future`` is forward, ``... into the past`` backward,
    ``... at time T, but only time T1 is in the buffer`` or no detail (an empty link) no
    data, as rolling's ``TimeCache::findClosest`` chooses them. The message is kept."""
    detail = message.split(", when looking up transform", 1)[0]
    if "s into the future." in detail:
        return ForwardExtrapolationException(message)
    if "s into the past." in detail:
        return BackwardExtrapolationException(message)
    return NoDataForExtrapolationException(message)


class LoopThreadError(TfbusError, RuntimeError):
    """A blocking ``tfbus.compat`` call that would have to wait was made from an event
    loop's own thread (it would wait on the loop it blocks): await the ``*_async`` method
    there instead."""


class InvalidArgumentException(TransformException):
    """Malformed input: an empty or '/'-prefixed frame id in a query, or a transform with
    a NaN, an infinite value, a denormalised quaternion, an empty id or a self transform
    (``tf2::InvalidArgumentException``).

    Attributes:
        codes: for a rejected transform, tf2's ``TF_*`` codes in tf2's order
            (``TF_SELF_TRANSFORM``, ``TF_NO_CHILD_FRAME_ID``, ``TF_NO_FRAME_ID``,
            ``TF_NAN_INPUT``, then tfbus's ``TF_INF_INPUT``, then
            ``TF_DENORMALIZED_QUATERNION``); empty for invalid query arguments.
    """

    def __init__(self, message: str = "", codes: tuple[str, ...] = ()) -> None:
        super().__init__(message)
        self.codes = codes


class TimeoutException(TransformException, TimeoutError):
    """An awaited transform did not become available within the timeout
    (``tf2::TimeoutException``).

    Also a built-in :class:`TimeoutError` (what ``asyncio.timeout``, ``anyio.fail_after``
    and ``trio.fail_after`` raise on Python >= 3.11), so one ``except TimeoutError``
    covers tfbus's ``timeout=`` and the event loop's deadlines; ``except
    TransformException`` still catches it as tf2 code expects.
    """


class BufferClosedException(TransformException):
    """A wait on a :class:`~tfbus.buffer.Buffer` ended because nothing will feed it any
    more: the buffer was closed (``Buffer.close()`` / ``aclose()``), or the last
    :class:`~tfbus.listener.TransformListener` feeding it was left (leaving its
    ``async with`` block or the ``Bus`` under it). Every pending wait fails at once with
    it, so a server shutting down does not wait for each wait's own timeout.

    tfbus's own: tf2_ros has no such case (its waits poll until their timeout).
    """


# --------------------------------------------------------------------------- robots



TF2_ERROR_CLASSES: dict[int, type[TransformException]] = {
    1: LookupException,
    2: ConnectivityException,
    3: ExtrapolationException,
    4: InvalidArgumentException,
    5: TimeoutException,
    6: TransformException,
}
"""The exception class of each ``tf2_msgs/TF2Error`` error code (1 LOOKUP_ERROR,
2 CONNECTIVITY_ERROR, 3 EXTRAPOLATION_ERROR, 4 INVALID_ARGUMENT_ERROR, 5 TIMEOUT_ERROR,
6 TRANSFORM_ERROR; 0 NO_ERROR has none), as tf2_ros's ``buffer_client.py``
``processResult`` maps them; the LookupTransform action's server and client on ROS 1 and
ROS 2 use this one table."""


def tf2_error_code(exc: TransformException) -> int:
    """The ``tf2_msgs/TF2Error`` code of ``exc`` (tf2_ros ``buffer_server.cpp``'s catch
    order): its class's or its nearest base's in :data:`TF2_ERROR_CLASSES`, 6
    (TRANSFORM_ERROR) for any other transform error. ROS 2's extrapolation subclasses are
    3 (the message has no finer code)."""
    return next((c for c, cls in TF2_ERROR_CLASSES.items() if isinstance(exc, cls)), 6)


def tf2_error(code: int, message: str) -> TransformException:
    """The exception a ``tf2_msgs/TF2Error`` with ``code`` and ``message`` stands for
    (:data:`TF2_ERROR_CLASSES`; an unknown code is a plain :class:`TransformException`)."""
    return TF2_ERROR_CLASSES.get(code, TransformException)(message)

class TF2Error(IntEnum):
    """ROS 2 tf2's error codes, one per exception class (``tf2/include/tf2/exceptions.hpp``
    ``enum class TF2Error``, rolling): the per-row codes of a batched lookup under
    ``errors="mask"`` (:attr:`tfbus.core.batch.TransformArray.error_codes`). Codes 0-6 are
    also ``tf2_msgs/TF2Error``'s (the wire codes of the LookupTransform action, which has
    no finer extrapolation codes: :func:`tf2_error_code`)."""

    TF2_NO_ERROR = 0
    TF2_LOOKUP_ERROR = 1
    TF2_CONNECTIVITY_ERROR = 2
    TF2_EXTRAPOLATION_ERROR = 3
    TF2_INVALID_ARGUMENT_ERROR = 4
    TF2_TIMEOUT_ERROR = 5
    TF2_TRANSFORM_ERROR = 6
    TF2_BACKWARD_EXTRAPOLATION_ERROR = 7
    TF2_FORWARD_EXTRAPOLATION_ERROR = 8
    TF2_NO_DATA_FOR_EXTRAPOLATION_ERROR = 9


_TF2_ERROR_OF: tuple[tuple[type[TransformException], TF2Error], ...] = (
    (BackwardExtrapolationException, TF2Error.TF2_BACKWARD_EXTRAPOLATION_ERROR),
    (ForwardExtrapolationException, TF2Error.TF2_FORWARD_EXTRAPOLATION_ERROR),
    (NoDataForExtrapolationException, TF2Error.TF2_NO_DATA_FOR_EXTRAPOLATION_ERROR),
    (ExtrapolationException, TF2Error.TF2_EXTRAPOLATION_ERROR),
    (LookupException, TF2Error.TF2_LOOKUP_ERROR),
    (ConnectivityException, TF2Error.TF2_CONNECTIVITY_ERROR),
    (InvalidArgumentException, TF2Error.TF2_INVALID_ARGUMENT_ERROR),
    (TimeoutException, TF2Error.TF2_TIMEOUT_ERROR),
)


def tf2_error_of(exc: TransformException) -> TF2Error:
    """ROS 2 tf2's :class:`TF2Error` code of ``exc``: its own class's (the extrapolation
    subclasses before their base), ``TF2_TRANSFORM_ERROR`` for any other transform error
    (e.g. :class:`BufferClosedException`)."""
    return next((code for cls, code in _TF2_ERROR_OF if isinstance(exc, cls)),
                TF2Error.TF2_TRANSFORM_ERROR)


class SimTimeStalled(TfbusError, TimeoutError):
    """A wait on a :class:`~tfbus.clock.SimClock` saw no valid ``/clock`` message for the
    clock's ``wall_timeout`` seconds of wall time: the simulation (or bag player) that
    drives simulated time no longer publishes it, so the wait could otherwise last
    forever.

    Also a built-in :class:`TimeoutError`. Raised by the clock's ``sleep``,
    ``sleep_until``, ``move_on_after`` / ``fail_after`` blocks, and so by a
    :class:`~tfbus.buffer.Buffer`'s ``timeout=`` waits and ``every()`` timers on it.
    """


class URDFError(TfbusError, ValueError):
    """A robot description that cannot be used: not XML, not a URDF, or not one tree
    (:func:`tfbus.robot.load_urdf`; the checks of urdfdom's ``urdf_parser/src/model.cpp``).

    The message names the offending element (``joint 'elbow'``, ``link 'arm'``, the XML
    line). Also a :class:`ValueError`.

    Attributes:
        element: the offending element as ``"joint 'NAME'"``, ``"link 'NAME'"``,
            ``"line N"`` or ``"robot"``.
    """

    def __init__(self, message: str, element: str = "robot") -> None:
        super().__init__(message)
        self.element = element


class JointStateError(TfbusError, ValueError):
    """A JointState (or some of its positions) that cannot be turned into transforms
    (:meth:`tfbus.robot.RobotStatePublisher.transforms`; robot_state_publisher's
    ``JointStateListener::callbackJointState`` refuses the same messages). Also a
    :class:`ValueError`.

    Attributes:
        refused: joint name -> the offending position (NaN, ±Inf, not a number).
        transforms: the transforms of the other joints of the message, computed anyway
            (empty when the whole message is invalid).
    """

    def __init__(self, message: str, refused: dict[str, object] | None = None,
                 transforms: Sequence[TransformStamped] = ()) -> None:
        super().__init__(message)
        self.refused = dict(refused or {})
        self.transforms = list(transforms)


# --------------------------------------------------------------------------- recordings


class BagError(TfbusError):
    """Base of every error raised by :mod:`tfbus.bag`; ``path`` names the bag."""

    def __init__(self, message: str, path: str | os.PathLike[str] | None = None) -> None:
        super().__init__(message)
        self.path = None if path is None else Path(path)


class BagNotFoundError(BagError, FileNotFoundError):
    """The bag path does not exist (also a :class:`FileNotFoundError`)."""


class BagFormatError(BagError, ValueError):
    """The path exists but is not a bag format tfbus reads (also a :class:`ValueError`)."""


class SchemaParseError(ValueError):
    """A message definition stored in a bag does not parse: the message names the type
    and the first line that does not (one short line, never the whole definition;
    :mod:`tfbus.bag.decode`)."""


class BagReadError(BagError):
    """A truncated or corrupt bag: reading stopped part-way.

    Everything before the damage was returned (iterators) or stored (``partial``).

    Attributes:
        offset: byte offset in the file where reading stopped, when known.
        last_time: bag time of the last message read before the damage, or ``None``.
        messages_read: how many /tf and /tf_static messages were read before it.
        partial: whatever the raising function had built from the readable part (the
            :class:`~tfbus.core.BufferCore` for :func:`tfbus.bag.load_buffer`), else ``None``.
    """

    def __init__(
        self,
        message: str,
        path: str | os.PathLike[str] | None = None,
        *,
        offset: int | None = None,
        last_time: Time | None = None,
        messages_read: int = 0,
    ) -> None:
        where = []
        if offset is not None:
            where.append(f"byte {offset}")
        if last_time is not None:
            where.append(f"after bag time {format_stamp(last_time)}")
        where.append(f"{messages_read} tf message(s) read")
        super().__init__(f"{path}: {message}; reading stopped ({', '.join(where)})", path)
        self.reason = message
        self.offset = offset
        self.last_time = last_time
        self.messages_read = messages_read
        self.partial: Any = None


class ScanError(Exception):
    """Reading a damaged bag stopped at byte ``offset`` of the file for ``reason``.

    Internal to :mod:`tfbus.bag` (``salvage`` raises it, ``reader`` turns it into a
    :class:`BagReadError`): it never reaches a caller, so it is no :class:`TfbusError`
    and not in ``__all__``.
    """

    def __init__(self, reason: str, offset: int) -> None:
        super().__init__(reason)
        self.reason = reason
        self.offset = offset


# --------------------------------------------------------------------------- wire format


class WireError(TfbusError, ValueError):
    """A payload could not be encoded or decoded (base class; also a :class:`ValueError`)."""


class WireDecodeError(WireError):
    """The payload is not a well-formed tfbus message (bad magic, msgpack or shape)."""


class WireVersionError(WireError):
    """The payload is a tfbus message of another wire format version."""


class WireLimitError(WireError):
    """The payload exceeds a :class:`~tfbus.codecs.native.WireLimits` bound."""


class WireEncodeError(WireError):
    """The message cannot be put on the wire (unsupported type, negative stamp, ...)."""


# --------------------------------------------------------------------------- transports


class TransportError(TfbusError):
    """A transport could not start or keep running: its session, endpoint or middleware
    failed (Zenoh's ``ZError``, a DDS or ROS 1 master error, ...), mapped to this class so
    callers never match on another library's exception types. The original error is the
    ``__cause__``."""


class BadReply(TransportError):
    """A ROS 1 peer answered, but not with ROS XML-RPC: not HTTP 200, not XML, nested too
    deep, too large, an XML-RPC fault, or a value of the wrong shape
    (:mod:`tfbus.transports.ros1.rpc`)."""


class CallFailed(TransportError):
    """A well-formed ROS 1 XML-RPC answer whose code is not 1 (``-1`` error, ``0``
    failure): the peer refused the call, e.g. ``lookupNode`` of a node the master does not
    know (:mod:`tfbus.transports.ros1.rpc`).

    Attributes:
        code: the answer's status code, as received.
    """

    def __init__(self, message: str, code: object) -> None:
        super().__init__(message)
        self.code = code


class PortInUseError(OSError):
    """The port asked of ``tfbus view`` is taken (viser would silently move to the next
    one): :mod:`tfbus.view.server`."""


class RecordError(ValueError):
    """A recording of ``tfbus view`` cannot be started (:mod:`tfbus.view.record`): a name
    that is not a plain file name, a file that exists, a folder that does not exist or
    cannot be written (the message names it)."""


class MissingExtraError(ModuleNotFoundError, TfbusError):
    """A subpackage of tfbus needs an optional dependency that is not installed.

    A :class:`ModuleNotFoundError` (so ``except ImportError`` still catches it) whose
    message names the package, the extra and how to install it: ``advice``, which
    :func:`tfbus._extras.require` fills with :func:`tfbus._extras.extra_advice` (the two
    ``pip install`` forms, or for a tfbus installed editable from a clone the
    ``pip install -e`` that keeps it so) when it raises this at import of the subpackage.

    Attributes:
        name: the missing top-level package (as :class:`ModuleNotFoundError`'s).
        extra: the tfbus extra that installs it.
        needed_by: the tfbus module that needs it.
    """

    def __init__(self, needed_by: str, package: str, extra: str, advice: str | None = None) -> None:
        if advice is None:
            advice = (f"pip install 'tfbus[{extra}]' (from a clone of tfbus: pip install "
                      f"'.[{extra}]')")
        super().__init__(f"{needed_by} needs the '{package}' package: {advice}", name=package)
        self.extra = extra
        self.needed_by = needed_by
