"""The gateway's address space: one object per line, one per drive, in OPC 40400's words.

::

    Objects/
      Lines/                               (folder)
        <line>/                            line object: the bus health counters
          Protocol, Url                    properties
          Connected, DrivesOnline, Utilisation, Requests, Replies, Timeouts, ...
          Drive<node>/                     drive object (the frequency converter and its axis)
            Line, Node, Protocol, UnitId   properties
            Online                         the poller's verdict (always Good)
            Monitoring/                    OPC 40400-2: IMonitoringElectric,
                                           PtFrequencyDriveAxisType
              ConverterOutputFrequency     Hz   (output frequency)
              FrequencyCommandValue        Hz   (the set frequency, as read back)
              ConverterOutputCurrent       A
              ConverterOutputVoltage       V
              ConverterOutputPower         kW   (where the protocol measures it)
              OutputTorque                 %    (where measured; no 40400 name in %)
              ShaftTurningDirection        stopped | forward | reverse
              Running, Tripped, State
            Logbook/                       (40400: PtLogbookType)
              ActiveTrip, TripCount
              TripCodes, TripMeanings,     the trip history, one array per field,
              TripOutputFrequencies,       newest first, as many entries as the
              TripOutputCurrents,          drive keeps records (SJ300 6, FR-700 8);
              TripOutputVoltages           the values at each trip
            Parameters/                    the polled and the granted parameters, in their units
              <code>                       writable where the line grants it
            TakeControl(), Run(Direction), Stop(), SetFrequency(Frequency)
                                           where the line grants control

docs/OPCUA.md has the table mapping each name to OPC 40400 and saying
where ours differs. Each variable is a :class:`Binding`: how to read its
value and read time from a snapshot, and what it last showed; the server
(:mod:`._server`) serves reads from it and pushes changes to
subscriptions.

A variable's quality is not judged here: a value of one of the snapshot's
read groups (status, monitor, direction, set frequency, trips) is judged
by the drive as served (:meth:`ServedDrive.quality
<sj300_async.gateway.ServedDrive.quality>`, with its group's deadline), a
polled parameter likewise (:meth:`~sj300_async.gateway.ServedDrive.parameter_quality`),
and :data:`~._quality.QUALITY_STATUS` words it. ``Online``, the poller's
verdict itself, is judged by the served view too
(:meth:`~sj300_async.gateway.ServedDrive.verdict_quality`: never offline,
stale once the last sample is older than the gateway's window). The lines'
counters (:mod:`._values`) are Good whenever the line has a value for them.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final

from asyncua import ua

from ...profiles import ParameterSpec, ReadGroup
from .. import GatewayDrive, Quality, ServedDrive, ServedLine
from ._quality import QUALITY_STATUS
from ._sources import (
    ACTIVE_TRIP,
    CURRENT,
    DIRECTION,
    FREQUENCY,
    ONLINE,
    POWER,
    RUNNING,
    SETPOINT,
    STATE,
    TORQUE,
    TRIP_COUNT,
    TRIP_SOURCES,
    TRIPPED,
    VOLTAGE,
    Reader,
    Source,
    Stamp,
    parameter_source,
)
from ._space import Argument, SpaceBuilder

__all__ = [
    "DIRECTION_STATES",
    "LINE_COUNTERS",
    "Binding",
    "DriveIdentity",
    "DriveNodes",
    "Group",
    "LineNodes",
    "MethodNodes",
    "build_drive",
    "build_line",
    "drive_identity",
    "shape_key",
]

#: Why the trip history is arrays, not an object per record: an object per
#: record, each with five variables and their units, was 72 of a drive's 101
#: nodes, and asyncua keeps some 24 attribute values per node: at 2,048 drives
#: most of the northbound's memory and start-up, for values that change only
#: when a drive trips. One array per field says the same to a client.
#: ShaftTurningDirection's states, indexed by :class:`~sj300_async.Direction`.
DIRECTION_STATES: Final = ("stopped", "forward", "reverse")


def _judge(
    served: ServedDrive,
    read_group: ReadGroup | None,
    parameter: str | None,
    now: float,
    present: bool,
) -> Quality:
    """The quality of a value of *read_group* (or polled *parameter*) at loop time *now*.

    The served view's; neither given: the Online verdict's own rule (see the module
    docstring).
    """
    if read_group is not None:
        return served.quality(read_group, now, present=present)
    if parameter is not None:
        return served.parameter_quality(parameter, now)
    return served.verdict_quality(now)


def _until(served: ServedDrive, read_group: ReadGroup | None, parameter: str | None) -> float:
    """Loop time until which time alone changes nothing of :func:`_judge`'s verdict."""
    if read_group is not None:
        return served.fresh_until(read_group)
    if parameter is not None:
        return served.parameter_until(parameter)
    return served.sample_until


