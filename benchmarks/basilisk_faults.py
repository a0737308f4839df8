"""Telemetry of ``peer-basilisk-rw4`` flown by Basilisk with a hidden wheel fault, as a ground CSV at 1 Hz.

The independent "satellite" of the diagnosis acceptance (issue 14): Basilisk (``bsk`` 2.12.1) flies
the peer case of :mod:`benchmarks.peer_basilisk` (same spacecraft, orbit, MRP feedback and
minimum-norm mapping), and a Python module between the mapping's command and the wheel effector
injects the fault that the flight software is never told of (no availability change):

- ``failure``: the motor delivers nothing;
- ``gain_loss``: it delivers ``magnitude`` × the command (remaining torque gain);
- ``friction``: ``magnitude`` N·m of dry friction −f sgn Ω is added to the motor torque;
- ``stuck``: the rotor seizes: a braking torque −J_s Ω / 0.2 s stops it within a second and holds it.

The module runs at the dynamics step (0.1 s) and clips healthy commands at the HR12's 0.2 N·m (the
effector's own limit is lifted so that a seizure can act). Written in the reference satellite's
ground CSV layout (``telemetry/dictionaries/reference_satellite.yaml`` names, ``t_utc`` ISO 8601):
measured and estimated quaternions (Basilisk's perfect ``simpleNav``: both σ_BN), the guidance
quaternion σ_RN, body rates, wheel speeds rounded to 0.25 rpm, the commanded wheel torques; the
epoch is the first sample written (``--start`` crops the flight's beginning). Command line:
``python -m benchmarks.basilisk_faults OUT.csv --fault failure --wheel 2 --onset 2000 [--magnitude M]
[--duration S] [--start S] [--epoch ISO]``.
"""

from __future__ import annotations

import argparse
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from benchmarks import peer_basilisk as peer

TACHOMETER_QUANTUM_RAD_S = 0.25 * np.pi / 30.0
SEIZE_TIME_S = 0.2
HR12_MAX_TORQUE_NM = 0.2
FAULTS = ("none", "failure", "gain_loss", "friction", "stuck")


def _fault_module(kind: str, wheel: int, onset_s: float, magnitude: float, js: float):
    """A Basilisk Python module turning the commanded wheel torques into the delivered (faulted) ones."""
    from Basilisk.architecture import messaging, sysModel

    class HiddenWheelFault(sysModel.SysModel):
        """Delivered torque = fault(command); the flight software never sees it."""

        def __init__(self) -> None:
            super().__init__()
            self.cmdInMsg = messaging.ArrayMotorTorqueMsgReader()
            self.speedInMsg = messaging.RWSpeedMsgReader()
            self.torqueOutMsg = messaging.ArrayMotorTorqueMsg()

        def Reset(self, CurrentSimNanos: int) -> None:
            self.UpdateState(CurrentSimNanos)

        def UpdateState(self, CurrentSimNanos: int) -> None:
            cmd = np.array(self.cmdInMsg().motorTorque[:4]) if self.cmdInMsg.isWritten() else np.zeros(4)
            speed = np.array(self.speedInMsg().wheelSpeeds[:4]) if self.speedInMsg.isWritten() else np.zeros(4)
            out = np.clip(cmd, -HR12_MAX_TORQUE_NM, HR12_MAX_TORQUE_NM)
            if kind != "none" and CurrentSimNanos * 1e-9 >= onset_s:
                if kind == "failure":
                    out[wheel] = 0.0
                elif kind == "gain_loss":
                    out[wheel] = magnitude * out[wheel]
                elif kind == "friction":
                    out[wheel] -= magnitude * np.sign(speed[wheel])
                elif kind == "stuck":
                    out[wheel] = -js * speed[wheel] / SEIZE_TIME_S
            payload = messaging.ArrayMotorTorqueMsgPayload()
            payload.motorTorque = list(out) + [0.0] * (len(payload.motorTorque) - 4)
            self.torqueOutMsg.write(payload, CurrentSimNanos, self.moduleID)

    return HiddenWheelFault()


