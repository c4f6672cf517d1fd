"""Who the API key belongs to (the page shows who is signed in)."""

from __future__ import annotations

from fastapi import APIRouter, Request

from app.api.deps import SessionDep, TenantDep
from app.api.routing import ApiRoute
from app.db import repo
from app.db.models import Tenant
from app.schemas import Me

router = APIRouter(tags=["me"], route_class=ApiRoute)


@router.get("/me", response_model=Me)
def who_am_i(request: Request, session: SessionDep, tenant_id: TenantDep) -> Me:
    """The tenant and the name of the key the request was made with."""
    # TenantDep has checked the header: "Bearer <key>"
    key = request.headers["authorization"].split(None, 1)[1].strip()
    tenant = session.get(Tenant, tenant_id)
    row = repo.api_key_for_hash(session, repo.hash_key(key))
    return Me(
        tenant_id=tenant_id,
        tenant_name=tenant.name if tenant is not None else "",
        key_name=row.name if row is not None else "",
    )