@dataclass(slots=True, eq=False)
class Binding:
    """One variable of a drive: where its value comes from and what it showed last.

    Its quality is the drive as served's (see the module docstring): it keeps the
    :class:`~sj300_async.gateway.ServedDrive` its value was taken from.
    """

    node: ua.NodeId
    vtype: ua.VariantType
    read: Reader
    #: The drive's object it is a variable of (a tuple of both per node cost 1 KiB a drive).
    owner: DriveNodes = field(repr=False)
    #: The drive as served its value was taken from (its judge); None: not taken yet.
    #: Taken when first read, watched or judged, never at start: a value taken then was
    #: kept by every variable nobody reads, with the start's served view of its drive
    #: (its snapshot and its values: some 2 KiB a drive; issue 44).
    served: ServedDrive | None = None
    #: Its path below the drive object (``Monitoring/State``): the audit log's name.
    name: str = ""
    #: The read group its value is one of: the served view judges it by that group.
    read_group: ReadGroup | None = None
    #: The polled parameter it is: the served view judges it as that parameter.
    #: (Neither: the Online verdict's own rule, see the module docstring.)
    parameter: str | None = None
    #: Its value is a list (an array of vtype), not a scalar.
    array: bool = False
    value: object = None
    #: Loop time the value was read (-inf: never).
    at: float = -math.inf
    #: The same instant as Unix time.
    wall: float = 0.0
    #: The served deadline of its value (loop time): until then time alone changes
    #: nothing of its status; past it a Good one is stale (the tick's test).
    until: float = -math.inf
    #: (value, status) last pushed to subscriptions (None: nobody watched it since).
    pushed: tuple[object, int] | None = None
    #: Monitored items on its value (0: nobody watches it, so nothing is taken, built
    #: or pushed for it at a sample: a read takes the drive's latest served view itself).
    watched: int = 0

    def take(self, served: ServedDrive, until: float | None = None) -> None:
        """Take the value and its read time from the drive as *served*.

        *until*: its served deadline, when the caller has it already (its group's).
        """
        snapshot = served.snapshot
        value, at = self.read(snapshot)
        self.value = value
        self.at = at
        self.wall = snapshot.time - (snapshot.taken_at - at) if at > -math.inf else snapshot.time
        self.served = served
        self.until = _until(served, self.read_group, self.parameter) if until is None else until

    def quality(self, now: float) -> Quality:
        """Its quality at loop time *now* (see the module docstring); not taken yet, it
        takes its drive's latest served view first."""
        served = self.served
        if served is None:
            served = self.owner.drive.served
            self.take(served)
        present = self.value is not None
        return _judge(served, self.read_group, self.parameter, now, present)

    def status(self, now: float) -> int:
        """Its status code at loop time *now*."""
        return QUALITY_STATUS[self.quality(now)]


@dataclass(frozen=True, slots=True)
class MethodNodes:
    """A drive's methods' node ids (None: its line grants no control)."""

    take_control: ua.NodeId
    run: ua.NodeId
    stop: ua.NodeId
    set_frequency: ua.NodeId


@dataclass(slots=True, eq=False)
class Group:
    """Variables read together: taken again only when their stamp or the verdict changed.

    They are judged together too (one read group, one parameter, or the verdict): a
    sample asks the served view once per group, not once per variable.
    """

    stamp: Stamp
    #: What its values are judged as (see :class:`Binding`).
    read_group: ReadGroup | None = None
    parameter: str | None = None
    bindings: list[Binding] = field(default_factory=list)
    #: (stamp, online) when last taken.
    seen: object = None
    #: Its bindings some monitored item watches (see DriveNodes.follow).
    watched: list[Binding] = field(default_factory=list)

    def until(self, served: ServedDrive) -> float:
        """Its values' served deadline in *served* (see :attr:`Binding.until`)."""
        return _until(served, self.read_group, self.parameter)

    def status(self, served: ServedDrive, now: float) -> int:
        """The status code at *now* of each of its values *served* has (not None)."""
        return QUALITY_STATUS[_judge(served, self.read_group, self.parameter, now, True)]


