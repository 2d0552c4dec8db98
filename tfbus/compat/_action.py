"""tf2_ros's ``LookupTransform`` action client (actionlib over TCPROS) on the process's
ROS 1 node: the topics of :class:`tfbus.compat.tf2_ros.BufferClient`.

actionlib's ``SimpleActionClient(ns, LookupTransformAction)`` publishes ``{ns}/goal``
(``tf2_msgs/LookupTransformActionGoal``) and ``{ns}/cancel`` (``actionlib_msgs/GoalID``)
and subscribes to ``{ns}/result`` and ``{ns}/status``. Here those four topics are carried
by the process's one ROS 1 node (:func:`tfbus.compat._loop.ros1_bus`, tfbus's ROS 1
transport: :meth:`~tfbus.transports.ros1.Ros1Transport.advertise_raw` and
:meth:`~tfbus.transports.ros1.Ros1Transport.subscribe_raw`), next to ``/tf`` and
``/tf_static``; the messages are encoded and decoded by the codecs of
:mod:`tfbus.remote.ros1` (whose server answers them too). Everything here runs in the
background loop; the blocking calls of :class:`~tfbus.compat.tf2_ros.BufferClient`
wait in their own thread through its portal, woken by the result that answers them.
"""

from __future__ import annotations

import time as _wallclock
from typing import Any

import anyio

from tfbus import errors
from tfbus.messages import TransformStamped
from tfbus.remote.ros1 import (
    CANCEL_MD5,
    CANCEL_TYPE,
    GOAL_MD5,
    GOAL_TYPE,
    RESULT_MD5,
    RESULT_TYPE,
    STATUS_MD5,
    STATUS_TYPE,
    decode_result_status,
    encode_goal,
    encode_goal_id,
    result_transform,
)
from tfbus.time import Time

__all__ = ["ActionClient"]

_Answer = tuple[TransformStamped, int, str, int, str]  # transform, code, message, status, text


class ActionClient:
    """The ``LookupTransform`` action client of namespace ``ns`` on a ROS 1 transport
    (one per namespace and process; make it in the background loop).

    Attributes:
        malformed: results that did not decode (counted, dropped).
        cancelled: goals cancelled on the server because their wait ended here first.
    """

    def __init__(self, transport: Any, ns: str) -> None:
        """Advertise ``goal`` and ``cancel`` and subscribe to ``result`` and ``status``
        under ``ns`` (made global: ``tf2_buffer_server`` is ``/tf2_buffer_server``).

        Raises:
            ValueError: ``ns`` is not a ROS graph name.
        """
        base = "/" + ns.strip("/")
        self.ns = base
        self._transport = transport
        self.goal_topic, self.cancel_topic = f"{base}/goal", f"{base}/cancel"
        self.result_topic, self.status_topic = f"{base}/result", f"{base}/status"
        transport.advertise_raw(self.goal_topic, GOAL_TYPE, GOAL_MD5)
        transport.advertise_raw(self.cancel_topic, CANCEL_TYPE, CANCEL_MD5)
        transport.subscribe_raw(self.result_topic, RESULT_TYPE, RESULT_MD5, self._on_result)
        transport.subscribe_raw(self.status_topic, STATUS_TYPE, STATUS_MD5, self._on_status)
        self._waiting: dict[str, tuple[anyio.Event, list[_Answer]]] = {}
        self._status = anyio.Event()
        self._seq = 0
        self.malformed = 0
        self.cancelled = 0

    def ready(self) -> bool:
        """actionlib ``ActionClient::waitForServer``'s condition: the server's node
        reads our ``goal`` and ``cancel`` and we receive its ``result`` and ``status``."""
        c = self._transport.connections
        return bool(c(self.goal_topic)[1] and c(self.cancel_topic)[1]
                    and c(self.result_topic)[0] and c(self.status_topic)[0])

    async def wait_ready(self) -> None:
        """Wait until :meth:`ready`: checked as each status message arrives (the
        server's ``GoalStatusArray`` at its ``status_frequency``, 5 Hz by default)."""
        while not self.ready():
            await self._status.wait()

    def _on_status(self, _payload: bytes, _callerid: str) -> None:
        event, self._status = self._status, anyio.Event()
        event.set()

    def _on_result(self, payload: bytes, _callerid: str) -> None:
        try:
            goal_id, ts, code, message, status, text = decode_result_status(payload)
        except ValueError:
            self.malformed += 1
            return
        waiting = self._waiting.get(goal_id)
        if waiting is not None and not waiting[1]:
            waiting[1].append((ts, code, message, status, text))
            waiting[0].set()

    async def lookup(self, target: str, source: str, source_time: Time, timeout: float,
                     target_time: Time, fixed: str, advanced: bool,
                     padding: float) -> TransformStamped:
        """Send one goal and wait for its result at most ``timeout + padding`` wall
        seconds (tf2_ros ``BufferClient.__process_goal``: ``wait_for_result(goal.timeout
        + self.timeout_padding)``), waiting for the server first within the same bound.
        A goal whose wait ends here unanswered (the bound, or a cancellation) is
        cancelled on the server (``actionlib_msgs/GoalID`` with its id, as actionlib's
        ``ClientGoalHandle.cancel``), so the server does not hold it for nobody.

        Raises:
            TimeoutException: no result within the bound (tf2_ros's message), or a
                result whose status is not SUCCEEDED.
            the server's tf2 error, as :func:`tfbus.remote.ros1.result_transform`.
        """
        self._seq += 1
        now = _wallclock.time_ns()
        # actionlib's GoalIDGenerator: "<caller id>-<count>-<secs>.<nsecs>"
        goal_id = (f"{self._transport.node_name}-{self._seq}-{now // 1_000_000_000}."
                   f"{now % 1_000_000_000:09d}")
        done = anyio.Event()
        box: list[_Answer] = []
        self._waiting[goal_id] = (done, box)
        sent = False
        try:
            with anyio.move_on_after(timeout + padding):
                await self.wait_ready()
                self._transport.send_raw_nowait(self.goal_topic, encode_goal(
                    goal_id, self._seq, target, source, source_time, timeout, target_time,
                    fixed, advanced))
                sent = True
                await done.wait()
        finally:
            self._waiting.pop(goal_id, None)
            if sent and not box:
                self.cancelled += 1
                self._transport.send_raw_nowait(self.cancel_topic,
                                                encode_goal_id(Time(0), goal_id))
        if not box:
            raise errors.TimeoutException(  # tf2_ros buffer_client.py's words, as they are
                "The LookupTransform goal sent to the BufferServer did not come back in the "
                "specified time. Something is likely wrong with the server")
        return result_transform(*box[0])
