"""Telemetry dictionary: packets (APID, layout, time code, CRC), parameters, limits and derived parameters.

Three sources load into one model: our YAML format (``telemetry/dictionaries/*.yaml``), ccsdspy CSV
definitions (``name,data_type,bit_length``) and XTCE (read with ``space-packet-parser``; the bulk
decode is ours, :mod:`telemetry.decoding`). Packets are fixed-length; every parameter carries its bit
offset from the first octet of the packet, so layouts from all three sources decode identically.
"""

from __future__ import annotations

import csv
import re
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, TypedDict

import numpy as np
import yaml

from telemetry.ccsds import APID_COUNT, IDLE_APID, PRIMARY_HEADER_OCTETS, TimeCode
from telemetry.packet_time import TimeFields, parse_time_fields

__all__ = [
    "Limits",
    "Parameter",
    "FieldSpec",
    "XtceSource",
    "DerivedParameter",
    "PacketDefinition",
    "Dictionary",
    "DERIVED_KINDS",
    "DATA_TYPES",
    "PARAMETER_NAME_MAX",
    "load_dictionary",
    "load_yaml",
    "load_ccsdspy_csv",
    "load_ccsdspy_folder",
    "merge_dictionaries",
    "lay_out",
    "load_xtce",
    "xtce_parameter",
    "parse_time_code",
    "parse_utc_ns",
    "SHIPPED",
    "FUTURE_MARGIN_NS",
]

PRIMARY_HEADER_BITS = 8 * PRIMARY_HEADER_OCTETS
CRC_OCTETS = 2
DATA_TYPES = ("uint", "int", "float")
DERIVED_KINDS = {"attitude_error_angle": 8, "cds_time": 3, "alias": 1}
SHIPPED = Path(__file__).with_name("dictionaries")
FUTURE_MARGIN_NS = 86_400 * 10**9  # on-board clocks run ahead by less than a day; later stamps are corrupt
MAX_PACKET_BITS = 8 * (PRIMARY_HEADER_OCTETS + 65536)  # CCSDS 133.0-B-2 §4.1.3.5: data field ≤ 65,536 octets
PARAMETER_NAME_MAX = 128  # the archive stores parameter names in varchar(128) columns (telemetry/archive/models.py)
EARLIEST_UTC_NS = 2 * 365 * 86_400 * 10**9  # 1972-01-01: UTC as defined today starts; 1970 stamps are unset clocks


def _check_parameter_name(name: str) -> None:
    """ValueError unless ``name`` is 1 to PARAMETER_NAME_MAX printable characters: it is archived as text, where
    PostgreSQL refuses a NUL and anything longer than its column (SQLite stored both)."""
    if not 0 < len(name) <= PARAMETER_NAME_MAX or any(ord(c) < 0x20 or ord(c) == 0x7F for c in name):
        shown = name[:40].encode("unicode_escape").decode("ascii")
        raise ValueError(
            f"{shown}.name: a parameter name is 1 to {PARAMETER_NAME_MAX} characters, no control characters"
        )


@dataclass(frozen=True)
class Limits:
    """Yellow (warning) and red (alarm) low/high limits in engineering units; None = no limit."""

    red_low: float | None = None
    yellow_low: float | None = None
    yellow_high: float | None = None
    red_high: float | None = None

    def __post_init__(self) -> None:
        ordered = [v for v in (self.red_low, self.yellow_low, self.yellow_high, self.red_high) if v is not None]
        if ordered != sorted(ordered):
            raise ValueError(f"limits: expected red_low <= yellow_low <= yellow_high <= red_high, got {self}")


@dataclass(frozen=True)
class Parameter:
    """A raw field of a packet: where it sits, how it is encoded, and how to calibrate it."""

    name: str
    data_type: str
    bit_offset: int
    bit_length: int
    units: str = ""
    description: str = ""
    polynomial: tuple[float, ...] = ()
    enumeration: dict[int, str] = field(default_factory=dict)
    limits: Limits = Limits()
    byte_order: str = "big"

    def __post_init__(self) -> None:
        _check_parameter_name(self.name)
        if self.byte_order not in ("big", "little") and not (
            self.byte_order.isdigit() and sorted(self.byte_order) == [str(k + 1) for k in range(len(self.byte_order))]
        ):
            raise ValueError(f"{self.name}.byte_order: expected big, little or a digit order like 3412")
        if self.data_type not in DATA_TYPES:
            raise ValueError(f"{self.name}.data_type: expected one of {DATA_TYPES}, got {self.data_type!r}")
        if self.data_type == "float" and self.bit_length not in (32, 64):
            raise ValueError(f"{self.name}.bit_length: floats are IEEE 754 binary32 or binary64, got {self.bit_length}")
        if not 1 <= self.bit_length <= 64:
            raise ValueError(f"{self.name}.bit_length: expected 1..64, got {self.bit_length}")
        if self.bit_offset % 8 + self.bit_length > 64:
            raise ValueError(f"{self.name}.bit_offset: a field may span at most 8 octets")
        if self.polynomial and self.enumeration:
            raise ValueError(f"{self.name}.calibration: polynomial and enumeration are exclusive")


