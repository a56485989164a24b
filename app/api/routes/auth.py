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
from app.auth import SESSION_COOKIE, BadCredentials
from app.security import principal_of

router = APIRouter(tags=["auth"])


class LoginRequest(StrictModel):
    username: str = Field(min_length=1, max_length=64)
    password: str = Field(min_length=1, max_length=1024)


def _me(request: Request) -> dict:
    p = principal_of(request.scope)
    auth = request.app.state.auth
    return {
        "auth_required": auth.require_auth,
        "signed_in": p is not None and p.username is not None,
        "username": None if p is None else p.username,
        "role": None if p is None else p.role.value,
        "can_drive": bool(p and p.can_drive),
        "expires_at": None if p is None else p.expires_at,
    }


@router.get("/api/auth/me", summary="Who am I: role, whether sign-in is required, session expiry")
def me(request: Request) -> dict:
    return _me(request)


@router.post(
    "/api/auth/login",
    summary="Sign in; sets an HttpOnly SameSite=Strict session cookie",
    responses={401: {"description": "wrong username or password"}, 429: {"description": "slow down"}},
)
async def login(body: LoginRequest, request: Request) -> JSONResponse:
    auth = request.app.state.auth
    addr = request.client.host if request.client else "unknown"
    keys = [f"ip:{addr}", f"user:{body.username.lower()}"]
    wait = auth.throttle.retry_after(keys)
    if wait > 0:
        return JSONResponse(
            {"detail": f"too many failed sign-ins; try again in {math.ceil(wait)} s"},
            status_code=429,
            headers={"Retry-After": str(math.ceil(wait))},
        )
    try:
        user = await run_in_threadpool(auth.store.authenticate, body.username, body.password)
    except BadCredentials:
        delay = auth.throttle.failed(keys)
        await asyncio.sleep(delay)  # the answer itself is slowed down, never the event loop
        return JSONResponse({"detail": "wrong username or password"}, status_code=401)
    auth.throttle.succeeded(keys)
    token, expires = await run_in_threadpool(auth.store.create_session, user)
    max_age = max(1, int(auth.store.session_ttl_s))
    resp = JSONResponse(
        {"username": user.username, "role": user.role, "expires_at": expires.timestamp()}, status_code=200
    )
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


@router.post("/api/auth/logout", summary="Sign out (ends the session everywhere it is used)")
async def logout(request: Request) -> JSONResponse:
    auth = request.app.state.auth
    token = request.cookies.get(SESSION_COOKIE)
    if token:
        await run_in_threadpool(auth.store.end_session, token)
        auth.forget(token)
    resp = JSONResponse({"signed_in": False})
    resp.delete_cookie(SESSION_COOKIE, path="/", httponly=True, samesite="strict")
    return resp
