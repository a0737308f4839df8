"""Polymorphic XTCE containers decoded in bulk: space_packet_parser's container walk, vectorised over packets.

space_packet_parser parses a packet from the root container down: each container's entries in
order, then the one inheritor whose restriction criteria hold (none: done, or an error when the
container is abstract; several: an error). Here the same walk runs on groups of packets at once:
packets that reach the same container at the same bit position share a fixed layout, so their
fields are read by one compiled pass (``read_fields``); a dynamically sized entry (XTCE
``DynamicValue`` with its ``LinearAdjustment``, space_packet_parser's own adjuster) splits a group
by size, restriction criteria split it by inheritor. Only what decodes exactly as space_packet_parser
does is compiled: integer and float encodings without calibrators, binary entries of fixed or
referenced size, comparisons on integer or float values. Anything else raises :class:`Unsupported`
and the caller parses those packets one by one with space_packet_parser.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from telemetry.dictionary import Parameter

__all__ = ["Unsupported", "XtceWalk"]

_OPERATORS: dict[str, Callable[[np.ndarray, Any], np.ndarray]] = {
    "__eq__": np.equal,
    "__ne__": np.not_equal,
    "__lt__": np.less,
    "__gt__": np.greater,
    "__le__": np.less_equal,
    "__ge__": np.greater_equal,
}
_INTEGER_ENCODINGS = ("unsigned", "signed", "twosCompliment", "twosComplement")


class Unsupported(Exception):
    """An XTCE construct the bulk walk does not reproduce exactly (space_packet_parser reads it instead)."""


@dataclass(frozen=True)
class _Field:
    """A numeric entry: its Parameter at bit 0 (placed at the packet's bit when read)."""

    parameter: Parameter


@dataclass(frozen=True)
class _Skip:
    """A non-numeric entry of fixed size, or of a size read from an earlier field (then adjusted)."""

    name: str
    bits: int | None = None
    reference: str | None = None
    adjust: Callable[[float], float] | None = None


@dataclass
class _Node:
    """A container: its own entries, and how its inheritors are told apart."""

    name: str
    abstract: bool
    entries: list[_Field | _Skip] = field(default_factory=list)
    criteria: list[Callable[[dict[str, np.ndarray]], np.ndarray]] = field(default_factory=list)
    inheritors: list[str] = field(default_factory=list)


@dataclass
class _Group:
    """Packets (positions ``idx`` in the APID's packets) at one container and bit, with the fields read so far."""

    idx: np.ndarray
    node: str
    bit: int
    values: dict[str, np.ndarray]


ReadFields = Callable[[np.ndarray, tuple[Parameter, ...]], dict[str, np.ndarray]]


class XtceWalk:
    """The container walk of one space_packet_parser definition, each container compiled when first reached.

    parameter_of(entry, bit) is the dictionary's Parameter of a numeric XTCE parameter.
    """

    def __init__(self, definition: Any, parameter_of: Callable[[Any, int], Parameter]) -> None:
        self.definition = definition
        self.parameter_of = parameter_of
        self.root = str(definition.root_container_name)
        self._nodes: dict[str, _Node] = {}
        self._layouts: dict[tuple[int, int, int], tuple[Parameter, ...]] = {}

    def parse(
        self, positions: np.ndarray, length: np.ndarray, read_fields: ReadFields
    ) -> tuple[list[tuple[np.ndarray, dict[str, np.ndarray]]], dict[int, str]]:
        """Values of the numeric fields of each group of packets that ended in the same container, and why
        the others could not be parsed (by position). ``read_fields(positions, parameters)`` reads the
        parameters from the packets at those positions; ``length`` is each packet's octets."""
        groups = [_Group(positions, self.root, 0, {})]
        done: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []
        failed: dict[int, str] = {}
        while groups:
            group = groups.pop()
            node = self._node(group.node)
            parts = self._entries(group, node, length, read_fields, failed)
            for part in parts:
                groups.extend(self._inherit(part, node, failed, done))
        return done, failed

    def _entries(
        self, group: _Group, node: _Node, length: np.ndarray, read_fields: ReadFields, failed: dict[int, str]
    ) -> list[_Group]:
        """The group after the node's entries: fields read, split where a dynamic size differs."""
        pending: list[Parameter] = []
        parts = [group]
        for entry in node.entries:
            if isinstance(entry, _Field):
                pending.append(entry.parameter)
                continue
            parts = [p for part in parts for p in self._read(part, pending, length, read_fields, failed, node.name)]
            pending = []
            parts = [p for part in parts for p in _skip(part, entry, failed)]
        return [p for part in parts for p in self._read(part, pending, length, read_fields, failed, node.name)]

    def _read(
        self,
        group: _Group,
        params: list[Parameter],
        length: np.ndarray,
        read_fields: ReadFields,
        failed: dict[int, str],
        container: str,
    ) -> list[_Group]:
        """The group with params (consecutive, from its bit) read; packets too short for them fail."""
        if not params or group.idx.size == 0:
            return [group] if group.idx.size else []
        placed = self._placed(params, group.bit)
        bit = group.bit + sum(p.bit_length for p in params)
        fits = length[group.idx] * 8 >= bit
        for i in group.idx[~fits].tolist():
            failed[i] = f"packet has {int(length[i])} octets, container {container} needs {(bit + 7) // 8}"
        if not fits.all():
            group = _Group(group.idx[fits], group.node, group.bit, {k: v[fits] for k, v in group.values.items()})
        if group.idx.size == 0:
            return []
        read = read_fields(group.idx, placed)
        return [_Group(group.idx, group.node, bit, {**group.values, **read})]

    def _placed(self, params: list[Parameter], bit: int) -> tuple[Parameter, ...]:
        """The params laid out from bit on (one tuple per layout: the decoder compiles it once)."""
        key = (id(params[0]), len(params), bit)
        if key not in self._layouts:
            placed = []
            for p in params:
                try:
                    placed.append(replace(p, bit_offset=bit))
                except ValueError as exc:  # e.g. a field spanning more than 8 octets at this bit
                    raise Unsupported(str(exc)) from exc
                bit += p.bit_length
            self._layouts[key] = tuple(placed)
        return self._layouts[key]

    def _inherit(
        self, group: _Group, node: _Node, failed: dict[int, str], done: list[tuple[np.ndarray, dict[str, np.ndarray]]]
    ) -> list[_Group]:
        """The group split by the inheritor whose restriction criteria hold (space_packet_parser's rule)."""
        if group.idx.size == 0:
            return []
        matches = []
        for name in node.inheritors:
            ok = np.ones(group.idx.size, dtype=bool)
            for holds in self._node(name).criteria:
                ok &= holds(group.values)
            matches.append(ok)
        count = np.sum(matches, axis=0) if matches else np.zeros(group.idx.size, dtype=np.int64)
        out = []
        for name, ok in zip(node.inheritors, matches):
            take = ok & (count == 1)
            if take.any():
                out.append(_Group(group.idx[take], name, group.bit, {k: v[take] for k, v in group.values.items()}))
        for i in group.idx[count > 1].tolist():
            failed[i] = f"several containers inheriting {node.name} match"
        none = count == 0
        if none.any():
            if node.abstract:
                failed.update((i, f"no container inheriting {node.name} matches") for i in group.idx[none].tolist())
            else:
                done.append((group.idx[none], {k: v[none] for k, v in group.values.items()}))
        return out

    def _node(self, name: str) -> _Node:
        """The compiled container ``name`` (Unsupported when it holds a construct the walk does not reproduce)."""
        if name not in self._nodes:
            self._nodes[name] = self._compile(self.definition.containers[name])
        return self._nodes[name]

    def _compile(self, container: Any) -> _Node:
        from space_packet_parser.xtce import comparisons

        node = _Node(container.name, bool(container.abstract), inheritors=list(container.inheritors))
        for criterion in container.restriction_criteria:
            if type(criterion) is comparisons.Comparison:
                node.criteria.append(
                    self._compare(
                        container.name,
                        criterion.referenced_parameter,
                        criterion.operator,
                        criterion.required_value,
                        criterion.use_calibrated_value,
                    )
                )
            elif type(criterion) is comparisons.BooleanExpression:
                node.criteria.append(self._expression(container.name, criterion.expression))
            else:
                raise Unsupported(f"{container.name}: restriction {criterion!r}")
        node.entries = [self._entry(e) for e in _flat_entries(container)]
        return node

    def _compare(
        self, container: str, param: str, operator: str, required: Any, calibrated: bool
    ) -> Callable[[dict[str, np.ndarray]], np.ndarray]:
        """Per packet, whether ``param <operator> required`` holds (the value coerced as space_packet_parser does)."""
        from space_packet_parser.xtce import comparisons

        if calibrated:
            self._plain(param)
        compare = _OPERATORS[comparisons.MatchCriteria._valid_operators[operator]]

        def holds(values: dict[str, np.ndarray]) -> np.ndarray:
            if param not in values:
                raise Unsupported(f"{container}: criterion on {param}, not read before it")
            return np.asarray(compare(values[param], _coerce(values[param], required)), dtype=bool)

        return holds

    def _expression(self, container: str, expression: Any) -> Callable[[dict[str, np.ndarray]], np.ndarray]:
        """An XTCE BooleanExpression (Condition, ANDed and ORed conditions, nested) evaluated per packet, with
        space_packet_parser's semantics (BooleanExpression.evaluate)."""
        from space_packet_parser.xtce import comparisons

        if isinstance(expression, comparisons.Condition):
            if expression.right_param is not None:
                raise Unsupported(f"{container}: condition comparing two parameters")
            return self._compare(
                container,
                expression.left_param,
                expression.operator,
                expression.right_value,
                expression.left_use_calibrated_value,
            )
        anded = isinstance(expression, comparisons.Anded)
        nested = expression.ors if anded else expression.ands
        parts = [self._expression(container, c) for c in (*expression.conditions, *nested)]
        if not parts:
            raise Unsupported(f"{container}: empty boolean expression")

        def holds(values: dict[str, np.ndarray]) -> np.ndarray:
            result = parts[0](values)
            for part in parts[1:]:
                result = (result & part(values)) if anded else (result | part(values))
            return result

        return holds

    def _plain(self, name: str) -> None:
        """Unsupported unless the parameter's calibrated value is its raw value (a number, no calibrator)."""
        from space_packet_parser.xtce import encodings, parameter_types

        param = self.definition.parameters.get(name)
        ptype = getattr(param, "parameter_type", None)
        enc = getattr(ptype, "encoding", None)
        if (
            not isinstance(enc, (encodings.IntegerDataEncoding, encodings.FloatDataEncoding))
            or isinstance(ptype, (parameter_types.EnumeratedParameterType, parameter_types.BooleanParameterType))
            or enc.default_calibrator is not None
            or enc.context_calibrators
        ):
            raise Unsupported(f"{name}: its calibrated value is not its raw number")

    def _entry(self, entry: Any) -> _Field | _Skip:
        from space_packet_parser.xtce import encodings, parameter_types

        ptype = entry.parameter_type
        enc: Any = getattr(ptype, "encoding", None)
        if isinstance(ptype, parameter_types.BooleanParameterType) or type(enc) not in (
            encodings.IntegerDataEncoding,
            encodings.FloatDataEncoding,
            encodings.BinaryDataEncoding,
        ):
            raise Unsupported(f"{entry.name}: {type(ptype).__name__} / {type(enc).__name__}")
        if isinstance(enc, encodings.BinaryDataEncoding):
            if enc.fixed_size_in_bits is not None:
                return _Skip(entry.name, bits=int(enc.fixed_size_in_bits))
            if enc.size_reference_parameter is None:
                raise Unsupported(f"{entry.name}: binary size from a discrete lookup")
            if enc.use_calibrated_value:
                self._plain(enc.size_reference_parameter)
            return _Skip(entry.name, reference=enc.size_reference_parameter, adjust=enc.linear_adjuster)
        if enc.default_calibrator is not None or enc.context_calibrators:
            raise Unsupported(f"{entry.name}: calibrated")
        if isinstance(enc, encodings.IntegerDataEncoding) and enc.encoding not in _INTEGER_ENCODINGS:
            raise Unsupported(f"{entry.name}: integer encoding {enc.encoding}")
        try:
            return _Field(self.parameter_of(entry, 0))
        except ValueError as exc:  # e.g. little-endian: the dictionary does not read it in bulk
            raise Unsupported(str(exc)) from exc


def _flat_entries(container: Any) -> list[Any]:
    """A container's entries in packet order, container references inlined (not its bases)."""
    from space_packet_parser.xtce.containers import SequenceContainer

    out: list[Any] = []
    for entry in container.entry_list:
        out.extend(_flat_entries(entry) if isinstance(entry, SequenceContainer) else [entry])
    return out


def _coerce(values: np.ndarray, required: str) -> int | float:
    """The required value as space_packet_parser coerces it: to the type of the parsed value."""
    try:
        return float(required) if values.dtype.kind == "f" else int(required)
    except ValueError as exc:
        raise Unsupported(f"comparison value {required!r} is not a number") from exc


def _skip(group: _Group, entry: _Skip, failed: dict[int, str]) -> list[_Group]:
    """The group past a non-numeric entry, split by its size when that comes from a field."""
    if entry.bits is not None:
        return [_Group(group.idx, group.node, group.bit + entry.bits, group.values)]
    assert entry.reference is not None
    if entry.reference not in group.values:
        raise Unsupported(f"{entry.name}: size from {entry.reference}, not read before it")
    reference = group.values[entry.reference]
    out = []
    for value in np.unique(reference).tolist():
        size = int(entry.adjust(value) if entry.adjust else value)
        mine = reference == value
        if size < 0:
            failed.update((i, f"{entry.name}: negative size {size} bits") for i in group.idx[mine].tolist())
            continue
        values = {k: v[mine] for k, v in group.values.items()}
        out.append(_Group(group.idx[mine], group.node, group.bit + size, values))
    return out