@dataclass(frozen=True)
class DerivedParameter:
    """A parameter computed from other parameters of the same packet (kind in DERIVED_KINDS)."""

    name: str
    kind: str
    inputs: tuple[str, ...]
    units: str = ""
    description: str = ""
    limits: Limits = Limits()

    def __post_init__(self) -> None:
        _check_parameter_name(self.name)
        if self.kind not in DERIVED_KINDS:
            raise ValueError(f"{self.name}.kind: expected one of {sorted(DERIVED_KINDS)}, got {self.kind!r}")
        if len(self.inputs) != DERIVED_KINDS[self.kind]:
            raise ValueError(f"{self.name}.inputs: {self.kind} needs {DERIVED_KINDS[self.kind]} inputs")


@dataclass(frozen=True)
class FieldSpec:
    """A field of a variable layout (ccsdspy semantics): scalar, fixed array, or an array sized by the packet
    length (``shape="expand"``) or by the value of an earlier field (``shape=<field name>``)."""

    name: str
    data_type: str
    bit_length: int
    bit_offset: int | None = None
    byte_order: str = "big"
    shape: tuple[int, ...] | str | None = None
    array_order: Literal["C", "F"] = "C"

    @property
    def is_variable(self) -> bool:
        """True when the element count depends on the packet."""
        return isinstance(self.shape, str)

    def element_names(self, count: int) -> list[str]:
        """Names of the elements in packet order: ``name``, ``name_k`` or ``name_i_j`` (ccsdspy's array index)."""
        if self.shape is None:
            return [self.name]
        if isinstance(self.shape, tuple) and len(self.shape) > 1:
            index = np.unravel_index(np.arange(count), self.shape, order=self.array_order)
            return [self.name + "".join(f"_{int(i[k])}" for i in index) for k in range(count)]
        return [f"{self.name}_{k}" for k in range(count)]


@dataclass(frozen=True)
class XtceSource:
    """Packets parsed one by one by space-packet-parser: its definition, the containers, their numeric parameters."""

    definition: Any = field(compare=False, repr=False)
    containers: tuple[str, ...] = ()
    numeric: tuple[str, ...] = ()
    values_per_octet: float = 8.0  # most numeric values one octet of these packets yields (see load_xtce)


@dataclass(frozen=True)
class PacketDefinition:
    """A telemetry packet type: APID, length, time (secondary-header code or named fields), CRC, fields.

    Fixed layouts list every parameter with its bit offset. A variable layout keeps its ``fields``
    (ccsdspy semantics); ``parameters`` then hold the fixed part before the first variable array and
    ``packet_octets`` the octets that fixed part needs; :meth:`resolve` lays a packet's fields out.
    ``accepts_segments``: a packet whose sequence flags mark a segment of a larger unit (CCSDS 133.0-B-2
    §4.1.3.4.2.2) decodes by this layout like any other, as space_packet_parser (segments not combined) and
    ccsdspy read it (XTCE and ccsdspy CSV definitions, YAML ``segmented: true``); else it is bad_header.
    """

    name: str
    apid: int
    packet_octets: int
    parameters: tuple[Parameter, ...]
    time_code: TimeCode | None = None
    crc: bool = False
    period_s: float | None = None
    description: str = ""
    derived: tuple[DerivedParameter, ...] = ()
    time_fields: TimeFields | None = None
    fields: tuple[FieldSpec, ...] = ()
    xtce: XtceSource | None = None
    accepts_segments: bool = False

    @property
    def variable(self) -> bool:
        """True when the layout depends on the packet length or on a field's value (or space-packet-parser reads it)."""
        return bool(self.fields) or self.xtce is not None

    @property
    def count_fields(self) -> tuple[str, ...]:
        """Fields whose values size arrays of this packet."""
        return tuple(str(f.shape) for f in self.fields if f.is_variable and f.shape != "expand")

    @property
    def values_per_octet(self) -> float:
        """Most values (parameters and derived ones) that one octet of these packets can decode to: exact for a
        fixed layout (a longer packet decodes its prefix); for a variable one, one per bit of its narrowest field."""
        derived = len(self.derived) / self.packet_octets
        if self.xtce is not None:
            return self.xtce.values_per_octet + derived
        if self.fields:
            return 8 / min(f.bit_length for f in self.fields) + derived
        return len(self.parameters) / self.packet_octets + derived

    def resolve(self, packet_octets: int, counts: dict[str, int]) -> tuple[Parameter, ...]:
        """Parameters of a variable layout in a packet of packet_octets whose count fields hold counts.

        ValueError when the fields need more octets than the packet has.
        """
        params, end = lay_out(self.fields, packet_octets, counts)
        if end > 8 * packet_octets:
            raise ValueError(f"packet has {packet_octets} octets, the definition needs {-(-end // 8)}")
        return params

    def __post_init__(self) -> None:
        if not 0 <= self.apid < IDLE_APID:
            raise ValueError(f"{self.name}.apid: expected 0..2046, got {self.apid}")
        if self.time_code is not None and self.time_fields is not None:
            raise ValueError(f"{self.name}: give a time_code or time_fields, not both")
        fixed_names = {p.name for p in self.parameters}
        if any(c not in fixed_names for c in self.count_fields):
            raise ValueError(f"{self.name}: array size fields {self.count_fields} must precede every variable array")
        if self.time_fields is not None and self.xtce is None:
            missing = [n for n in self.time_fields.names if n not in fixed_names]
            if missing:
                raise ValueError(f"{self.name}.time_fields: no fixed-position parameters {missing}")
        body_end = 8 * (self.packet_octets - (CRC_OCTETS if self.crc else 0))
        for p in self.parameters:
            if p.bit_offset < PRIMARY_HEADER_BITS or p.bit_offset + p.bit_length > body_end:
                raise ValueError(f"{self.name}.{p.name}: bits {p.bit_offset}+{p.bit_length} outside the packet body")
        names = [p.name for p in self.parameters] + [d.name for d in self.derived]
        if len(set(names)) != len(names):
            raise ValueError(f"{self.name}.parameters: duplicate names")
        known = set(names)
        for d in self.derived:
            missing = [i for i in d.inputs if i not in known]
            if missing:
                raise ValueError(f"{self.name}.{d.name}.inputs: unknown parameters {missing}")
        if self.time_code and PRIMARY_HEADER_OCTETS + self.time_code.octets > self.packet_octets:
            raise ValueError(f"{self.name}.time_code: longer than the packet")


