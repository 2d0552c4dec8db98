from collections.abc import Callable, Generator
from typing import Any

class TopicCounters:
    published: int
    remote: int
    delivered: int
    dropped: int
    def __init__(self) -> None: ...

class CallbackFields:
    _callback: Callable[[Any], None]
    _delivered: int
    _counters: TopicCounters

class Delivery:
    def __init__(
        self,
        latch: Any,
        topic_counters: dict[str, Any],
        subscriptions: dict[str, list[Any]],
        callbacks: dict[str, list[Any]],
        new_counters: Callable[[str], Any],
    ) -> None: ...
    def deliver(self, topic: str, message: object) -> None: ...

class AsyncioCancelCalled:
    def __init__(self, loop: Any, tasks: dict[Any, Any], states: dict[Any, Any]) -> None: ...
    def called(self) -> bool: ...

class ShieldedYield:
    def __init__(self, loop: Any) -> None: ...
    def __await__(self) -> Generator[Any]: ...
