"""``--bus`` strings: one table of transport schemes, parsed here, opened lazily.

A bus spec names a transport and its options::

    memory                                  in-process only (nothing leaves the process)
    zenoh                                   Zenoh, this machine, no configuration
    zenoh:tcp/10.0.0.2:7448                 a bare value sets the scheme's default key
                                            (zenoh: connect)
    zenoh:connect=tcp/127.0.0.1:7447&name=planner     key=value options after ':'
    zenoh?listen=tcp/0.0.0.0:7448&namespace=robot1    ... or after '?' (both may be used)

Grammar: ``scheme [":" (key=value ["&" key=value]... | bare value)] ["?" key=value
["&" key=value]...]``. Values given after ``key=`` are URL-decoded (``%2C``); a key may
be repeated, and a value may list several items separated by ``,``. Keys are checked
against the scheme's known keys here, without importing the transport.

Each scheme is one :class:`TransportScheme` row of one table (the built-in rows are at
the bottom of this module; :func:`register_scheme` adds more at run time). A row names the
module implementing the transport, imported only when the scheme is opened -- so parsing
never needs an optional dependency, and a missing one gives one clear
:class:`~tfbus.errors.TransportError` naming the extra to install. That module provides
``transport_from_spec(spec: BusSpec, **overrides) -> Transport``.
"""

from __future__ import annotations

import importlib
import importlib.util
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, cast
from urllib.parse import parse_qsl

from tfbus.bus import Bus, Transport
from tfbus.errors import TransportError

__all__ = [
    "BusSpec",
    "TransportScheme",
    "open_bus",
    "open_transport",
    "parse_bus_spec",
    "register_scheme",
    "schemes",
]

DEFAULT_BUS: Final = "zenoh"
"""The bus of the command line when ``--bus`` is not given."""
BUS_HELP: Final = (
    f"Bus to use (default {DEFAULT_BUS!r}: this machine, no configuration), e.g. "
    "'zenoh?listen=tcp/127.0.0.1:7500', 'zenoh:tcp/192.168.1.10:7448', 'ros2', "
    "'ros2:domain=7' (ROS 2 over DDS), 'rmw_zenoh:tcp/127.0.0.1:7447' (ROS 2 over "
    "rmw_zenoh, through its router), 'ros1', 'ros1:http://127.0.0.1:11311' (a ROS 1 "
    "master; default ROS_MASTER_URI), 'memory' (this process only)."
)
"""The one help text of every command's ``--bus`` option."""
_KEY_VALUE: Final = re.compile(r"[A-Za-z_][A-Za-z0-9_]*=")
_TRUE: Final = frozenset({"1", "true", "yes", "on"})
_FALSE: Final = frozenset({"0", "false", "no", "off", ""})


@dataclass(frozen=True, slots=True)
class BusSpec:
    """A parsed ``--bus`` value (:func:`parse_bus_spec`).

    Attributes:
        scheme: the transport's scheme (``"zenoh"``, ``"memory"``, ...).
        options: every option given, key -> its values in order (a key given with an
            empty value maps to ``()``).
        text: the string it was parsed from.
    """

    scheme: str
    options: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    text: str = ""

    def values(self, key: str) -> tuple[str, ...] | None:
        """All values of ``key``, or None when the key was not given."""
        return self.options.get(key)

    def value(self, key: str) -> str | None:
        """The one value of ``key``, or None when not given (or given empty).

        Raises:
            ValueError: if ``key`` was given more than one value.
        """
        values = self.options.get(key)
        if not values:
            return None
        if len(values) > 1:
            raise ValueError(f"bus option {key!r} given more than once")
        return values[0]

    def integer(self, key: str, default: int, *, minimum: int | None = None,
                maximum: int | None = None) -> int:
        """``key`` as an integer (``default`` when not given), within ``minimum`` ..
        ``maximum`` (inclusive) when they are given.

        Raises:
            ValueError: if the value is not an integer or out of range (the message
                names the key, the value and the range).
        """
        text = self.value(key)
        if text is None:
            return default
        try:
            number = int(text)
        except ValueError:
            raise ValueError(f"bus option {key!r} must be an integer, got {text!r}") from None
        if (minimum is not None and number < minimum) or (maximum is not None
                                                           and number > maximum):
            low = "" if minimum is None else minimum
            high = "" if maximum is None else maximum
            raise ValueError(f"bus option {key!r} must be in {low}..{high}, got {text!r}")
        return number

    def boolean(self, key: str, default: bool = False) -> bool:
        """``key`` as a boolean: ``1/true/yes/on`` or ``0/false/no/off``.

        Raises:
            ValueError: for any other value (the message names the key).
        """
        text = self.value(key)
        if text is None:
            return default
        if text.lower() in _TRUE:
            return True
        if text.lower() in _FALSE:
            return False
        raise ValueError(f"bus option {key!r} must be a boolean, got {text!r}")