@dataclass(slots=True, eq=False)
class DriveNodes:
    """One drive's object: its variables and methods."""

    drive: GatewayDrive
    node: ua.NodeId
    bindings: list[Binding] = field(default_factory=list)
    groups: list[Group] = field(default_factory=list)
    #: Writable parameter variables: node -> parameter code.
    writable: dict[ua.NodeId, str] = field(default_factory=dict)
    methods: MethodNodes | None = None
    #: Monitored items on its variables, all together (0: a sample costs nothing here).
    watched: int = 0
    #: Its groups with a watched binding: all a sample looks at (see follow).
    watched_groups: list[Group] = field(default_factory=list)

    def follow(self) -> None:
        """Note which bindings and groups are watched now (after a watch count changed).

        A sample then visits only those: a drive has a dozen groups and some forty
        variables, a SCADA typically watches a few of them.
        """
        for group in self.groups:
            watched = [binding for binding in group.bindings if binding.watched > 0]
            if watched and not group.watched:
                # Samples passed it by while nobody watched it: what it saw last is not
                # what its variables show now (the drive may have gone offline and come
                # back meanwhile), so the next sample is taken whatever its stamp.
                group.seen = None
            group.watched = watched
        self.watched_groups = [group for group in self.groups if group.watched]


@dataclass(slots=True, eq=False)
class LineNodes:
    """One line's object: its counters, by name."""

    line: ServedLine
    node: ua.NodeId
    counters: dict[str, ua.NodeId] = field(default_factory=dict)
    #: What each counter last showed to subscriptions.
    shown: dict[str, object] = field(default_factory=dict)


#: A line's counters: name, variant type, description, unit.
LINE_COUNTERS: Final[tuple[tuple[str, ua.VariantType, str, str], ...]] = (
    ("Connected", ua.VariantType.Boolean, "the link to the line is up", ""),
    ("DrivesOnline", ua.VariantType.UInt32, "drives the poller hears", ""),
    ("Utilisation", ua.VariantType.Double, "share of time the line was busy (0..1)", ""),
    ("Requests", ua.VariantType.UInt64, "requests sent", ""),
    ("Replies", ua.VariantType.UInt64, "replies received", ""),
    ("Timeouts", ua.VariantType.UInt64, "requests not answered in time", ""),
    ("Retries", ua.VariantType.UInt64, "requests sent again", ""),
    ("Naks", ua.VariantType.UInt64, "requests the drives refused", ""),
    ("TransportErrors", ua.VariantType.UInt64, "link failures during a request", ""),
    ("ProtocolErrors", ua.VariantType.UInt64, "replies that broke the protocol", ""),
    ("BadFrames", ua.VariantType.UInt64, "frames that failed their check", ""),
    ("EarlyFrames", ua.VariantType.UInt64, "replies before the request ended", ""),
    ("StrayFrames", ua.VariantType.UInt64, "frames nobody asked for", ""),
    ("DiscardedBytes", ua.VariantType.UInt64, "bytes that were no frame", ""),
    ("Connects", ua.VariantType.UInt64, "times the link came up", ""),
    ("Disconnects", ua.VariantType.UInt64, "times the link went down", ""),
    ("LatencyMean", ua.VariantType.Double, "mean time from request to reply", "s"),
)


class _DriveBuilder:
    """Adds one drive's nodes to a :class:`SpaceBuilder` and binds its variables."""

    def __init__(self, space: SpaceBuilder, nodes: DriveNodes, path: str) -> None:
        self.space = space
        self.nodes = nodes
        self.path = path
        self._groups: dict[int, Group] = {}

    def var(
        self,
        parent: ua.NodeId,
        path: str,
        name: str,
        vtype: ua.VariantType,
        source: Source,
        *,
        parameter: str | None = None,
        description: str = "",
        unit: str = "",
        value_range: tuple[float, float] | None = None,
        states: Sequence[str] = (),
        writable: bool = False,
        array: bool = False,
    ) -> ua.NodeId:
        node = self.space.variable(
            parent, f"{path}/{name}", name, vtype, description=description, unit=unit,
            value_range=value_range, states=states, writable=writable, array=array,
        )  # fmt: skip
        read, stamp, read_group = source
        # One string for every drive (the same path below each): 18 a drive, 2.9 MiB at 2,048.
        relative = sys.intern(f"{path}/{name}".removeprefix(f"{self.path}/"))
        binding = Binding(
            node,
            vtype,
            read,
            self.nodes,
            name=relative,
            read_group=read_group,
            parameter=parameter,
            array=array,
        )
        self.nodes.bindings.append(binding)
        group = self._groups.get(id(stamp))
        if group is None:
            group = self._groups[id(stamp)] = Group(stamp, read_group, parameter)
            self.nodes.groups.append(group)
        # Read together, judged together.
        assert (group.read_group, group.parameter) == (read_group, parameter), relative
        group.bindings.append(binding)
        return node


