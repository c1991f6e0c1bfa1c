"""What stands before the app's routes: its limits, the guard middleware (hosts, origins, body
sizes) and the error handlers that turn every failure into one JSON line with a 4xx or 500."""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from starlette.exceptions import HTTPException

from shadeform.app.schema import ErrorBody
from shadeform.errors import InputError
from shadeform.io.images import MAX_PIXELS

#: Every operation's error responses in the OpenAPI schema: any 4xx is one JSON line
#: (:class:`~shadeform.app.schema.ErrorBody`); FastAPI's list-shaped 422 is never sent.
ERROR_RESPONSES: dict[int | str, dict] = {
    "4XX": {
        "model": ErrorBody,
        "description": "What was wrong with the request and what to do, in one line.",
    }
}


@dataclass(frozen=True)
class AppLimits:
    """How much the server accepts and keeps in memory.

    Attributes
    ----------
    max_upload_bytes : int
        Largest image file accepted (413 beyond).
    max_pixels : int
        Most pixels an image may have (413 beyond), checked before decoding: the loader's one
        limit (:data:`shadeform.io.images.MAX_PIXELS`) unless the server is started with another.
    max_images, max_image_bytes : int
        Images kept in memory; the least recently used go first.
    max_results, max_result_bytes : int
        Reconstructions kept for re-meshing (a change of ``step`` only) and exports, and fused
        models: every view of a fusion keeps its own, so that editing one view re-solves only it.
    max_json_bytes : int
        Largest JSON request body (regions with many points still fit).
    max_stored_bytes : int
        Most bytes of uploaded files the session store keeps on disk (with ``sessions=``).
    """

    max_upload_bytes: int = 64 * 2**20
    max_pixels: int = MAX_PIXELS
    max_images: int = 16
    max_image_bytes: int = 1024 * 2**20
    max_results: int = 32
    max_result_bytes: int = 1024 * 2**20
    max_json_bytes: int = 4 * 2**20
    max_stored_bytes: int = 2 * 2**30


def size_text(nbytes: int) -> str:
    return f"{nbytes / 2**20:.3g} MiB" if nbytes >= 2**20 else f"{nbytes / 2**10:.3g} KiB"


def file_too_large(limits: AppLimits) -> str:
    return f"the file is larger than {size_text(limits.max_upload_bytes)}; open a smaller image (crop or downscale it)"


def shorten(name: str) -> str:
    """A name the user sent, cut to 40 characters for a one-line message."""
    return name if len(name) <= 40 else name[:37] + "..."


def check_known(name: str, choices, what: str) -> None:
    """A 404 unless ``name`` is one of ``choices`` (an example's name, say), naming them all."""
    if name not in choices:
        raise HTTPException(404, f"unknown {what} {shorten(name)!r}; choose one of: {', '.join(choices)}")


# --- errors ------------------------------------------------------------------------------------


def add_error_handlers(app: FastAPI) -> None:
    async def http_error(request: Request, err: HTTPException) -> Response:
        detail = err.detail if isinstance(err.detail, str) else json.dumps(err.detail)
        if err.status_code == 404 and detail == "Not Found":
            detail = f"nothing at {request.url.path}; open / for the app"
        elif err.status_code == 400 and detail == "There was an error parsing the body":
            detail = _unreadable_body(err.__cause__)
        elif err.status_code == 405:
            detail = f"{request.method} is not allowed on {request.url.path}; see /api/openapi.json"
        return _error(err.status_code, detail, getattr(err, "headers", None))

    async def validation_error(request: Request, err: RequestValidationError) -> Response:
        return _error(422, _validation_message(err.errors()))

    async def input_error(request: Request, err: InputError) -> Response:
        from shadeform.io.images import ImageTooLargeError

        return _error(413 if isinstance(err, ImageTooLargeError) else 422, str(err))

    async def server_error(request: Request, err: Exception) -> Response:
        # a bug, not the user's mistake: Starlette raises it on after this answer, so the server
        # (uvicorn) logs the traceback; the client gets one line without it
        return _error(
            500,
            f"internal error ({type(err).__name__}) in shadeform; please report it with "
            "the steps that led here",
        )

    app.add_exception_handler(HTTPException, http_error)
    app.add_exception_handler(RequestValidationError, validation_error)
    app.add_exception_handler(InputError, input_error)
    app.add_exception_handler(Exception, server_error)