def _fixed_count(f: FieldSpec) -> int:
    """Element count of a scalar or fixed-shape field (variable ones count 0 here)."""
    if f.shape is None:
        return 1
    return int(np.prod(f.shape)) if isinstance(f.shape, tuple) else 0


@dataclass(frozen=True)
class Dictionary:
    """All packet types of one spacecraft, by APID, and the window of plausible packet times."""

    name: str
    packets: dict[int, PacketDefinition]
    valid_from_utc_ns: int | None = None
    valid_until_utc_ns: int | None = None
    description: str = ""
    satellite: str = ""
    notes: tuple[str, ...] = ()
    packet_prefix_octets: int = 0
    packet_suffix_octets: int = 0

    @property
    def satellite_name(self) -> str:
        """The spacecraft these packets come from (archive key); the dictionary name when not given."""
        return self.satellite or self.name

    def time_window(self, now_utc_ns: int | None = None) -> tuple[int, int]:
        """Plausible packet times [from, until] in UTC ns; by default from 1972 (no zero/unset clock is archived)
        until ingest time + FUTURE_MARGIN_NS."""
        now = time.time_ns() if now_utc_ns is None else now_utc_ns
        low = self.valid_from_utc_ns if self.valid_from_utc_ns is not None else EARLIEST_UTC_NS
        high = self.valid_until_utc_ns if self.valid_until_utc_ns is not None else now + FUTURE_MARGIN_NS
        return low, high

    def packet_octets_by_apid(self) -> dict[int, int]:
        """Total packet length (octets) of every known APID, for stream framing."""
        return {apid: p.packet_octets for apid, p in self.packets.items()}

    def crc_apids(self) -> frozenset[int]:
        """APIDs whose packets end with a CRC-16 packet error control field."""
        return frozenset(apid for apid, p in self.packets.items() if p.crc)

    def parameter(self, name: str) -> tuple[PacketDefinition, Parameter | DerivedParameter]:
        """The packet and the (raw or derived) parameter of that name."""
        for packet in self.packets.values():
            members: tuple[Parameter | DerivedParameter, ...] = (*packet.parameters, *packet.derived)
            for p in members:
                if p.name == name:
                    return packet, p
        raise ValueError(f"name: no parameter {name!r} in dictionary {self.name!r}")


def parse_utc_ns(text: str | int) -> int:
    """UTC ns since the Unix epoch of an ISO 8601 string (``Z`` or no zone = UTC) or an int of ns."""
    if isinstance(text, (int, np.integer)):
        return int(text)
    stamp = str(text).strip().removesuffix("Z").removesuffix("+00:00")
    try:
        return int(np.datetime64(stamp, "ns").astype(np.int64))
    except ValueError as exc:
        raise ValueError(f"time: cannot read {text!r} as ISO 8601 UTC") from exc


def parse_time_code(spec: str | dict[str, Any] | None) -> TimeCode | None:
    """A TimeCode from a YAML mapping (format, octets, epoch, time_scale) or a short name ("CDS", "CDS-ms", "CUC-4-2").

    The epoch defaults to 1958-01-01 (CCSDS level 1) and is read on the calendar of the time scale.
    """
    if spec is None:
        return None
    if isinstance(spec, str):
        parts = spec.upper().split("-")
        if parts[0] == "CDS" and len(parts) == 1:
            return TimeCode("CDS")
        if parts == ["CDS", "MS"]:
            return TimeCode("CDS", submillisecond_octets=0)
        if parts[0] == "CUC" and len(parts) == 3 and all(x.isdigit() for x in parts[1:]):
            return TimeCode("CUC", coarse_octets=int(parts[1]), fine_octets=int(parts[2]))
        raise ValueError(f"time_code: unknown short name {spec!r} (use CDS, CDS-ms or CUC-<coarse>-<fine>)")
    spec = dict(spec)
    if "epoch_utc" in spec:  # earlier spelling: an epoch on the UTC calendar
        if spec.get("time_scale", "UTC") != "UTC" or "epoch" in spec:
            raise ValueError("time_code.epoch_utc: means a UTC epoch; use epoch with time_scale instead")
        spec["epoch"] = spec.pop("epoch_utc")
    epoch = spec.pop("epoch", None)
    keys = ("coarse_octets", "fine_octets", "day_octets", "submillisecond_octets", "time_scale")
    kwargs = {k: spec.pop(k) for k in keys if k in spec}
    fmt = spec.pop("format", None)
    if spec:
        raise ValueError(f"time_code: unknown keys {sorted(spec)}")
    if epoch is not None:
        kwargs["epoch_ns"] = parse_utc_ns(epoch)
    return TimeCode(str(fmt), **kwargs)