@dataclass(frozen=True, slots=True)
class DriveIdentity:
    """What of a drive's nodes is its own: everything else is its shape's (:func:`shape_key`).

    The lazy address space (:mod:`._lazy`) makes a drive's nodes from another
    drive's of the same shape, with these put in: whatever else
    :func:`build_drive` makes differ between two drives must be in the shape's
    key, or here (``tests/opcua/test_opcua_lazy.py`` compares the two ways).
    """

    #: The drive object's path (``line1/Drive3``), its browse and display name, description.
    path: str
    name: str
    description: str
    #: Its properties: name, value, type.
    properties: tuple[tuple[str, object, ua.VariantType], ...]


def drive_identity(drive: GatewayDrive, parent_path: str) -> DriveIdentity:
    """*drive*'s own names and properties (see :class:`DriveIdentity`)."""
    profile = drive.profile
    described = f"{profile.manufacturer} {profile.model}, {profile.node_noun} {drive.node}"
    string, int32 = ua.VariantType.String, ua.VariantType.Int32
    return DriveIdentity(
        path=f"{parent_path}/Drive{drive.node}",
        name=f"Drive{drive.node}",
        description=f"{described} on line {drive.line.name}",
        properties=(
            ("Line", drive.line.name, string),
            ("Node", drive.node, int32),
            ("Protocol", drive.line.protocol, string),
            ("UnitId", drive.unit, int32),
        ),
    )


def shape_key(drive: GatewayDrive, *, control: bool) -> tuple[object, ...]:
    """What decides which nodes :func:`build_drive` makes below *drive*'s object, and their
    attributes: two drives of one key differ only by their :class:`DriveIdentity`."""
    profile = drive.profile
    granted = drive.line.writable_parameters(drive.node)
    return (
        id(profile),
        profile.max_frequency_hz,
        tuple(sorted(profile.capabilities.measures)),
        tuple(drive.line.parameters),
        tuple(sorted(granted)),
        control,
    )


