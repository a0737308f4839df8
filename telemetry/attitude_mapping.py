"""Attitude mapping: which parameters of a dictionary are a satellite's attitude, rates, wheels, mode and orbit.

A small YAML declaration beside a dictionary (``<dictionary stem>.attitude.yaml``) names the attitude
quaternion's four parameters with their convention (scalar ``first`` or ``last``; direction
``body_to_inertial``, i.e. q_ib of DESIGN.md, or ``inertial_to_body``), and optionally the body rates,
wheel speeds, the wheels onboard FDIR isolated, the mode, the GPS orbit and the library scenario of the
satellite's onboard ACS (``acs_model``; absent: the satellite has no ACS model and only its actual
attitude is shown). :func:`actual_attitude` turns decoded values into DESIGN.md's scalar-first q_ib and
reports non-unit quaternions and hemisphere flips (q and −q are one attitude).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

__all__ = [
    "SHIPPED_MAPPINGS",
    "UNIT_NORM_TOLERANCE",
    "AttitudeMapping",
    "QuaternionCheck",
    "actual_attitude",
    "load_mapping",
    "mapping_for_parameters",
    "shipped_mapping",
]

SHIPPED_MAPPINGS = Path(__file__).parent / "dictionaries"
MAPPING_SUFFIX = ".attitude.yaml"
# A float32 unit quaternion is unit to ~1e-7; 1e-3 (≈ 0.06° of rotation if left unnormalised) is a corrupt sample.
UNIT_NORM_TOLERANCE = 1e-3
SCALAR_POSITIONS = ("first", "last")
DIRECTIONS = ("body_to_inertial", "inertial_to_body")


@dataclass(frozen=True)
class AttitudeMapping:
    """Names of a satellite's attitude-related parameters in one dictionary, and their conventions."""

    dictionary: str
    packet: str
    quaternion: tuple[str, str, str, str]
    scalar: str = "first"
    direction: str = "body_to_inertial"
    rates_b_rad_s: tuple[str, str, str] | None = None
    wheel_speeds_rad_s: tuple[str, ...] | None = None
    wheel_isolated: tuple[str, ...] | None = None
    mode: str | None = None
    turn_modes: tuple[int, ...] = ()
    orbit_packet: str | None = None
    r_ecef_m: tuple[str, str, str] | None = None
    v_ecef_m_s: tuple[str, str, str] | None = None
    acs_model: str | None = None
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        where = self.source or self.dictionary
        if len(self.quaternion) != 4:
            raise ValueError(f"{where}: attitude.quaternion: expected 4 parameter names, got {len(self.quaternion)}")
        if self.scalar not in SCALAR_POSITIONS:
            raise ValueError(f"{where}: attitude.scalar: expected one of {SCALAR_POSITIONS}, got {self.scalar!r}")
        if self.direction not in DIRECTIONS:
            raise ValueError(f"{where}: attitude.direction: expected one of {DIRECTIONS}, got {self.direction!r}")
        if self.acs_model is not None and not (
            self.rates_b_rad_s and self.wheel_speeds_rad_s and self.r_ecef_m and self.v_ecef_m_s and self.wheel_isolated
        ):
            raise ValueError(
                f"{where}: acs_model: a twin needs rates_b_rad_s, wheel_speeds_rad_s, wheel_isolated "
                "and the GPS orbit (r_ecef_m, v_ecef_m_s) mapped too"
            )

    def hk_parameters(self) -> list[str]:
        """Parameters of the attitude packet the mapping reads."""
        names = [
            *self.quaternion,
            *(self.rates_b_rad_s or ()),
            *(self.wheel_speeds_rad_s or ()),
            *(self.wheel_isolated or ()),
        ]
        return names + ([self.mode] if self.mode else [])

    def orbit_parameters(self) -> list[str]:
        """Parameters of the orbit packet the mapping reads."""
        return [*(self.r_ecef_m or ()), *(self.v_ecef_m_s or ())]

    def check(self, dictionary: Any) -> None:
        """ValueError naming every mapped parameter the dictionary lacks (and the mapping file)."""
        where = self.source or self.dictionary
        packets = {p.name: p for p in dictionary.packets.values()}
        wanted = [(self.packet, self.hk_parameters())]
        if self.orbit_packet:
            wanted.append((self.orbit_packet, self.orbit_parameters()))
        for packet, names in wanted:
            if packet not in packets:
                raise ValueError(f"{where}: packet {packet!r} is not in dictionary {self.dictionary!r}")
            known = {p.name for p in packets[packet].parameters} | {d.name for d in packets[packet].derived}
            missing = [n for n in names if n not in known]
            if missing:
                raise ValueError(f"{where}: parameters {missing} are not in packet {packet!r} of {self.dictionary!r}")


def _names(data: dict[str, Any], key: str, n: int | None, where: str) -> tuple[str, ...] | None:
    value = data.get(key)
    if value is None:
        return None
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value) or (n is not None and len(value) != n):
        raise ValueError(f"{where}: {key}: expected a list of {n or 'some'} parameter names")
    return tuple(value)


