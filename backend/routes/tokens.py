"""Token management (admin) and the audit log."""

from __future__ import annotations

from fastapi import APIRouter, Query

from backend.core.auth import Role
from backend.core.errors import ERROR_RESPONSES, ApiError
from backend.deps import AdminDep, ServicesDep
from backend.schemas import AuditPublic, DbId, TokenCreate, TokenIssued, TokenPublic

router = APIRouter(tags=["tokens"], responses=ERROR_RESPONSES)


@router.get("/tokens", response_model=list[TokenPublic], summary="List API tokens")
def list_tokens(services: ServicesDep, _: AdminDep) -> list[TokenPublic]:
    """Every token with its role and state (never the token or its hash)."""
    return [TokenPublic.model_validate(row) for row in services.tokens.list()]


@router.post("/tokens", response_model=TokenIssued, status_code=201, summary="Issue an API token")
def create_token(body: TokenCreate, services: ServicesDep, principal: AdminDep) -> TokenIssued:
    """Create a token; the plain token is in this answer only."""
    token_id, token = services.auth.issue(body.name, Role.parse(body.role))
    services.audit.record(principal.name, "token.create", f"token/{token_id}", {"name": body.name, "role": body.role})
    row = next(r for r in services.tokens.list() if r.id == token_id)
    return TokenIssued(**TokenPublic.model_validate(row).model_dump(), token=token)


@router.delete("/tokens/{token_id}", response_model=TokenPublic, summary="Revoke an API token")
def revoke_token(token_id: DbId, services: ServicesDep, principal: AdminDep) -> TokenPublic:
    """Revoke at once (cached lookups are forgotten)."""
    row = services.tokens.revoke(token_id)
    if row is None:
        raise ApiError(404, f"no token with id {token_id}", "token_id")
    services.auth.forget(token_id)
    services.audit.record(principal.name, "token.revoke", f"token/{token_id}", {"name": row.name})
    return TokenPublic.model_validate(row)


@router.get("/audit", response_model=list[AuditPublic], summary="Audit log")
def list_audit(
    services: ServicesDep,
    _: AdminDep,
    limit: int = Query(100, ge=1, le=1000),
    action: str | None = Query(None, max_length=50, examples=["simulation.create"]),
) -> list[AuditPublic]:
    """Uploads, simulations, acknowledgements and token changes, newest first."""
    return [AuditPublic.model_validate(row) for row in services.audit.list(limit, action)]