def _error(status: int, detail: str, headers: dict | None = None) -> Response:
    # a detail quoting a client's text: anything UTF-8 cannot hold is escaped, never a failure here
    text = " ".join(str(detail).split()).encode("utf-8", "backslashreplace").decode("utf-8")
    return JSONResponse({"detail": text}, status_code=status, headers=headers)


def _unreadable_body(cause: BaseException | None) -> str:
    """What was wrong with a body FastAPI could not parse (its own message names no cause)."""
    if isinstance(cause, UnicodeDecodeError):
        return "the request body is not UTF-8 text; send JSON encoded as UTF-8"
    if isinstance(cause, RecursionError):
        return "the request body is nested too deeply; send the JSON objects the API describes"
    reason = " ".join(str(cause).split())[:80] if cause is not None else ""
    return (
        f"the request body could not be read{f' ({reason})' if reason else ''}; send a JSON object, "
        "or the multipart form the API describes for uploads"
    )


def _validation_message(errors: Sequence[dict]) -> str:
    """pydantic's error list as one line: the first problem, where it is, and how many more."""
    first = errors[0]
    kind = first.get("type", "")
    where = ".".join(str(part) for part in first.get("loc", ()) if part not in ("body", "query", "path"))
    if kind == "json_invalid":
        reason = first.get("ctx", {}).get("error", "")
        message = f"the request body is not valid JSON ({reason}); send a JSON object"
    elif kind == "missing":
        if where == "file":
            message = "no file in the upload; send the image as the multipart form field 'file'"
        else:
            message = f"{where or 'body'}: missing; it is required"
    elif kind in ("too_short", "too_long"):
        ctx = first.get("ctx", {})
        bound = (
            f"at least {ctx.get('min_length')}" if kind == "too_short" else f"at most {ctx.get('max_length')}"
        )
        message = f"{where or 'body'}: give {bound}, got {ctx.get('actual_length')}"
    elif "Expected UploadFile" in str(first.get("msg", "")):
        message = f"{where}: not a file; send it as a file in the multipart form (a part with a filename)"
    elif kind == "extra_forbidden":
        message = f"{where}: unknown field; remove it (see /api/openapi.json for the fields)"
    else:
        text = first.get("msg", "invalid value")
        text = re.sub(r"^Input should be", "must be", text)
        text = re.sub(r"^Value error, ", "", text)
        message = f"{where or 'body'}: {text}"
    more = len(errors) - 1
    return message + (f" (and {more} more problem{'s' * (more > 1)})" if more else "")


# --- the guard: hosts, origins, body sizes -----------------------------------------------------

#: Methods that change nothing: another site's page may still navigate the browser to them.
_SAFE_METHODS = ("GET", "HEAD")

#: Ports an origin or a ``Host`` header leaves out.
_DEFAULT_PORTS = {"http": 80, "https": 443}

_OPEN_IT_HERE = "open the app at the address it printed"


