"""Typed FastAPI dependencies: the services container and role checks."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.concurrency import run_in_threadpool

from backend.core.auth import Principal, Role
from backend.core.errors import ApiError
from backend.services import Services

__all__ = ["get_services", "require", "ServicesDep", "ViewerDep", "OperatorDep", "AdminDep"]

_bearer = HTTPBearer(auto_error=False, description="API token: `Authorization: Bearer acs_…`")


async def get_services(request: Request) -> Services:
    """The services container built by create_app."""
    return request.app.state.services


ServicesDep = Annotated[Services, Depends(get_services)]


def require(role: Role) -> Callable[..., Awaitable[Principal]]:
    """Dependency: the caller's principal, 401 without a valid token, 403 below ``role``."""

    async def check(
        services: ServicesDep, credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
    ) -> Principal:
        token = credentials.credentials if credentials else None
        principal = services.auth.cached(token)
        if principal is None and token:
            principal = await run_in_threadpool(services.auth.resolve, token)
        if principal is None:
            raise ApiError(
                401,
                "missing or unknown API token: send 'Authorization: Bearer <token>'",
                "Authorization",
                headers={"WWW-Authenticate": "Bearer"},
            )
        if principal.role < role:
            raise ApiError(403, f"role {principal.role.name} may not do this: needs {role.name}", "Authorization")
        return principal

    return check


ViewerDep = Annotated[Principal, Depends(require(Role.viewer))]
OperatorDep = Annotated[Principal, Depends(require(Role.operator))]
AdminDep = Annotated[Principal, Depends(require(Role.admin))]
