"""Files of a simulation result: npz, CSV, Parquet and PNG plots like seed 000 Figs 4–7; a job's npz as rows."""

from __future__ import annotations

import json
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING

import numpy as np

from sim_core import quaternion
from sim_core.trajectory import ARCSEC_PER_RAD, Trajectory

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = [
    "EXPORT_BATCH_ROWS",
    "columns",
    "npz_rows",
    "read_npz",
    "write_all",
    "write_csv",
    "write_npz",
    "write_parquet",
    "write_plots",
]

EXPORT_BATCH_ROWS = 50_000  # rows per streamed record batch of npz_rows: a few MB of CSV


def write_npz(traj: Trajectory, path: Path) -> Path:
    """All series (variant, sample, …), the time axis and the events as one compressed npz."""
    meta = {
        "scenario": traj.scenario_name,
        "variants": traj.variant_names,
        "events": traj.events,
        "wall_time_s": traj.wall_time_s,
        "simulated_time_s": traj.simulated_time_s,
        **traj.extra,
    }
    np.savez_compressed(
        path,
        t_s=traj.t_s,
        wheel_inertia_kg_m2=traj.wheel_inertia_kg_m2,
        meta=np.array(json.dumps(meta)),
        allow_pickle=False,
        **traj.series,
    )
    return path


def read_npz(path: Path) -> Trajectory:
    """Trajectory back from :func:`write_npz`."""
    with np.load(path) as data:
        meta = json.loads(str(data["meta"]))
        series = {k: data[k] for k in data.files if k not in ("t_s", "wheel_inertia_kg_m2", "meta")}
        t, jr = data["t_s"], data["wheel_inertia_kg_m2"]
    events = [[tuple(e) for e in ev] for ev in meta.pop("events")]
    return Trajectory(
        meta.pop("scenario"),
        meta.pop("variants"),
        t,
        series,
        events,
        jr,
        meta.pop("wall_time_s"),
        meta.pop("simulated_time_s"),
        meta,
    )


def columns(traj: Trajectory, variant: int = 0) -> dict[str, np.ndarray]:
    """Flat named columns of one variant (units in the names), with the seed-000 ORF angles and errors."""
    out: dict[str, np.ndarray] = {"t_s": traj.t_s}
    for name, arr in traj.series.items():
        a = arr[variant]
        if a.ndim == 1:
            out[name] = a
        else:
            for i in range(a.shape[-1]):
                out[f"{name}_{i}"] = a[:, i]
    out["pointing_error_arcsec"] = traj.pointing_error_rad()[variant] * ARCSEC_PER_RAD
    return out


def write_csv(traj: Trajectory, path: Path, variant: int = 0) -> Path:
    """One variant as CSV with a header row."""
    cols = columns(traj, variant)
    np.savetxt(
        path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="", fmt="%.10g"
    )
    return path