@dataclass(frozen=True, slots=True)
class TransportScheme:
    """One row of the scheme table: how to parse and open one kind of bus.

    Attributes:
        scheme: the name before ``:`` / ``?`` (``"zenoh"``).
        module: the module implementing it, imported only when the scheme is opened;
            it defines ``factory``.
        keys: the option keys it accepts (checked when parsing).
        default_key: the key a bare ``scheme:value`` sets (``"connect"`` for zenoh), or
            None if a bare value is an error.
        extra: the ``pip install 'tfbus[extra]'`` extra that provides ``requires``.
        requires: top-level modules that must be importable (checked before importing
            ``module``, to name the missing extra instead of showing an ImportError).
        factory: the name of ``transport_from_spec(spec, **overrides) -> Transport``
            in ``module``.
        summary: one line for help texts.
        peer_aware: its transports are :class:`~tfbus.transports._base.PeerAware` (they
            know their peers: Zenoh's liveliness), so a command can say so before opening.
        scan_topics: its factory takes a ``scan_topics=`` override, the
            ``sensor_msgs/LaserScan`` topics to subscribe to (ROS 1: a subscription has a
            type); a scheme that carries every topic (memory, Zenoh) needs none.
        fleet_option: the option key that, set to ``*``, makes a bus carry every robot's
            frames under its namespace (Zenoh's ``namespace=*``; read by
            :class:`~tfbus.fleet.FleetBuffer`); None when the scheme has no fleet form.
            :meth:`is_fleet` asks it of a parsed spec.
        unknown_authority: the broadcaster name the middleware's own tools show for a
            transform whose sender it cannot name (ROS 1: ``unknown_publisher``,
            roscpp's ``MessageEvent`` default that tf_monitor prints); None: the
            command line's own word.
        clock_topic: its factory takes a ``clock_topic=`` override, the topic of
            ``rosgraph_msgs/Clock`` to carry for a :class:`~tfbus.clock.SimClock` (ROS 1
            and ROS 2: a subscription has a type); a scheme that carries every topic
            (memory, Zenoh) needs none.
    """

    scheme: str
    module: str
    keys: frozenset[str] = frozenset()
    default_key: str | None = None
    extra: str | None = None
    requires: tuple[str, ...] = ()
    factory: str = "transport_from_spec"
    summary: str = ""
    peer_aware: bool = False
    scan_topics: bool = False
    fleet_option: str | None = None
    unknown_authority: str | None = None
    clock_topic: bool = False

    def is_fleet(self, spec: BusSpec) -> bool:
        """Whether ``spec`` (a parsed bus of this scheme) is a fleet bus: its
        :attr:`fleet_option` is ``*``.

        Raises:
            ValueError: the option was given more than one value (:meth:`BusSpec.value`).
        """
        return self.fleet_option is not None and spec.value(self.fleet_option) == "*"


_SCHEMES: dict[str, TransportScheme] = {}


def register_scheme(scheme: TransportScheme, *, replace: bool = False) -> None:
    """Add a scheme to the table (the built-in ones are registered at import).

    Raises:
        ValueError: if the name is not a plain identifier, or is taken and not
            ``replace``.
    """
    if not re.fullmatch(r"[a-z][a-z0-9_]*", scheme.scheme):
        raise ValueError(f"scheme {scheme.scheme!r} must be a lower-case identifier")
    if scheme.scheme in _SCHEMES and not replace:
        raise ValueError(f"bus scheme {scheme.scheme!r} is already registered")
    _SCHEMES[scheme.scheme] = scheme


def schemes() -> dict[str, TransportScheme]:
    """The registered schemes by name (a copy)."""
    return dict(_SCHEMES)


def _unknown(spec: str) -> ValueError:
    known = ", ".join(sorted(_SCHEMES))
    return ValueError(
        f"unsupported bus {spec!r}: expected one of {known}, optionally followed by "
        "':key=value&...' or '?key=value&...' (e.g. 'zenoh:connect=tcp/10.0.0.2:7448')"
    )


def parse_bus_spec(spec: str) -> BusSpec:
    """Parse a ``--bus`` value (see the module docstring for the grammar).

    Raises:
        ValueError: unknown scheme, unknown option key, or a bare value for a scheme
            without a default key (the message names the spec and the known keys).
    """
    text = spec.strip()
    head, has_query, query = text.partition("?")
    name, _, body = head.partition(":")
    info = _SCHEMES.get(name.strip().lower())
    if info is None:
        raise _unknown(spec)
    pairs: list[tuple[str, str]] = []
    if body:
        if _KEY_VALUE.match(body):
            pairs += parse_qsl(body, keep_blank_values=True)
        elif info.default_key is not None:
            pairs.append((info.default_key, body))
        else:
            raise ValueError(f"bus {info.scheme!r} takes key=value options, got {body!r}")
    if has_query:
        pairs += parse_qsl(query, keep_blank_values=True)
    options: dict[str, tuple[str, ...]] = {}
    for key, value in pairs:
        if key not in info.keys:
            known = ", ".join(sorted(info.keys)) or "none"
            raise ValueError(f"unknown bus option {key!r} (known: {known})")
        options[key] = options.get(key, ()) + tuple(v for v in value.split(",") if v)
    return BusSpec(info.scheme, options, spec)