def fly(kind: str, wheel: int, onset_s: float, magnitude: float, duration_s: float) -> dict[str, np.ndarray]:
    """Basilisk flight of the peer case with one hidden fault (0-based ``wheel``); 1 Hz series."""
    from Basilisk.utilities import macros

    craft = peer.build(
        failed_wheels=None,
        wheel_torque_limit=False,
        command_filter=lambda js: _fault_module(kind, wheel, onset_s, magnitude, js),
    )
    every = macros.sec2nano(1.0)
    logs = {
        "state": craft.nav.attOutMsg.recorder(every),
        "ref": craft.ref.attRefOutMsg.recorder(every),
        "speed": craft.wheels.rwSpeedOutMsg.recorder(every),
        "cmd": craft.mapping.rwMotorTorqueOutMsg.recorder(every),
    }
    for log in logs.values():
        craft.sim.AddModelToTask("fswTask", log)
    craft.sim.InitializeSimulation()
    craft.fly(duration_s)
    return {
        "t_s": logs["state"].times() * 1e-9,
        "sigma_bn": np.array(logs["state"].sigma_BN),
        "omega_b": np.array(logs["state"].omega_BN_B),
        "sigma_rn": np.array(logs["ref"].sigma_RN),
        "speed": np.array(logs["speed"].wheelSpeeds)[:, :4],
        "cmd": np.array(logs["cmd"].motorTorque)[:, :4],
    }


def _q_ib(sigma: np.ndarray) -> np.ndarray:
    """Scalar-first q_ib of Basilisk's σ (the active rotation carrying N axes onto B, body → inertial)."""
    from scipy.spatial.transform import Rotation

    xyzw = Rotation.from_mrp(sigma).as_quat()
    return np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)


def write_csv(path: Path, series: dict[str, np.ndarray], epoch: datetime) -> None:
    """The reference satellite's ground CSV (parameter names of its dictionary), epoch = the first sample."""
    t = series["t_s"]
    q = _q_ib(series["sigma_bn"])
    qp = _q_ib(series["sigma_rn"])
    speed = TACHOMETER_QUANTUM_RAD_S * np.round(series["speed"] / TACHOMETER_QUANTUM_RAD_S)
    cols = (
        ["t_utc"]
        + [f"q_st_ib_{i}" for i in range(4)]
        + [f"q_est_ib_{i}" for i in range(4)]
        + [f"q_prog_ib_{i}" for i in range(4)]
        + [f"omega_est_b_rad_s_{a}" for a in "xyz"]
        + [f"wheel_speed_rad_s_{w}" for w in range(1, 5)]
        + [f"wheel_torque_cmd_nm_{w}" for w in range(1, 5)]
    )
    lines = [",".join(cols)]
    for k in range(t.shape[0]):
        stamp = (epoch + timedelta(seconds=float(t[k] - t[0]))).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
        row = [*q[k], *q[k], *qp[k], *series["omega_b"][k], *speed[k], *series["cmd"][k]]
        lines.append(stamp + "," + ",".join(f"{v:.8g}" for v in row))
    path.write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    """Fly one faulted case in Basilisk and write its ground CSV."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("--fault", choices=FAULTS, default="failure")
    p.add_argument("--wheel", type=int, default=1, help="1-based wheel number")
    p.add_argument("--onset", type=float, default=2000.0, help="s after the first sample")
    p.add_argument("--magnitude", type=float, default=0.0, help="remaining gain (gain_loss) or friction N·m")
    p.add_argument("--duration", type=float, default=peer.DURATION_S)
    p.add_argument("--epoch", default="2026-06-01T00:00:00Z", help="UTC of the first sample written")
    p.add_argument("--start", type=float, default=0.0, help="write samples from this flight time on (s)")
    args = p.parse_args(argv)
    series = fly(args.fault, args.wheel - 1, args.onset, args.magnitude, args.duration)
    keep = series["t_s"] >= args.start
    series = {k: v[keep] for k, v in series.items()}
    epoch = datetime.fromisoformat(args.epoch).astimezone(UTC)
    write_csv(args.out, series, epoch)
    print(f"wrote {args.out}: {series['t_s'].shape[0]} samples, {args.fault} on wheel {args.wheel} at {args.onset} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