class Guard:
    """ASGI middleware run before anything else sees a request.

    - ``Host`` must name an allowed host at the port the server is bound to (or an allowed
      forwarder's ``host:port``): a DNS name rebound to 127.0.0.1 cannot reach the app.
    - A JSON body with a lone UTF-16 surrogate is refused (:func:`lone_surrogate`).
    - ``Origin``, when a browser sends one, must be exactly the app's own origin: the scheme,
      host and port the request was addressed to. Another site's page, a page on another port
      of this machine, and a sandboxed page or local file (``Origin: null``) are refused; so is
      a request the browser marks ``Sec-Fetch-Site: cross-site`` or ``same-site``, unless it is
      a plain navigation (a link followed to the app). The app's own client, served from the
      same origin, passes; so does the Vite dev server (``npm run dev``), whose proxy forwards
      the page's ``Host`` with its ``Origin``.
    - Request bodies are read here up to their limit (the upload limit plus form overhead for
      ``/api/images`` and, for all photos together, ``/api/photosets``; the JSON limit
      elsewhere) and refused with 413 beyond it, before any parser runs or anything is spooled
      to disk: a ``Content-Length`` over the limit before a byte is read, a body streamed
      without one as soon as it passes the limit.
    """

    _FORM_OVERHEAD = 64 * 1024

    def __init__(self, app, *, allowed_hosts: Iterable[str] | None, limits: AppLimits) -> None:
        self.app = app
        self.limits = limits
        self.allowed: set[str] | None = None  # host names, at the port the server is bound to
        self.forwarders: set[tuple[str, int]] = set()  # host and port exactly
        if allowed_hosts is not None:
            self.allowed = set()
            for entry in allowed_hosts:
                bare_v6 = entry.count(":") > 1 and not entry.startswith("[")
                authority = _authority(f"[{entry}]" if bare_v6 else entry)
                if authority is None:
                    raise ValueError(f"not a host or host:port: {entry!r}")
                host, port = authority
                if port is None:
                    self.allowed.add(host)
                else:
                    self.forwarders.add((host, port))

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        headers: dict[str, list[str]] = {}
        for key, value in scope["headers"]:
            headers.setdefault(key.decode("latin-1").lower(), []).append(value.decode("latin-1"))
        if len(headers.get("host", ())) > 1:
            return await _send_error(send, 400, "the request has more than one Host header; send one")
        refusal = self._refusal(scope, headers)
        if refusal is not None:
            return await _send_error(send, 403, refusal)

        # every method: a body on a GET is read (and capped) like any other
        limit, too_large = self._body_limit(scope["path"])
        declared = headers.get("content-length", [""])[-1].strip()
        if re.fullmatch(r"[0-9]+", declared) and int(declared) > limit:
            return await _send_error(send, 413, too_large)
        chunks, total = [], 0
        while True:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            chunk = message.get("body", b"")
            total += len(chunk)
            if total > limit:
                return await _send_error(send, 413, too_large)
            chunks.append(chunk)
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        content_type = headers.get("content-type", [""])[0].strip().lower()
        if not content_type.startswith("multipart/") and lone_surrogate(body):
            return await _send_error(send, 400, _LONE_SURROGATE)
        replayed = False

        async def replay():
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: the disconnect, when the client leaves

        return await self.app(scope, replay, send)

    def _body_limit(self, path: str) -> tuple[int, str]:
        """The most bytes a request body to ``path`` may have, and the refusal beyond it."""
        if path == "/api/images":
            return self.limits.max_upload_bytes + self._FORM_OVERHEAD, file_too_large(self.limits)
        if path == "/api/photosets":
            return self.limits.max_upload_bytes + self._FORM_OVERHEAD, (
                f"the photos together are larger than {size_text(self.limits.max_upload_bytes)}; "
                "open fewer or smaller photos"
            )
        limit = self.limits.max_json_bytes
        return limit, f"the request body is larger than {size_text(limit)}; send fewer or simpler regions"

    def _refusal(self, scope, headers: dict[str, list[str]]) -> str | None:
        """Why a request must be refused (one line for the user), or None to serve it."""
        host_header = headers.get("host", [""])[0]
        own = _authority(host_header)
        if self.allowed is not None and not self._addressed_here(scope, own):
            shown = host_header if len(host_header) <= 60 else host_header[:57] + "..."
            return (
                f"this server only answers requests addressed to {self._addresses(scope)} (this one was "
                f"addressed to {shown!r}); open it at the address it printed (or start it with --host "
                "and --allow-remote)"
            )
        origins = headers.get("origin", [])
        if origins:
            origin = origins[0].strip()
            if origin.lower() == "null":
                return (
                    "requests from sandboxed pages and local files (Origin: null) are refused; "
                    + _OPEN_IT_HERE
                )
            scheme = scope.get("scheme", "http")
            if len(origins) > 1 or own is None or _origin(origin) != _with_port(scheme, *own):
                shown = origin if len(origin) <= 60 else origin[:57] + "..."
                return (
                    f"requests from other sites' pages are refused (this one came from {shown!r}, "
                    f"not from the app at {scheme}://{host_header}); {_OPEN_IT_HERE}"
                )
        site = headers.get("sec-fetch-site", [""])[0].strip().lower()
        if site in ("cross-site", "same-site"):
            mode = headers.get("sec-fetch-mode", [""])[0].strip().lower()
            if scope["method"] not in _SAFE_METHODS or mode != "navigate":
                return f"requests from other sites' pages are refused (the browser marked this one {site}); {_OPEN_IT_HERE}"
        return None

    def _addressed_here(self, scope, own: tuple[str, int | None] | None) -> bool:
        """Whether ``Host`` (as :func:`_authority` reads it) names this server: an allowed host
        name at the port the server is bound to (the scheme's default port where ``Host`` gives
        none), or a forwarder's exact ``host:port`` given in ``allowed_hosts``.

        The name is what stops DNS rebinding (a page of ``attacker.example`` whose name was
        rebound to 127.0.0.1 sends that name). The port makes ``Host`` the address the browser
        really used: ``localhost:9000`` reaching the app on 8000 went through something that
        forwarded it, whose origin (and whatever else that origin serves) the browser would take
        for the app's own; a forwarder the user runs is named in ``allowed_hosts``.
        """
        if own is None:
            return False
        host, port = own
        port = _DEFAULT_PORTS.get(scope.get("scheme", "http"), 0) if port is None else port
        if (host, port) in self.forwarders:
            return True
        bound = _bound_port(scope)
        return host in (self.allowed or ()) and (bound is None or port == bound)

    def _addresses(self, scope) -> str:
        """The addresses :meth:`_addressed_here` accepts, for the refusal."""
        bound = _bound_port(scope)

        def shown(host: str, port: int | None) -> str:
            name = f"[{host}]" if ":" in host else host
            return name if port is None else f"{name}:{port}"

        names = [shown(host, bound) for host in sorted(self.allowed or ())]
        return ", ".join(names + [shown(*pair) for pair in sorted(self.forwarders)])


