"""The exception hierarchy, with tf2's names (``tf2/exceptions.h``, ``tf2_py``).

::

    TransformException                 base of everything tfbus raises about transforms
    ├── LookupException                a frame id is unknown, or the tree has a loop
    ├── ConnectivityException          both frames known, but in different trees
    ├── ExtrapolationException         a link on the path has no data at that time
    ├── InvalidArgumentException       malformed input: bad frame id, NaN, ±Inf, bad quaternion
    └── TimeoutException               an awaited transform did not arrive in time

Messages follow tf2's wording character for character where tf2 defines them.
"""

from __future__ import annotations

__all__ = [
    "ConnectivityException",
    "ExtrapolationException",
    "InvalidArgumentException",
    "LookupException",
    "TimeoutException",
    "TransformException",
]


class TransformException(Exception):
    """Base class of every transform error (``tf2::TransformException``)."""


class LookupException(TransformException):
    """A frame id does not exist, or the tf tree contains a loop (``tf2::LookupException``)."""


class ConnectivityException(TransformException):
    """The two frames are not part of the same tree (``tf2::ConnectivityException``)."""


class ExtrapolationException(TransformException):
    """A link on the path has no data at the requested time (``tf2::ExtrapolationException``).

    tf2 never extrapolates, not even by 1 ns.
    """


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


class TimeoutException(TransformException):
    """An awaited transform did not become available within the timeout
    (``tf2::TimeoutException``)."""