def _limits(spec: dict[str, Any] | None) -> Limits:
    """Limits from a YAML mapping with keys red_low, yellow_low, yellow_high, red_high."""
    spec = dict(spec or {})
    unknown = set(spec) - {"red_low", "yellow_low", "yellow_high", "red_high"}
    if unknown:
        raise ValueError(f"limits: unknown keys {sorted(unknown)}")
    return Limits(**{k: float(v) for k, v in spec.items()})


def _derived(specs: list[dict[str, Any]] | None) -> tuple[DerivedParameter, ...]:
    """Derived parameters from YAML mappings (name, kind, inputs, units, description, limits)."""
    return tuple(
        DerivedParameter(
            name=str(s["name"]),
            kind=str(s["kind"]),
            inputs=tuple(str(i) for i in s["inputs"]),
            units=str(s.get("units", "")),
            description=str(s.get("description", "")),
            limits=_limits(s.get("limits")),
        )
        for s in specs or []
    )


def _yaml_parameters(specs: list[dict[str, Any]], first_bit: int) -> tuple[tuple[Parameter, ...], int]:
    """Parameters laid out back to back from first_bit, and the bit after the last one."""
    params, bit = [], first_bit
    for s in specs:
        unknown = set(s) - {
            "name",
            "type",
            "bits",
            "units",
            "description",
            "polynomial",
            "enumeration",
            "limits",
            "byte_order",
        }
        if unknown:
            raise ValueError(f"{s.get('name')}: unknown keys {sorted(unknown)}")
        enum = {int(k): str(v) for k, v in (s.get("enumeration") or {}).items()}
        params.append(
            Parameter(
                name=str(s["name"]),
                data_type=str(s["type"]),
                bit_offset=bit,
                bit_length=int(s["bits"]),
                units=str(s.get("units", "")),
                description=str(s.get("description", "")),
                polynomial=tuple(float(c) for c in s.get("polynomial") or ()),
                enumeration=enum,
                limits=_limits(s.get("limits")),
                byte_order=str(s.get("byte_order", "big")),
            )
        )
        bit += int(s["bits"])
    return tuple(params), bit


def _beside(folder: Path, file: Any, field: str) -> Path:
    """A layout file a dictionary names: a regular file in the dictionary's own folder, never elsewhere."""
    path = (folder / str(file)).resolve()
    if path.parent != folder.resolve() or not path.is_file():
        raise ValueError(f"{field}: {file!r} must be a file next to the dictionary (same folder), not another path")
    return path


class _PacketCommon(TypedDict):
    """The packet fields a YAML packet sets the same way whether its layout is inline or taken from a file."""

    time_code: TimeCode | None
    time_fields: TimeFields | None
    period_s: float | None
    description: str
    derived: tuple[DerivedParameter, ...]
    accepts_segments: bool


def _yaml_packet(spec: dict[str, Any], folder: Path) -> PacketDefinition:
    """One packet definition from our YAML format (layout inline or taken from an XTCE/CSV file)."""
    name, apid = str(spec["name"]), int(spec["apid"])
    time_code = parse_time_code(spec.get("time_code"))
    time_fields = parse_time_fields(spec.get("time_fields"))
    crc = bool(spec.get("crc", False))
    common = _PacketCommon(
        time_code=time_code,
        time_fields=time_fields,
        period_s=float(spec["period_s"]) if spec.get("period_s") is not None else None,
        description=str(spec.get("description", "")),
        derived=_derived(spec.get("derived")),
        accepts_segments=bool(spec.get("segmented", False)),
    )
    source = spec.get("layout_from")
    if source:
        if not isinstance(source, dict) or set(source) not in ({"xtce"}, {"ccsdspy_csv"}):
            raise ValueError(f"{name}.layout_from: expected {{xtce: FILE}} or {{ccsdspy_csv: FILE}}, got {source}")
        if "xtce" in source:
            base = load_xtce(_beside(folder, source["xtce"], f"{name}.layout_from.xtce")).packets.get(apid)
        else:
            layout = _beside(folder, source["ccsdspy_csv"], f"{name}.layout_from.ccsdspy_csv")
            base = load_ccsdspy_csv(layout, apid=apid, name=name).packets.get(apid)
        if base is None:
            raise ValueError(f"{name}.layout_from: no packet with APID {apid} in {source}")
        return replace(base, name=name, crc=crc, **common)
    first = PRIMARY_HEADER_BITS + 8 * (time_code.octets if time_code else 0)
    params, end_bit = _yaml_parameters(spec["parameters"], first)
    if end_bit % 8:
        raise ValueError(f"{name}.parameters: layout ends at bit {end_bit}, not on an octet boundary")
    octets = end_bit // 8 + (CRC_OCTETS if crc else 0)
    declared = spec.get("packet_octets")
    if declared is not None and int(declared) != octets:
        raise ValueError(f"{name}.packet_octets: declared {declared}, layout gives {octets}")
    return PacketDefinition(name=name, apid=apid, packet_octets=octets, parameters=params, crc=crc, **common)


