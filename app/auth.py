"""Sign-in: users with scrypt password hashes, cookie sessions stored hashed, and a login throttle.

Why these choices:
- scrypt (RFC 7914) is memory-hard and in the standard library (``hashlib.scrypt``); parameters are
  stored with each hash so they can be raised later without breaking old passwords. Comparison is
  constant-time (``hmac.compare_digest``).
- The session cookie holds a random 256-bit token; the database keeps only its SHA-256, so a leaked
  database does not hand out live sessions (the OWASP Session Management cheat sheet's advice).
- Repeated failures are slowed down per client address and per username with an exponential delay
  (OWASP Authentication cheat sheet: "exponential back-off"), and the 401 never says which part of the
  credentials was wrong.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import threading
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from enum import StrEnum

from sqlalchemy.engine import Engine
from sqlmodel import Session, delete, select

from app.models import User, UserSession

SESSION_COOKIE = "navdeck_session"
CLIENT_COOKIE = "navdeck_client"
USERNAME_MAX = 64
PASSWORD_MIN = 8


class Role(StrEnum):
    OPERATOR = "operator"  # drives, changes modes, edits maps
    VIEWER = "viewer"  # watches; may always press the e-stop


class AuthError(Exception):
    """Base class of sign-in failures."""


class BadCredentials(AuthError):
    """Unknown user or wrong password (deliberately the same error for both)."""


class UserExists(AuthError):
    pass


class InvalidUser(AuthError):
    """A username, password or role that cannot be stored."""


@dataclass(frozen=True)
class ScryptOptions:
    """scrypt cost parameters (RFC 7914 §2). n=2**14, r=8, p=1 is the interactive-login setting
    recommended there and in Python's docs: ~16 MB and ~50 ms per hash."""

    n: int = 2**14  # CPU/memory cost, a power of two
    r: int = 8  # block size
    p: int = 1  # parallelism
    salt_bytes: int = 16
    dklen: int = 32


def hash_password(password: str, options: ScryptOptions = ScryptOptions()) -> str:
    """``scrypt$n$r$p$salt$hash`` (hex) for ``password`` with a fresh random salt."""
    salt = secrets.token_bytes(options.salt_bytes)
    dk = hashlib.scrypt(
        password.encode(),
        salt=salt,
        n=options.n,
        r=options.r,
        p=options.p,
        dklen=options.dklen,
        maxmem=64 * 1024 * 1024,
    )
    return f"scrypt${options.n}${options.r}${options.p}${salt.hex()}${dk.hex()}"


def verify_password(password: str, stored: str) -> bool:
    """Constant-time check of ``password`` against a ``hash_password`` string."""
    try:
        algo, n, r, p, salt_hex, dk_hex = stored.split("$")
        if algo != "scrypt":
            return False
        want = bytes.fromhex(dk_hex)
        got = hashlib.scrypt(
            password.encode(),
            salt=bytes.fromhex(salt_hex),
            n=int(n),
            r=int(r),
            p=int(p),
            dklen=len(want),
            maxmem=64 * 1024 * 1024,
        )
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got, want)


_dummy_hash: str | None = None


def _dummy() -> str:
    """A hash of a random password, checked for unknown users so both failures take the same time."""
    global _dummy_hash
    if _dummy_hash is None:
        _dummy_hash = hash_password(secrets.token_hex(16))
    return _dummy_hash


def token_digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def _utc(dt: datetime) -> datetime:
    """SQLite returns naive datetimes; every stored time is UTC."""
    return dt if dt.tzinfo is not None else dt.replace(tzinfo=UTC)


@dataclass(frozen=True)
class Principal:
    """Who is behind a request or websocket.

    ``client_id`` names the browser (cookie) and is what holds the control lease; ``username`` is None
    when sign-in is not required (bound to localhost: every local client is an operator)."""

    client_id: str
    role: Role
    username: str | None = None
    token_hash: str | None = None
    expires_at: float | None = None  # epoch seconds

    @property
    def display(self) -> str:
        """A name others may see: the username, else a short digest (never the client's cookie)."""
        return self.username or "guest-" + hashlib.sha256(self.client_id.encode()).hexdigest()[:6]

    @property
    def can_drive(self) -> bool:
        return self.role == Role.OPERATOR

    def expired(self, now: float | None = None) -> bool:
        return self.expires_at is not None and (time.time() if now is None else now) >= self.expires_at


