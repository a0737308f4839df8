"""The 3D monitors' simulated side: fly a diagnosed hypothesis on it, see what it flies, back to the nominal twin."""

from __future__ import annotations

from fastapi import APIRouter
from starlette.concurrency import run_in_threadpool

from backend.core.errors import ERROR_RESPONSES
from backend.deps import OperatorDep, ServicesDep, ViewerDep
from backend.schemas import FlightCreate, FlightPublic, SimulatedMonitorPublic
from backend.twin.diagnosis_flight import fly_hypothesis, land_flight

router = APIRouter(tags=["monitors"], responses=ERROR_RESPONSES)


@router.post(
    "/monitors/simulated/flight",
    response_model=FlightPublic,
    summary="Fly a diagnosed hypothesis on the simulated monitor",
)
async def create_flight(body: FlightCreate, services: ServicesDep, principal: OperatorDep) -> FlightPublic:
    """Fly hypothesis ``rank`` of a succeeded diagnosis from before its onset (the diagnosis' replay), against the
    telemetry of the window: the simulated monitor shows it, named on its panel; answered once flown."""
    flight = await run_in_threadpool(fly_hypothesis, services, body.diagnosis_id, body.rank, principal.name)
    details = {"rank": body.rank, "label": flight["label"]}
    await run_in_threadpool(
        services.audit.record, principal.name, "monitors.fly", f"diagnoses/{body.diagnosis_id}", details
    )
    return FlightPublic(**flight)


@router.get("/monitors/simulated", response_model=SimulatedMonitorPublic, summary="What the simulated monitor flies")
def get_simulated(services: ServicesDep, _: ViewerDep) -> SimulatedMonitorPublic:
    """The nominal twin or the flown hypothesis, its label, and the label each connected viewer's panel shows."""
    return SimulatedMonitorPublic(**services.monitors.state())


@router.delete("/monitors/simulated/flight", response_model=SimulatedMonitorPublic, summary="Back to the nominal twin")
async def delete_flight(services: ServicesDep, principal: OperatorDep) -> SimulatedMonitorPublic:
    """The live twin back on the monitors, in live follow."""
    state = await run_in_threadpool(land_flight, services)
    await run_in_threadpool(services.audit.record, principal.name, "monitors.nominal", "monitors/simulated", {})
    return SimulatedMonitorPublic(**state)
