from collections.abc import Callable
from typing import Any

class InlineHandler:
    @property
    def messages(self) -> int: ...
    @property
    def stored(self) -> int: ...
    @property
    def refused(self) -> int: ...
    def __init__(
        self,
        listener: Any,
        static: bool,
        store: Callable[[Any, str], bool],
        store_many: Callable[[Any, str, bool], Any],
        now_ns: Callable[[], int],
        authority: str,
        publisher_authority: bool,
    ) -> None: ...
    def __call__(self, message: object) -> None: ...
