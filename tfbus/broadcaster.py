"""Publishers of transforms: ``TransformBroadcaster`` (``/tf``) and
``StaticTransformBroadcaster`` (``/tf_static``), as in tf2_ros.

::

    await TransformBroadcaster(bus).send_transform(ts)            # one or a sequence
    StaticTransformBroadcaster(bus).send_transform_nowait([a, b])

Each call publishes one :class:`~tfbus.messages.TFMessage` holding all the transforms
given (batching many transforms in one message is much cheaper than one message each).
tf2_ros's C++ static broadcaster re-sends every static it ever sent because its topic
latches only the last message; tfbus's bus latches ``/tf_static`` per child frame, so
sending just the new ones is enough.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import ClassVar

from tfbus.bus import Bus
from tfbus.core import BufferCore
from tfbus.messages import TFMessage, TransformStamped
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC

__all__ = ["StaticTransformBroadcaster", "TransformBroadcaster"]


_plain_transform = BufferCore._plain_transform  # the core's (compiled or pure) quick test
# The same test, and the message of the one transform it accepts, in one call (C code
# in the compiled core, no Python frame).
_message_of_one = BufferCore._message_of_one


def _check(ts: TransformStamped) -> None:
    """Refuse what a receiving buffer would refuse, with the InvalidArgumentException
    ``BufferCore.set_transform`` raises (tf2 ``BufferCore::setTransformImpl``'s checks:
    self transform, empty frame id, NaN, infinite translation, quaternion norm).

    The common case (the message classes themselves, plain floats, finite, a unit
    quaternion, two different ids without a leading '/') passes the core's quick test
    (``CoreBase._plain_transform``: C code in the compiled core, no Python frame);
    anything else is given to a scratch BufferCore, the one authority on validity, which
    raises the very exception a listener would have logged (and accepts what it
    accepts).
    """
    if not _plain_transform(ts):
        BufferCore().set_transform(ts, "TransformBroadcaster")  # raises when invalid


def _as_message(transform: TransformStamped | Iterable[TransformStamped]) -> TFMessage:
    """The message a send of ``transform`` publishes, every transform checked (see
    :func:`_check`). The senders ask ``_message_of_one`` first (the common case: one
    transform the quick test accepts), and this only when it answers None."""
    if isinstance(transform, TransformStamped):
        _check(transform)
        return TFMessage((transform,))
    try:
        transforms = tuple(transform)
    except TypeError:
        raise TypeError(
            f"expected a TransformStamped or a sequence of them, not {type(transform).__name__}"
        ) from None
    for ts in transforms:
        if not isinstance(ts, TransformStamped):
            raise TypeError(f"expected TransformStamped, not {type(ts).__name__}")
        _check(ts)
    return TFMessage(transforms)


class TransformBroadcaster:
    """Publishes dynamic transforms on ``/tf`` (tf2_ros ``TransformBroadcaster``)."""

    topic: ClassVar[str] = TF_TOPIC

    def __init__(self, bus: Bus) -> None:
        """Broadcast on ``bus``.

        A transport that can announce a topic before sending on it (an ``advertise``
        method, as :class:`~tfbus.transports.ros1.Ros1Transport` has) is told now, as
        tf2_ros's broadcasters advertise their topic when constructed, so peers can
        connect before the first message.
        """
        self._bus = bus
        advertise = getattr(bus.transport, "advertise", None)
        if callable(advertise):
            advertise(self.topic)
        self.sent = 0
        """Transforms sent so far."""

    @property
    def bus(self) -> Bus:
        """The bus published on."""
        return self._bus

    def send_transform_nowait(
        self, transform: TransformStamped | Iterable[TransformStamped]
    ) -> None:
        """Publish ``transform`` (one or a sequence) as one TFMessage; never blocks.

        An empty sequence publishes nothing. Every transform is checked as a receiving
        buffer would check it, before anything is published: one invalid transform
        refuses the whole call, so a bad value is refused here, at the sender, and
        never reaches the listeners (which would only drop it and log).

        Raises:
            InvalidArgumentException: a transform ``BufferCore.set_transform`` refuses
                (NaN, an infinite translation, a quaternion whose squared norm is not
                within 0.01 of 1, an empty id, a self transform, a field of the wrong
                type), with the same message and ``codes``.
            TypeError: if ``transform`` is not a TransformStamped or an iterable of them.
            RuntimeError: if the bus is not open yet.
            anyio.ClosedResourceError: if the bus is closed.
        """
        message = _message_of_one(transform)  # the common case: one call, no frame
        if message is None:
            message = _as_message(transform)
            if not message.transforms:
                return
        self._bus.publish_nowait(self.topic, message)
        self.sent += len(message.transforms)

    async def send_transform(
        self, transform: TransformStamped | Iterable[TransformStamped]
    ) -> None:
        """:meth:`send_transform_nowait` plus a checkpoint; never waits for subscribers.

        Raises:
            InvalidArgumentException: as :meth:`send_transform_nowait` (nothing sent).
            TypeError: if ``transform`` is not a TransformStamped or an iterable of them.
            RuntimeError: if the bus is not open yet.
            anyio.ClosedResourceError: if the bus is closed.
            anyio.get_cancelled_exc_class(): if cancelled (before publishing).
        """
        message = _message_of_one(transform)  # _as_message's common case, inline
        if message is None:
            message = _as_message(transform)
            if not message.transforms:
                return
        # Bus.publish, inline: its checkpoint, the publish, its cancel-shielded yield.
        bus = self._bus
        maybe_cancelled = bus._maybe_cancelled
        if maybe_cancelled is None or maybe_cancelled():
            await bus._before_publish()
        # Bus.publish_nowait, inline (a TFMessage built here: nothing to type-check).
        if bus._state != "open":
            bus._check_open()
        topic = self.topic
        bus._deliver(topic, message)
        if bus._transport is not None:
            bus._transport.send_nowait(topic, message)
        self.sent += len(message.transforms)
        await bus._after_publish()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.topic} sent={self.sent}>"


class StaticTransformBroadcaster(TransformBroadcaster):
    """Publishes static transforms on ``/tf_static`` (tf2_ros
    ``StaticTransformBroadcaster``).

    The bus latches them per child frame: subscribers that arrive later still get the
    current static transform of every child, and re-sending a child replaces it.
    """

    topic: ClassVar[str] = TF_STATIC_TOPIC