def _bound_port(scope) -> int | None:
    """The port the server listens on (the ASGI scope's ``server``); None when it does not say
    (a Unix socket)."""
    server = scope.get("server")
    return server[1] if server and isinstance(server[1], int) else None


#: Where a JSON body may hold a UTF-16 surrogate: an escape of one (half of a character outside
#: the BMP), its three bytes as UTF-8 would write them (Python's parser decodes bytes with
#: ``surrogatepass``), or a body in UTF-16 or UTF-32 (zero bytes in its first four).
_MAY_HAVE_SURROGATE = re.compile(rb"\\u[dD][89a-fA-F][0-9a-fA-F]{2}|\xed[\xa0-\xbf]|\A[^\x00]{0,3}\x00")
_SURROGATE = re.compile("[\ud800-\udfff]")

_LONE_SURROGATE = (
    "the request body has a string with a lone UTF-16 surrogate (an escape such as \\ud800 without "
    "its pair), which is not a character; send the text as UTF-8"
)


def lone_surrogate(body: bytes) -> bool:
    """Whether a JSON ``body`` has a string holding a lone UTF-16 surrogate.

    JSON may write any character as ``\\uXXXX`` escapes, a character outside the BMP as a
    pair of surrogates (``\\ud83d\\ude00``); Python's parser turns a lone one (``\\ud800``)
    into a ``str`` that is not Unicode text: UTF-8 cannot encode it, so it would fail wherever
    the text goes next (the session store, a file name, a JSON answer). Refusing such a body
    before any route parses it keeps every string the routes see encodable. A body that is not
    JSON is the route's to refuse (False here); one that cannot hold a surrogate (no escape of
    one, no bytes of one, not UTF-16 or UTF-32) is not parsed here.
    """
    if not _MAY_HAVE_SURROGATE.search(body):
        return False
    try:
        text = json.dumps(json.loads(body), ensure_ascii=False)
    except (ValueError, RecursionError):
        return False
    return _SURROGATE.search(text) is not None


def _authority(text: str) -> tuple[str, int | None] | None:
    """``host[:port]`` or ``[v6]:port`` as (host in lower case without brackets, port or None);
    None when it is not an authority (a path, user info, a port that is not a number)."""
    text = text.strip().lower()
    if not text or any(ch in text for ch in "/?#@\\ "):
        return None
    if text.startswith("["):
        host, bracket, rest = text[1:].partition("]")
        if not bracket:
            return None
    elif text.count(":") > 1:  # a bare IPv6 address
        host, rest = text, ""
    else:
        host, colon, port = text.partition(":")
        rest = colon + port
    if rest in ("", ":"):  # RFC 3986 allows an empty port: the default one
        return host, None
    if not re.fullmatch(r":[0-9]{1,5}", rest):
        return None
    return host, int(rest[1:])


def _origin(text: str) -> tuple[str, str, int] | None:
    """An ``Origin`` header as (scheme, host, port), the default port filled in; None if it is
    not a web origin."""
    scheme, sep, rest = text.strip().lower().partition("://")
    if not sep or scheme not in _DEFAULT_PORTS:
        return None
    authority = _authority(rest)
    return None if authority is None else _with_port(scheme, *authority)


def _with_port(scheme: str, host: str, port: int | None) -> tuple[str, str, int]:
    return scheme, host, _DEFAULT_PORTS.get(scheme, 0) if port is None else port


async def _send_error(send: Callable, status: int, detail: str) -> None:
    body = json.dumps({"detail": detail}).encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())],
        }
    )
    await send({"type": "http.response.body", "body": body})