class UserStore:
    """Users and sessions in the database (tables ``users`` and ``user_sessions``, migration 0003)."""

    def __init__(self, engine: Engine, session_ttl_s: float = 12 * 3600.0) -> None:
        self.engine = engine
        self.session_ttl_s = session_ttl_s

    def add_user(self, username: str, password: str, role: str = Role.VIEWER) -> User:
        username = username.strip()
        if not username or len(username) > USERNAME_MAX or not username.isprintable() or " " in username:
            raise InvalidUser(f"username must be 1-{USERNAME_MAX} printable characters without spaces")
        if len(password) < PASSWORD_MIN:
            raise InvalidUser(f"password must have at least {PASSWORD_MIN} characters")
        try:
            role = Role(role)
        except ValueError:
            raise InvalidUser(f"role must be one of: {', '.join(r.value for r in Role)}") from None
        with Session(self.engine, expire_on_commit=False) as db:
            if db.exec(select(User).where(User.username == username)).first() is not None:
                raise UserExists(f"user {username!r} already exists")
            user = User(username=username, password_hash=hash_password(password), role=role.value)
            db.add(user)
            db.commit()
            db.refresh(user)
            return user

    def set_password(self, username: str, password: str) -> None:
        if len(password) < PASSWORD_MIN:
            raise InvalidUser(f"password must have at least {PASSWORD_MIN} characters")
        with Session(self.engine) as db:
            user = db.exec(select(User).where(User.username == username)).first()
            if user is None:
                raise InvalidUser(f"no user {username!r}")
            user.password_hash = hash_password(password)
            db.add(user)
            db.exec(delete(UserSession).where(UserSession.user_id == user.id))  # sign out everywhere
            db.commit()

    def list_users(self) -> list[User]:
        with Session(self.engine, expire_on_commit=False) as db:
            return list(db.exec(select(User).order_by(User.username)))

    def remove_user(self, username: str) -> bool:
        with Session(self.engine) as db:
            user = db.exec(select(User).where(User.username == username)).first()
            if user is None:
                return False
            db.exec(delete(UserSession).where(UserSession.user_id == user.id))
            db.delete(user)
            db.commit()
            return True

    def authenticate(self, username: str, password: str) -> User:
        """The user if the password matches; ``BadCredentials`` otherwise (same for an unknown user)."""
        with Session(self.engine, expire_on_commit=False) as db:
            user = db.exec(select(User).where(User.username == username)).first()
        ok = verify_password(password, user.password_hash if user else _dummy())
        if user is None or not ok:
            raise BadCredentials("wrong username or password")
        return user

    def create_session(self, user: User) -> tuple[str, datetime]:
        """A new random token (to put in the cookie) and its expiry; only its hash is stored."""
        token = secrets.token_urlsafe(32)
        expires = datetime.now(UTC) + timedelta(seconds=self.session_ttl_s)
        with Session(self.engine) as db:
            db.add(UserSession(token_hash=token_digest(token), user_id=user.id, expires_at=expires))
            db.exec(delete(UserSession).where(UserSession.expires_at < datetime.now(UTC)))  # tidy up
            db.commit()
        return token, expires

    def lookup(self, token: str) -> tuple[User, float] | None:
        """(user, expiry epoch) for a live session token; None if unknown or expired."""
        if not token or len(token) > 200:
            return None
        with Session(self.engine, expire_on_commit=False) as db:
            row = db.exec(
                select(UserSession, User)
                .join(User, User.id == UserSession.user_id)
                .where(UserSession.token_hash == token_digest(token))
            ).first()
        if row is None:
            return None
        sess, user = row
        expires = _utc(sess.expires_at).timestamp()
        if expires <= time.time():
            return None
        return user, expires

    def still_valid(self, token_hash: str) -> bool:
        """Whether a session (by its stored hash) exists and has not expired (websocket re-checks)."""
        with Session(self.engine) as db:
            sess = db.exec(select(UserSession).where(UserSession.token_hash == token_hash)).first()
        return sess is not None and _utc(sess.expires_at).timestamp() > time.time()

    def end_session(self, token: str) -> None:
        with Session(self.engine) as db:
            db.exec(delete(UserSession).where(UserSession.token_hash == token_digest(token)))
            db.commit()


@dataclass(frozen=True)
class ThrottleOptions:
    """Exponential back-off after failed sign-ins: the k-th consecutive failure of a key is answered
    after ``base_delay_s * 2**(k-1)`` s (capped), and attempts arriving before that are refused (429)."""

    base_delay_s: float = 0.5
    max_delay_s: float = 30.0
    forget_after_s: float = 900.0  # failures older than this no longer count


@dataclass
class _Failures:
    count: int = 0
    last: float = 0.0
    locked_until: float = 0.0


@dataclass
class LoginThrottle:
    """Failure counts per key (``ip:<addr>`` and ``user:<name>``); thread-safe."""

    options: ThrottleOptions = field(default_factory=ThrottleOptions)
    _keys: dict[str, _Failures] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def retry_after(self, keys: list[str], now: float | None = None) -> float:
        """Seconds to wait before any of ``keys`` may try again (0 if allowed now)."""
        now = time.monotonic() if now is None else now
        with self._lock:
            return max(
                (max(0.0, f.locked_until - now) for k in keys if (f := self._keys.get(k))), default=0.0
            )

    def failed(self, keys: list[str], now: float | None = None) -> float:
        """Record a failure; returns the delay to apply to this answer (the largest over ``keys``)."""
        now = time.monotonic() if now is None else now
        o = self.options
        delay = 0.0
        with self._lock:
            for k in keys:
                f = self._keys.setdefault(k, _Failures())
                if now - f.last > o.forget_after_s:
                    f.count = 0
                f.count += 1
                f.last = now
                d = min(o.max_delay_s, o.base_delay_s * 2.0 ** (f.count - 1))
                f.locked_until = now + d
                delay = max(delay, d)
            if len(self._keys) > 10_000:  # bounded memory under a spray of usernames
                for k in sorted(self._keys, key=lambda k: self._keys[k].last)[:5000]:
                    del self._keys[k]
        return delay

    def succeeded(self, keys: list[str]) -> None:
        with self._lock:
            for k in keys:
                self._keys.pop(k, None)