def build_drive(
    space: SpaceBuilder, parent: ua.NodeId, parent_path: str, drive: GatewayDrive, *, control: bool
) -> DriveNodes:
    """Gather *drive*'s object under its line's object (see the module docstring)."""
    profile = drive.profile
    identity = drive_identity(drive, parent_path)
    path = identity.path
    node = space.object(parent, path, identity.name, identity.description, component=True)
    nodes = DriveNodes(drive, node)
    b = _DriveBuilder(space, nodes, path)
    for name, value, vtype in identity.properties:
        space.property(node, f"{path}/{name}", name, value, vtype)
    b.var(node, path, "Online", ua.VariantType.Boolean, ONLINE,
          description="the poller hears the drive")  # fmt: skip

    hz_range = (0.0, float(profile.max_frequency_hz))
    monitoring = f"{path}/Monitoring"
    folder = space.object(node, monitoring, "Monitoring", folder=True, component=True)
    double, boolean = ua.VariantType.Double, ua.VariantType.Boolean
    b.var(folder, monitoring, "ConverterOutputFrequency", double,
          FREQUENCY, unit="Hz", value_range=hz_range,
          description="output frequency")  # fmt: skip
    b.var(folder, monitoring, "FrequencyCommandValue", double,
          SETPOINT, unit="Hz", value_range=hz_range,
          description="the set frequency, as read back from the drive")  # fmt: skip
    b.var(folder, monitoring, "ConverterOutputCurrent", double,
          CURRENT, unit="A",
          description="output current")  # fmt: skip
    b.var(folder, monitoring, "ConverterOutputVoltage", double,
          VOLTAGE, unit="V",
          description="output voltage")  # fmt: skip
    measures = profile.capabilities.measures
    if "power_kw" in measures:
        b.var(folder, monitoring, "ConverterOutputPower", double,
              POWER, unit="kW", description="output power")  # fmt: skip
    if "output_torque_percent" in measures:
        b.var(folder, monitoring, "OutputTorque", double,
              TORQUE, unit="%",
              description="output torque, percent of the motor's rated torque")  # fmt: skip
    b.var(folder, monitoring, "ShaftTurningDirection", ua.VariantType.UInt16, DIRECTION,
          states=DIRECTION_STATES, description="0 stopped, 1 forward, 2 reverse")  # fmt: skip
    b.var(folder, monitoring, "Running", boolean, RUNNING,
          description="the drive runs (accelerating, at speed or decelerating)")  # fmt: skip
    b.var(folder, monitoring, "Tripped", boolean, TRIPPED,
          description="the drive is tripped (a fault stopped it)")  # fmt: skip
    b.var(folder, monitoring, "State", ua.VariantType.String, STATE,
          description="the state in words, the trip named")  # fmt: skip

    logbook = f"{path}/Logbook"
    folder = space.object(node, logbook, "Logbook", "the trip history", folder=True, component=True)
    b.var(folder, logbook, "ActiveTrip", ua.VariantType.String, ACTIVE_TRIP,
          description="the trip the drive is in, code and meaning (empty: none)")  # fmt: skip
    b.var(folder, logbook, "TripCount", ua.VariantType.UInt32, TRIP_COUNT,
          description="trips since the counter was cleared")  # fmt: skip
    for field_name, vtype, source, unit, description in TRIP_SOURCES:
        b.var(folder, logbook, field_name, vtype, source, unit=unit,
              description=description, array=True)  # fmt: skip

    granted = drive.line.writable_parameters(drive.node)
    codes = list(dict.fromkeys((*drive.line.parameters, *sorted(granted))))
    if codes:
        parameters = f"{path}/Parameters"
        folder = space.object(node, parameters, "Parameters", folder=True, component=True)
        for code in codes:
            spec: ParameterSpec = profile.parameters.spec(code)
            writable = code in granted
            variable = b.var(
                folder, parameters, code, double, parameter_source(code), parameter=code,
                unit=spec.unit,
                value_range=(float(spec.minimum), float(spec.maximum)),
                description=spec.name, writable=writable,
            )  # fmt: skip
            if writable:
                nodes.writable[variable] = code
    if control:
        nodes.methods = _methods(space, node, path)
    return nodes


def _methods(space: SpaceBuilder, node: ua.NodeId, path: str) -> MethodNodes:
    lease = Argument(
        "LeaseSeconds", ua.VariantType.Double, "seconds the lease lasts unless renewed"
    )
    return MethodNodes(
        take_control=space.method(
            node, f"{path}/TakeControl", "TakeControl",
            "take or renew the control lease (run and set frequency need it)", (), (lease,),
        ),
        run=space.method(
            node, f"{path}/Run", "Run", "run forward or reverse (needs the lease)",
            (Argument("Direction", ua.VariantType.String, "forward or reverse"),),
        ),
        stop=space.method(node, f"{path}/Stop", "Stop", "stop (needs no lease)"),
        set_frequency=space.method(
            node, f"{path}/SetFrequency", "SetFrequency", "set the frequency (needs the lease)",
            (Argument("Frequency", ua.VariantType.Double, "Hz, 0.01 Hz steps"),),
        ),
    )  # fmt: skip


def build_line(space: SpaceBuilder, parent: ua.NodeId, line: ServedLine) -> LineNodes:
    """Gather *line*'s object under the Lines folder (its drives are added by the caller)."""
    config = line.config
    path = config.name
    node = space.object(parent, path, config.name, f"line {config.name} ({config.protocol})")
    nodes = LineNodes(line, node)
    space.property(node, f"{path}/Protocol", "Protocol", config.protocol, ua.VariantType.String)
    space.property(node, f"{path}/Url", "Url", config.url, ua.VariantType.String)
    for name, vtype, description, unit in LINE_COUNTERS:
        nodes.counters[name] = space.variable(
            node, f"{path}/{name}", name, vtype, description=description, unit=unit
        )
    return nodes
