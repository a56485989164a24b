"""Sign-in: ``POST /api/auth/login``, ``POST /api/auth/logout``, ``GET /api/auth/me``.

A wrong username and a wrong password get the same 401, after the same (growing) delay; attempts
during the back-off window get 429 with ``Retry-After`` (app/auth.py LoginThrottle).
"""

from __future__ import annotations

import asyncio
import math

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from pydantic import Field
from starlette.concurrency import run_in_threadpool

from app.api.deps import StrictModel
from app.api.problems import problem
from app.api.schemas import ERRORS, Out, Timestamp
from app.auth import SESSION_COOKIE, BadCredentials, Role
from app.security import principal_of

router = APIRouter(tags=["auth"])


class MeOut(Out):
    auth_required: bool
    signed_in: bool
    username: str | None
    role: Role | None
    can_drive: bool
    expires_at: Timestamp | None = Field(description="when the session ends")


class LoginOut(Out):
    username: str
    role: Role
    expires_at: Timestamp


class LogoutOut(Out):
    signed_in: bool


class LoginRequest(StrictModel):
    username: str = Field(min_length=1, max_length=64)
    password: str = Field(min_length=1, max_length=1024)


def _me(request: Request) -> MeOut:
    p = principal_of(request.scope)
    auth = request.app.state.auth
    return MeOut.model_validate(
        {
            "auth_required": auth.require_auth,
            "signed_in": p is not None and p.username is not None,
            "username": None if p is None else p.username,
            "role": None if p is None else p.role.value,
            "can_drive": bool(p and p.can_drive),
            "expires_at": None if p is None else p.expires_at,
        }
    )


@router.get(
    "/api/auth/me",
    response_model=MeOut,
    summary="Who am I: role, whether sign-in is required, session expiry",
)
def me(request: Request) -> MeOut:
    return _me(request)


@router.post(
    "/api/auth/login",
    response_model=LoginOut,
    summary="Sign in; sets an HttpOnly SameSite=Strict session cookie",
    responses=ERRORS(s401="wrong username or password", s429="slow down (`Retry-After`)"),
)
async def login(body: LoginRequest, request: Request) -> JSONResponse:
    auth = request.app.state.auth
    addr = request.client.host if request.client else "unknown"
    keys = [f"ip:{addr}", f"user:{body.username.lower()}"]
    wait = auth.throttle.retry_after(keys)
    if wait > 0:
        return problem(
            429,
            f"too many failed sign-ins; try again in {math.ceil(wait)} s",
            kind="rate-limited",
            headers={"Retry-After": str(math.ceil(wait))},
        )
    try:
        user = await run_in_threadpool(auth.store.authenticate, body.username, body.password)
    except BadCredentials:
        delay = auth.throttle.failed(keys)
        await asyncio.sleep(delay)  # the answer itself is slowed down, never the event loop
        return problem(401, "wrong username or password", kind="bad-credentials")
    auth.throttle.succeeded(keys)
    token, expires = await run_in_threadpool(auth.store.create_session, user)
    max_age = max(1, int(auth.store.session_ttl_s))
    out = LoginOut(username=user.username, role=Role(user.role), expires_at=expires)
    resp = JSONResponse(out.model_dump(mode="json"), status_code=200)
    resp.set_cookie(
        SESSION_COOKIE,
        token,
        max_age=max_age,
        path="/",
        httponly=True,
        samesite="strict",
        secure=auth.secure_cookies,
    )
    return resp


@router.post(
    "/api/auth/logout",
    response_model=LogoutOut,
    summary="Sign out (ends the session everywhere it is used)",
)
async def logout(request: Request) -> JSONResponse:
    auth = request.app.state.auth
    token = request.cookies.get(SESSION_COOKIE)
    if token:
        await run_in_threadpool(auth.store.end_session, token)
        auth.forget(token)
    resp = JSONResponse(LogoutOut(signed_in=False).model_dump())
    resp.delete_cookie(SESSION_COOKIE, path="/", httponly=True, samesite="strict")
    return resp