def load_mapping(path: Path) -> AttitudeMapping:
    """Read one ``*.attitude.yaml`` (ValueError naming the file and the field)."""
    where = path.name
    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict) or not isinstance(data.get("attitude"), dict):
        raise ValueError(f"{where}: expected a mapping with an 'attitude' section")  # noqa: TRY004 (bad file)
    att, orb = data["attitude"], data.get("orbit") or {}
    q = _names(att, "quaternion", 4, where)
    if q is None or "dictionary" not in data or "packet" not in att:
        raise ValueError(f"{where}: 'dictionary', 'attitude.packet' and 'attitude.quaternion' are required")
    return AttitudeMapping(
        dictionary=str(data["dictionary"]),
        packet=str(att["packet"]),
        quaternion=q,  # type: ignore[arg-type]
        scalar=str(att.get("scalar", "first")),
        direction=str(att.get("direction", "body_to_inertial")),
        rates_b_rad_s=_names(att, "rates_b_rad_s", 3, where),  # type: ignore[arg-type]
        wheel_speeds_rad_s=_names(att, "wheel_speeds_rad_s", None, where),
        wheel_isolated=_names(att, "wheel_isolated", None, where),
        mode=att.get("mode"),
        turn_modes=tuple(int(m) for m in att.get("turn_modes", ())),
        orbit_packet=orb.get("packet"),
        r_ecef_m=_names(orb, "r_ecef_m", 3, where),  # type: ignore[arg-type]
        v_ecef_m_s=_names(orb, "v_ecef_m_s", 3, where),  # type: ignore[arg-type]
        acs_model=data.get("acs_model"),
        source=where,
    )


def shipped_mapping(dictionary_name: str, folder: Path = SHIPPED_MAPPINGS) -> AttitudeMapping | None:
    """The mapping shipped beside dictionary ``dictionary_name`` (None if there is none)."""
    path = folder / f"{Path(dictionary_name).stem}{MAPPING_SUFFIX}"
    return load_mapping(path) if path.is_file() else None


def mapping_for_parameters(archived: set[str], folder: Path = SHIPPED_MAPPINGS) -> AttitudeMapping | None:
    """The shipped mapping whose attitude parameters are all among ``archived`` (a satellite's archived names)."""
    for path in sorted(folder.glob(f"*{MAPPING_SUFFIX}")):
        mapping = load_mapping(path)
        if set(mapping.hk_parameters()) <= archived:
            return mapping
    return None


@dataclass(frozen=True)
class QuaternionCheck:
    """What :func:`actual_attitude` found wrong in a run of quaternion samples."""

    non_unit: int  # samples whose norm is off by more than UNIT_NORM_TOLERANCE (normalised)
    invalid: int  # samples that are zero or not finite (dropped)
    flips: int  # hemisphere flips (q → −q between neighbours; made continuous)
    worst_norm_error: float

    def messages(self) -> list[str]:
        """Human-readable findings (empty when the quaternions were clean)."""
        out = []
        if self.non_unit:
            out.append(
                f"{self.non_unit} quaternion samples not unit (|‖q‖ − 1| up to {self.worst_norm_error:.3g}): normalised"
            )
        if self.invalid:
            out.append(f"{self.invalid} quaternion samples zero or not finite: ignored")
        if self.flips:
            out.append(f"{self.flips} hemisphere flips (q → −q): made continuous")
        return out


def actual_attitude(
    mapping: AttitudeMapping, values: dict[str, np.ndarray], previous_q_ib: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, QuaternionCheck]:
    """(valid (n,) mask, (n, 4) scalar-first unit q_ib continuous from ``previous_q_ib``, findings) of a batch."""
    raw = np.stack([np.asarray(values[n], dtype=np.float64) for n in mapping.quaternion], axis=-1)
    q = raw if mapping.scalar == "first" else raw[:, [3, 0, 1, 2]]
    if mapping.direction == "inertial_to_body":
        q = q * np.array([1.0, -1.0, -1.0, -1.0])  # q_bi → q_ib: the conjugate
    norm = np.linalg.norm(q, axis=-1)
    valid = np.isfinite(norm) & (norm > 0.5)
    error = np.abs(norm - 1.0)
    non_unit = valid & (error > UNIT_NORM_TOLERANCE)
    q = np.where(valid[:, None], q / np.where(valid, norm, 1.0)[:, None], np.nan)
    flips, last = 0, previous_q_ib
    for i in np.flatnonzero(valid):
        if last is not None and float(np.dot(last, q[i])) < 0.0:
            q[i] = -q[i]
            flips += 1
        last = q[i]
    worst = float(error[non_unit].max()) if non_unit.any() else 0.0
    return valid, q, QuaternionCheck(int(non_unit.sum()), int((~valid).sum()), flips, worst)