def write_parquet(traj: Trajectory, path: Path) -> Path:
    """Every variant as Parquet rows with a ``variant`` column."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    tables = []
    for v, name in enumerate(traj.variant_names):
        cols = columns(traj, v)
        cols["variant"] = np.full(traj.t_s.size, name)
        tables.append(pa.table(cols))
    pq.write_table(pa.concat_tables(tables), path)
    return path


@dataclass(frozen=True)
class _Member:
    """One .npy member of an npz archive, from its header: the name, shape, dtype and whether it is C-ordered."""

    name: str
    shape: tuple[int, ...]
    dtype: np.dtype
    c_order: bool


def _npz_members(archive: zipfile.ZipFile) -> Iterator[tuple[_Member, IO[bytes]]]:
    """Each .npy member of an npz with its stream opened just past the header (NEP 1 format 1.0 or 2.0), nothing
    of its data read."""
    for info in archive.infolist():
        if not info.filename.endswith(".npy"):
            continue
        stream = archive.open(info)
        version = np.lib.format.read_magic(stream)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(stream)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(stream)
        else:
            stream.close()
            raise ValueError(f"{info.filename}: .npy format {version} (numpy's savez writes 1.0 or 2.0)")
        yield _Member(info.filename[: -len(".npy")], shape, dtype, not fortran and not dtype.hasobject), stream


def npz_rows(path: Path) -> tuple[pa.Schema, Iterator[pa.RecordBatch]]:
    """A job's trajectory.npz (engine or rigid spin) as rows at full resolution: ``member`` (batch index), ``t_s``,
    then every time series (an array whose axis 1 is the time axis, the batch on axis 0) as one column per
    component, ``name_i`` (as :func:`columns`), or ``name`` when scalar; member after member, in record batches of
    EXPORT_BATCH_ROWS rows. Streamed per series: member-major rows are the C order of a (member, time, component)
    array, so each batch reads the next rows of every series' compressed member in turn; only the time axis and
    one batch are held (a Fortran-ordered series, which np.savez writes only for Fortran-contiguous arrays, is read
    whole)."""
    import pyarrow as pa

    with zipfile.ZipFile(path) as archive:
        members = {}
        for member, stream in _npz_members(archive):
            members[member.name] = member
            stream.close()
        with np.load(path) as npz:
            t = npz["t_s"]
    series = {
        k: m for k, m in members.items() if k != "t_s" and len(m.shape) >= 2 and m.shape[1] == t.size
    }  # the npz's own order, as np.load lists it
    widths = {k: int(np.prod(m.shape[2:], dtype=np.int64)) for k, m in series.items()}
    fields = [pa.field("member", pa.int32()), pa.field("t_s", pa.from_numpy_dtype(t.dtype))]
    for k, m in series.items():
        names = [k] if len(m.shape) == 2 else [f"{k}_{i}" for i in range(widths[k])]
        fields += [pa.field(name, pa.from_numpy_dtype(m.dtype)) for name in names]
    schema = pa.schema(fields)
    n_members = next(iter(series.values())).shape[0] if series else 1

    def batches() -> Iterator[pa.RecordBatch]:
        with zipfile.ZipFile(path) as archive:
            readers: dict[str, Callable[[int], np.ndarray]] = {}
            for member, stream in _npz_members(archive):
                if member.name in series:
                    readers[member.name] = _row_reader(member, stream, widths[member.name], path)
            for m in range(n_members):
                for lo in range(0, t.size, EXPORT_BATCH_ROWS):
                    rows = t[lo : lo + EXPORT_BATCH_ROWS]
                    cols = [np.full(rows.size, m, dtype=np.int32), rows]
                    for k in series:
                        block = readers[k](rows.size)
                        cols += [block[:, i] for i in range(widths[k])]
                    yield pa.record_batch([pa.array(c) for c in cols], schema=schema)

    return schema, batches()


def _row_reader(member: _Member, stream: IO[bytes], width: int, path: Path) -> Callable[[int], np.ndarray]:
    """The next ``n`` rows (n, width) of a series in member-major order: read from its stream when C-ordered, else
    sliced from the array read whole."""
    if not member.c_order:
        stream.close()
        with np.load(path) as npz:
            whole = npz[member.name].reshape(-1, width, order="C")
        at = 0

        def sliced(n: int) -> np.ndarray:
            nonlocal at
            at += n
            return whole[at - n : at]

        return sliced
    row_bytes = width * member.dtype.itemsize

    def read(n: int) -> np.ndarray:
        data = stream.read(n * row_bytes)
        if len(data) != n * row_bytes:
            raise ValueError(f"{member.name}.npy: ends early ({len(data)} of {n * row_bytes} bytes)")
        return np.frombuffer(data, dtype=member.dtype).reshape(n, width)

    return read


def write_plots(traj: Trajectory, out_dir: Path, variant: int = 0) -> list[Path]:
    """PNG plots like seed 000 Figs 4–7: program angles and rates, errors, wheel torques and momenta, MD moments."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = traj.t_s
    s = {k: v[variant] for k, v in traj.series.items()}
    e = quaternion.multiply(quaternion.conjugate(s["q_prog_ib"]), s["q_ib"])
    e = np.where(e[:, :1] < 0, -e, e)
    err_arcsec = 2.0 * e[:, 1:] * ARCSEC_PER_RAD
    rate_err = np.degrees(s["omega_b_rad_s"] - s["omega_prog_b_rad_s"])
    figures = {
        "program_rates": (np.degrees(s["omega_prog_b_rad_s"]), "program rate ω^p (deg/s)"),
        "attitude_errors": (err_arcsec, "attitude error δφ (arcsec)"),
        "rate_errors": (rate_err, "rate error δω (deg/s)"),
        "wheel_torques": (s["wheel_torque_nm"], "wheel torque m_p (N·m)"),
        "wheel_momenta": (s["wheel_speed_rad_s"] * traj.wheel_inertia_kg_m2, "wheel momentum h_p (N·m·s)"),
        "md_moments": (s["md_dipole_am2"], "MD moment l_i (A·m²)"),
    }
    paths = []
    for name, (y, label) in figures.items():
        fig, ax = plt.subplots(figsize=(8, 3.2), dpi=110)
        ax.plot(t, y, lw=0.8)
        ax.set_xlabel("t (s)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.set_title(f"{traj.scenario_name} / {traj.variant_names[variant]}")
        fig.tight_layout()
        path = out_dir / f"{name}.png"
        fig.savefig(path)
        plt.close(fig)
        paths.append(path)
    return paths


def write_all(traj: Trajectory, out_dir: Path) -> list[Path]:
    """npz + Parquet of the batch, CSV and plots of variant 0, and the summary JSON of each variant."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [
        write_npz(traj, out_dir / "trajectory.npz"),
        write_parquet(traj, out_dir / "trajectory.parquet"),
        write_csv(traj, out_dir / "trajectory.csv"),
    ]
    summary = out_dir / "summary.json"
    summary.write_text(json.dumps([traj.summary(v) for v in range(traj.n_variants)], indent=2))
    return paths + [summary] + write_plots(traj, out_dir)