def open_transport(
    spec: BusSpec | str,
    *,
    default_name: str | None = None,
    scan_topics: Sequence[str] = (),
    **overrides: Any,
) -> Transport:
    """A new transport for ``spec`` (its scheme's module is imported now).

    ``overrides`` go to the scheme's factory (e.g. ``name="tfbus-monitor"`` for zenoh).
    ``default_name`` is the node's name for the schemes whose nodes have one (a ``name``
    key: zenoh, ros1) when neither the spec nor ``overrides`` gives one.
    ``scan_topics`` are ``sensor_msgs/LaserScan`` topics the transport must carry: given
    to the factory of a scheme that subscribes by type (:attr:`TransportScheme.scan_topics`,
    ROS 1), carried anyway by the others (memory, Zenoh: every topic).

    Raises:
        ValueError: an invalid spec or option value.
        TransportError: the scheme's optional dependencies are not installed (the
            message names the extra: ``pip install 'tfbus[zenoh]'``), or the transport
            rejects its configuration.
    """
    parsed = parse_bus_spec(spec) if isinstance(spec, str) else spec
    info = _SCHEMES.get(parsed.scheme)
    if info is None:
        raise _unknown(parsed.text or parsed.scheme)
    for required in info.requires:
        if importlib.util.find_spec(required) is None:
            extra = f" (pip install 'tfbus[{info.extra}]')" if info.extra else ""
            raise TransportError(
                f"the {info.scheme!r} bus needs the Python package {required!r}, which is "
                f"not installed{extra}"
            )
    module = importlib.import_module(info.module)
    factory = cast(Callable[..., Transport], getattr(module, info.factory))
    if (
        default_name is not None
        and "name" in info.keys
        and "name" not in overrides
        and parsed.value("name") is None
    ):
        overrides["name"] = default_name
    if info.scan_topics and scan_topics:
        overrides["scan_topics"] = tuple(scan_topics)
    return factory(parsed, **overrides)


def open_bus(
    spec: BusSpec | str,
    *,
    queue_size: int = 100,
    default_name: str | None = None,
    **overrides: Any,
) -> Bus:
    """A new, not yet opened :class:`~tfbus.bus.Bus` on ``spec``'s transport
    (``async with open_bus("zenoh") as bus:``). Raises as :func:`open_transport`, and
    ValueError for a ``queue_size`` below 1."""
    transport = open_transport(spec, default_name=default_name, **overrides)
    return Bus(transport=transport, queue_size=queue_size)


# -- the built-in schemes: one row each ------------------------------------------------

register_scheme(
    TransportScheme(
        "memory",
        "tfbus.transports.memory.options",
        summary="in-process only: nothing leaves this process",
    )
)
register_scheme(
    TransportScheme(
        "zenoh",
        "tfbus.transports.zenoh.options",
        keys=frozenset(
            {"connect", "listen", "config", "prefix", "namespace", "name", "port", "express",
             "mode", "congestion_control", "connect_timeout"}
        ),
        default_key="connect",
        extra="zenoh",
        requires=("zenoh", "msgspec"),
        summary="Zenoh: this machine by default, or connect/listen endpoints",
        peer_aware=True,
        fleet_option="namespace",
    )
)
register_scheme(
    TransportScheme(
        "ros2",
        "tfbus.transports.ros2.options",
        keys=frozenset({"domain", "config", "interfaces", "peers"}),
        default_key="domain",
        extra="ros2",
        requires=("cyclonedds",),
        summary="ROS 2 over DDS (Cyclone): /tf and /tf_static with ROS 2 nodes, loopback",
        clock_topic=True,
    )
)
register_scheme(
    TransportScheme(
        "ros1",
        "tfbus.transports.ros1.options",
        keys=frozenset({"master", "name", "host", "remote"}),
        default_key="master",
        extra="ros1",
        requires=("rosbags",),
        summary="ROS 1 node (TCPROS): ROS_MASTER_URI, else http://127.0.0.1:11311",
        scan_topics=True,
        unknown_authority="unknown_publisher",
        clock_topic=True,
    )
)
register_scheme(
    TransportScheme(
        "rmw_zenoh",
        "tfbus.transports.rmw_zenoh.options",
        keys=frozenset({"connect", "listen", "mode", "domain", "namespace", "name",
                        "attachment", "connect_timeout"}),
        default_key="connect",
        extra="zenoh",
        requires=("zenoh",),
        summary="ROS 2 on rmw_zenoh: /tf and /tf_static through a Zenoh router (spec-tested)",
        peer_aware=True,
        fleet_option="namespace",
    )
)