def load_yaml(path: str | Path) -> Dictionary:
    """A dictionary in our YAML format (see telemetry/dictionaries/reference_satellite.yaml)."""
    path = Path(path)
    doc = yaml.safe_load(path.read_text())
    if not isinstance(doc, dict) or "packets" not in doc:
        raise ValueError(f"{path}: expected a mapping with a 'packets' list")
    packets = [_yaml_packet(p, path.parent) for p in doc["packets"]]
    by_apid = {p.apid: p for p in packets}
    if len(by_apid) != len(packets):
        raise ValueError(f"{path}: packets: two packets share an APID")
    valid = doc.get("valid_time_utc") or {}
    return Dictionary(
        name=str(doc.get("name", path.stem)),
        packets=by_apid,
        valid_from_utc_ns=parse_utc_ns(valid["from"]) if "from" in valid else None,
        valid_until_utc_ns=parse_utc_ns(valid["until"]) if "until" in valid else None,
        description=str(doc.get("description", "")),
        satellite=str(doc.get("satellite", "")),
        packet_prefix_octets=int(doc.get("packet_prefix_octets", 0)),
        packet_suffix_octets=int(doc.get("packet_suffix_octets", 0)),
    )


def lay_out(
    fields: tuple[FieldSpec, ...], packet_octets: int | None, counts: dict[str, int]
) -> tuple[tuple[Parameter, ...], int]:
    """Parameters of fields laid out from the end of the primary header (ccsdspy semantics), and the end bit.

    An explicit bit_offset counts from the first octet of the packet; ``fill`` and ``str`` fields only
    take room. With packet_octets None the layout stops before the first variable array.
    """
    bit, end = PRIMARY_HEADER_BITS, PRIMARY_HEADER_BITS
    params: list[Parameter] = []
    for i, f in enumerate(fields):
        bit = f.bit_offset if f.bit_offset is not None else bit
        if f.is_variable and packet_octets is None:
            break
        if f.shape == "expand":
            footer = sum(g.bit_length * _fixed_count(g) for g in fields[i + 1 :])
            count = max((8 * int(packet_octets or 0) - bit - footer) // f.bit_length, 0)
        elif isinstance(f.shape, str):
            count = int(counts[f.shape])
        else:
            count = _fixed_count(f)
        if not (bit >= 0 and 1 <= f.bit_length <= 64 and bit + count * f.bit_length <= MAX_PACKET_BITS):
            raise ValueError(
                f"{f.name}.data_type: {count} × {f.bit_length} bits from bit {bit} do not fit in the "
                f"largest CCSDS packet ({MAX_PACKET_BITS // 8} octets)"
            )
        if f.data_type in DATA_TYPES:
            params.extend(
                Parameter(name, f.data_type, bit + k * f.bit_length, f.bit_length, byte_order=f.byte_order)
                for k, name in enumerate(f.element_names(count))
            )
        bit += count * f.bit_length
        end = max(end, bit)
    return tuple(params), end


def _ccsdspy_fields(path: Path) -> list[FieldSpec]:
    """The fields of a ccsdspy CSV definition as ccsdspy itself reads them (``FixedLength/VariableLength.from_file``).

    ccsdspy reads ``name,data_type,bit_length`` and an optional ``bit_offset`` column, ignores any
    other column (``byte_order`` too: its CSV reader leaves every field big-endian), and takes
    ``uint(4)``, ``uint(2, 3)``, ``uint(expand)`` and ``uint(<field>)`` as arrays.
    """
    import ccsdspy

    try:
        try:
            packet = ccsdspy.FixedLength.from_file(str(path))
        except ValueError as exc:
            if "variable fields" not in str(exc):
                raise
            packet = ccsdspy.VariableLength.from_file(str(path))
    except (ValueError, RuntimeError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: ccsdspy cannot read this definition: {exc}") from exc
    specs = []
    for f in packet._fields:
        shape = getattr(f, "_array_shape", None)
        if isinstance(shape, int):
            shape = (shape,)
        specs.append(
            FieldSpec(
                name=f._name,
                data_type=f._data_type,
                bit_length=int(f._bit_length),
                bit_offset=None if f._bit_offset is None else int(f._bit_offset),
                byte_order=f._byte_order,
                shape=tuple(int(x) for x in shape) if isinstance(shape, tuple) else shape,
                array_order=getattr(f, "_array_order", "C"),
            )
        )
    return specs


def load_ccsdspy_csv(
    path: str | Path,
    apid: int,
    name: str | None = None,
    time_code: TimeCode | None = None,
    time_fields: TimeFields | None = None,
) -> Dictionary:
    """A one-packet dictionary from a ccsdspy CSV definition, read by ccsdspy (3- or 4-column, arrays, expand).

    Fixed layouts list every element (arrays as ``name_k``); a layout with an ``expand`` array or an
    array sized by another field stays variable (:meth:`PacketDefinition.resolve` per packet).
    """
    path = Path(path)
    fields = tuple(_ccsdspy_fields(path))
    variable = any(f.is_variable for f in fields)
    params, end = lay_out(fields, None if variable else 0, {})
    if end % 8 and not variable:
        raise ValueError(f"{path}: layout ends at bit {end}, not on an octet boundary")
    try:
        packet = PacketDefinition(
            name=name or path.stem,
            apid=apid,
            packet_octets=-(-end // 8),
            parameters=params,
            time_code=time_code,
            time_fields=time_fields.bound_to(p.name for p in params) if time_fields else None,
            fields=fields if variable else (),
            accepts_segments=True,
        )
    except ValueError as exc:
        raise ValueError(f"{path.name}: {exc}") from exc
    with path.open(newline="") as f:
        header = next(csv.reader(f, skipinitialspace=True), [])
    ignored = [c for c in header if c not in ("name", "data_type", "bit_length", "bit_offset")]
    notes = (f"{path.name}: columns {ignored} ignored, as ccsdspy's CSV reader does",) if ignored else ()
    return Dictionary(name=path.stem, packets={apid: packet}, notes=notes)


APID_IN_NAME = re.compile(r"(?:^|[^a-z])apid[_-]?0*(\d+)|^0*(\d+)$", re.IGNORECASE)


def load_ccsdspy_folder(
    folder: str | Path, time_code: TimeCode | None = None, time_fields: TimeFields | None = None
) -> Dictionary:
    """One ccsdspy CSV per APID in a folder, the APID in each file name (``apid00384.csv``, ``384.csv``)."""
    folder = Path(folder)
    files = sorted(folder.glob("*.csv"))
    if not files:
        raise ValueError(f"{folder}: no ccsdspy .csv definitions in this folder")
    parts = []
    for path in files:
        found = APID_IN_NAME.search(path.stem)
        if found is None:
            raise ValueError(f"{path.name}: the file name must carry the APID (apid00384.csv or 384.csv)")
        apid = int(found.group(1) or found.group(2))
        parts.append(load_ccsdspy_csv(path, apid=apid, time_code=time_code, time_fields=time_fields))
    return merge_dictionaries(parts, name=folder.name)


def merge_dictionaries(parts: list[Dictionary], name: str | None = None) -> Dictionary:
    """One spacecraft's dictionary from several (e.g. one ccsdspy CSV per APID); an APID is defined once.

    A parameter name in several packets is one series (the same measurand telemetered twice).
    """
    if len(parts) == 1 and name is None:
        return parts[0]
    packets: dict[int, PacketDefinition] = {}
    for part in parts:
        for apid, packet in part.packets.items():
            if apid in packets:
                raise ValueError(f"dictionaries: APID {apid} is defined twice ({packets[apid].name}, {packet.name})")
            packets[apid] = packet
    lows = [d.valid_from_utc_ns for d in parts if d.valid_from_utc_ns is not None]
    highs = [d.valid_until_utc_ns for d in parts if d.valid_until_utc_ns is not None]
    return Dictionary(
        name=name or "+".join(d.name for d in parts),
        packets=dict(sorted(packets.items())),
        valid_from_utc_ns=max(lows) if lows else None,
        valid_until_utc_ns=min(highs) if highs else None,
        satellite=next((d.satellite for d in parts if d.satellite), ""),
        notes=tuple(n for d in parts for n in d.notes),
        packet_prefix_octets=max(d.packet_prefix_octets for d in parts),
        packet_suffix_octets=max(d.packet_suffix_octets for d in parts),
    )


def _xtce_entries(container: Any) -> list[Any]:
    """Parameters of an XTCE container in packet order: base container first, container refs inlined."""
    from space_packet_parser.xtce.containers import SequenceContainer

    out: list[Any] = []
    for entry in container.entry_list:
        out.extend(_xtce_entries(entry) if isinstance(entry, SequenceContainer) else [entry])
    return out


def xtce_parameter(param: Any, bit: int) -> Parameter:
    """Our Parameter from a space-packet-parser XTCE parameter at a bit offset (ValueError: not read in bulk)."""
    from space_packet_parser.xtce import calibrators, encodings, parameter_types

    ptype, enc = param.parameter_type, param.parameter_type.encoding
    if getattr(enc, "byte_order", "mostSignificantByteFirst") != "mostSignificantByteFirst":
        raise ValueError(f"{param.name}: only big-endian XTCE encodings are supported")
    if isinstance(enc, encodings.FloatDataEncoding):
        data_type = "float"
    elif isinstance(enc, encodings.IntegerDataEncoding):
        data_type = "uint" if enc.encoding == "unsigned" else "int"
    else:
        raise ValueError(f"{param.name}: XTCE encoding {type(enc).__name__} is not supported in bulk decode")
    poly: tuple[float, ...] = ()
    if isinstance(enc.default_calibrator, calibrators.PolynomialCalibrator):
        order = max(c.exponent for c in enc.default_calibrator.coefficients)
        coeffs = np.zeros(int(order) + 1)
        for c in enc.default_calibrator.coefficients:
            coeffs[int(c.exponent)] = float(c.coefficient)
        poly = tuple(coeffs)
    elif enc.default_calibrator is not None:
        raise ValueError(f"{param.name}: XTCE calibrator {type(enc.default_calibrator).__name__} not supported")
    enum = {}
    if isinstance(ptype, parameter_types.EnumeratedParameterType):
        enum = {int(k): str(v) for k, v in ptype.enumeration.items()}  # spp maps value -> label
    unit = ptype.unit if isinstance(ptype.unit, str) or ptype.unit is None else " ".join(ptype.unit)
    return Parameter(
        name=param.name,
        data_type=data_type,
        bit_offset=bit,
        bit_length=int(enc.size_in_bits),
        units=unit or "",
        description=param.short_description or param.long_description or "",
        polynomial=poly,
        enumeration=enum,
    )


_APID_NAMES = ("PKT_APID", "APID", "CCSDS_APID")
_HEADER_NAMES = (*_APID_NAMES, "VERSION", "TYPE")


def _criterion_terms(criterion: Any) -> tuple[list[Any], bool]:
    """The conditions of one restriction criterion (XTCE Comparison, or a BooleanExpression's Condition,
    ANDed or ORed conditions without nesting) as (parameter, operator, value) objects, and True when they are
    ORed. Nested AND/OR gives no terms: not read as an APID selection (a container whose APID test is nested selects
    no APID by it), and a restriction beyond the APID for _restricts_beyond_apid."""
    from space_packet_parser.xtce import comparisons

    if not isinstance(criterion, comparisons.BooleanExpression):
        return [criterion], False
    expression = criterion.expression
    if isinstance(expression, comparisons.Condition):
        return [expression], False
    nested = expression.ands if isinstance(expression, comparisons.Ored) else expression.ors
    if nested:
        return [], False  # nested AND/OR: a restriction beyond the APID (space_packet_parser evaluates it)
    return list(expression.conditions), isinstance(expression, comparisons.Ored)


def _term_parameter(term: Any) -> str | None:
    """The parameter a Comparison or Condition tests (None when it compares two parameters)."""
    if getattr(term, "right_param", None) is not None:
        return None
    return getattr(term, "referenced_parameter", None) or getattr(term, "left_param", None)


def _term_value(term: Any) -> Any:
    return term.required_value if hasattr(term, "required_value") else term.right_value


def _criterion_apids(container: Any, criterion: Any) -> set[int] | None:
    """APIDs one restriction criterion selects: PKT_APID == N, or an OR of such (one container for several
    APIDs, as IMAP-Ultra's team writes it), or an AND holding one; None when it does not test the APID."""
    terms, ored = _criterion_terms(criterion)
    on_apid = [t for t in terms if _term_parameter(t) in _APID_NAMES]
    if not on_apid:
        return None
    if any(t.operator not in ("==", "eq") for t in on_apid):
        raise ValueError(f"{container.name}: APID restriction {on_apid[0].operator!r} is not an equality")
    if ored and len(on_apid) != len(terms):
        raise ValueError(f"{container.name}: an APID ORed with another condition does not select APIDs")
    if not ored and len(on_apid) > 1:
        raise ValueError(f"{container.name}: two APID equalities ANDed")
    return {int(_term_value(t)) for t in on_apid}


def _xtce_apids(definition: Any, container: Any) -> set[int]:
    """The APIDs a container's restriction criteria (or its bases') select (empty when none do)."""
    while container is not None:
        for criterion in container.restriction_criteria:
            apids = _criterion_apids(container, criterion)
            if apids is not None:
                return apids
        base = container.base_container_name
        container = definition.containers.get(base) if base else None
    return set()


def _xtce_chain(definition: Any, container: Any) -> list[Any]:
    """A container and its bases, root first."""
    chain: list[Any] = []
    c = container
    while c is not None:
        chain.insert(0, c)
        c = definition.containers.get(c.base_container_name) if c.base_container_name else None
    return chain


def _xtce_fixed(
    definition: Any, container: Any, apid: int, time_code: TimeCode | None, time_fields: TimeFields | None
) -> PacketDefinition:
    """The fixed layout of a container (ValueError when an entry has no fixed size or is not numeric)."""
    params, bit = [], 0
    for entry in (e for c in _xtce_chain(definition, container) for e in _xtce_entries(c)):
        size = getattr(entry.parameter_type.encoding, "size_in_bits", None)
        if not isinstance(size, int):
            raise ValueError(f"{entry.name}: no fixed size")
        if bit >= PRIMARY_HEADER_BITS:
            params.append(xtce_parameter(entry, bit))
        bit += size
    if bit % 8:
        raise ValueError(f"{container.name}: layout ends at bit {bit}, not on an octet boundary")
    return PacketDefinition(
        name=container.name,
        apid=apid,
        packet_octets=bit // 8,
        parameters=tuple(params),
        time_code=time_code,
        time_fields=time_fields.bound_to(p.name for p in params) if time_fields else None,
        description=container.short_description or container.long_description or "",
        accepts_segments=True,
    )


def _xtce_numeric_names(definition: Any, containers: list[Any]) -> tuple[str, ...]:
    """Integer, float, enumerated and boolean parameters the containers (and their bases) carry, in order, but
    the primary header's (its first 48 bits: VERSION … PKT_LEN): as for fixed layouts and ccsdspy, the header
    is the packet's, kept as its sequence count and raw octets, not a series."""
    from space_packet_parser.xtce import encodings

    names: dict[str, None] = {}
    for container in containers:
        bit = 0
        for entry in (e for c in _xtce_chain(definition, container) for e in _xtce_entries(c)):
            encoding = getattr(entry.parameter_type, "encoding", None)
            if bit < PRIMARY_HEADER_BITS:
                size = getattr(encoding, "size_in_bits", None)
                bit += size if isinstance(size, int) else PRIMARY_HEADER_BITS
                continue
            if isinstance(encoding, (encodings.IntegerDataEncoding, encodings.FloatDataEncoding)):
                names.setdefault(entry.name)
    return tuple(names)


def _xtce_values_per_octet(definition: Any, containers: list[Any]) -> float:
    """Most numeric values per octet of a packet these containers parse: over each non-abstract container of their
    chains (where a packet may end), its chain's numeric entries over the octets its fixed-size entries
    need (a dynamically sized entry counted as empty; a packet is at least a primary header and one octet)."""
    from space_packet_parser.xtce import encodings

    densest = 0.0
    for container in containers:
        values = bits = 0
        for c in _xtce_chain(definition, container):
            for entry in _xtce_entries(c):
                encoding = getattr(entry.parameter_type, "encoding", None)
                values += isinstance(encoding, (encodings.IntegerDataEncoding, encodings.FloatDataEncoding))
                size = getattr(encoding, "size_in_bits", None) or getattr(encoding, "fixed_size_in_bits", None)
                bits += size if isinstance(size, int) else 0
            if not c.abstract:
                densest = max(densest, values / max(-(-bits // 8), PRIMARY_HEADER_OCTETS + 1))
    return densest


def _restricts_beyond_apid(definition: Any, container: Any) -> bool:
    """True when a container (or a base) is selected by more than the APID (XTCE polymorphism)."""
    for c in _xtce_chain(definition, container):
        for criterion in c.restriction_criteria:
            terms, _ = _criterion_terms(criterion)
            if not terms or any(_term_parameter(t) not in _HEADER_NAMES for t in terms):
                return True
    return False


def _xtce_root(definition: Any, path: str | Path) -> str:
    """The container every packet is parsed from: space_packet_parser's default (``CCSDSPacket``) when the file
    has it, else the one container that has no base and that others extend (CTIM calls it
    ``CCSDSTelemetryPacket``; space_packet_parser needs it named by its caller)."""
    if definition.root_container_name in definition.containers:
        return str(definition.root_container_name)
    roots = [c.name for c in definition.containers.values() if not c.base_container_name and c.inheritors]
    if len(roots) != 1:
        raise ValueError(
            f"{path}: no container {definition.root_container_name!r} to parse packets from, and "
            f"{len(roots)} containers without a base that others extend ({', '.join(roots[:5])}): expected one"
        )
    return str(roots[0])


def load_xtce(path: str | Path, time_code: TimeCode | None = None, time_fields: TimeFields | None = None) -> Dictionary:
    """A dictionary of the APID-selected containers of an XTCE file (space-packet-parser reads it).

    An APID whose one concrete container has a fixed, numeric layout decodes in bulk (ours); an APID with
    polymorphic containers (inheritance with restriction criteria beyond the APID) or with dynamically
    sized or non-numeric entries is parsed packet by packet by space-packet-parser (``PacketDefinition.xtce``),
    its numeric parameters kept under their XTCE names (one series per name across containers).
    """
    import space_packet_parser as spp

    definition = spp.load_xtce(Path(path))
    definition.root_container_name = _xtce_root(definition, path)
    by_apid: dict[int, list[Any]] = {}
    for container in definition.containers.values():
        if not container.abstract:
            for apid in sorted(_xtce_apids(definition, container)):
                by_apid.setdefault(apid, []).append(container)
    packets = {}
    for apid, containers in by_apid.items():
        polymorphic = len(containers) > 1
        if polymorphic and not any(_restricts_beyond_apid(definition, c) for c in containers):
            raise ValueError(
                f"{containers[1].name}: APID {apid} already belongs to {containers[0].name} "
                "(two containers, no restriction to tell them apart)"
            )
        if not polymorphic:
            try:
                packets[apid] = _xtce_fixed(definition, containers[0], apid, time_code, time_fields)
                continue
            except (ValueError, AttributeError, TypeError):
                pass  # dynamic sizes or non-numeric entries: space-packet-parser reads them
        numeric = _xtce_numeric_names(definition, containers)
        chains = [_xtce_chain(definition, c) for c in containers]
        shared = [c for k, c in enumerate(chains[0]) if all(len(ch) > k and ch[k] is c for ch in chains)]
        base = shared[-1] if shared else containers[0]  # the deepest container they all extend
        packets[apid] = PacketDefinition(
            name=base.name,
            apid=apid,
            packet_octets=PRIMARY_HEADER_OCTETS + 1,
            parameters=(),
            time_code=time_code,
            time_fields=time_fields.bound_to(numeric) if time_fields else None,
            description=base.short_description or base.long_description or "",
            xtce=XtceSource(
                definition, tuple(c.name for c in containers), numeric, _xtce_values_per_octet(definition, containers)
            ),
            accepts_segments=True,
        )
    if not packets:
        raise ValueError(f"{path}: no concrete container selects an APID")
    return Dictionary(name=definition.space_system_name or Path(path).stem, packets=packets)


def load_dictionary(
    path: str | Path, apid: int | None = None, time_code: str | None = None, time_fields: str | None = None
) -> Dictionary:
    """Any supported dictionary: .yaml/.yml, .csv (ccsdspy), .xml (XTCE), or a folder of ccsdspy CSVs (one per APID).

    A bare name means a shipped one. time_code / time_fields (``year=F1,doy=F2,…``) stamp the
    packets of CSV and XTCE definitions, which carry no time of their own.
    """
    path = Path(path)
    if not path.exists() and (SHIPPED / path).exists():
        path = SHIPPED / path
    if not path.exists():
        raise ValueError(f"dictionary: no file {path} (shipped: {sorted(p.name for p in SHIPPED.glob('*.yaml'))})")
    code, fields = parse_time_code(time_code), parse_time_fields(time_fields)
    if path.is_dir():
        return load_ccsdspy_folder(path, time_code=code, time_fields=fields)
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        if code or fields:
            raise ValueError("time: a YAML dictionary defines its packets' time itself (time_code or time_fields)")
        return load_yaml(path)
    if suffix == ".xml":
        return load_xtce(path, time_code=code, time_fields=fields)
    if suffix == ".csv":
        if apid is None or not 0 <= apid < APID_COUNT:
            raise ValueError("apid: a ccsdspy CSV definition needs the APID (0..2046) of its packets")
        return load_ccsdspy_csv(path, apid=apid, time_code=code, time_fields=fields)
    raise ValueError(f"dictionary: unknown suffix {suffix!r} (use .yaml, .xml, .csv or a folder of .csv)")
