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

from shadeform.errors import InputError


@dataclass(frozen=True)
class AppLimits:
    """How much the server accepts and keeps in memory.

    Attributes
    ----------
    max_upload_bytes : int
        Largest image file accepted (413 beyond).
    max_pixels : int
        Most pixels an image may have (413 beyond), checked before decoding.
    max_images, max_image_bytes : int
        Images kept in memory; the least recently used go first.
    max_results, max_result_bytes : int
        Reconstructions kept for re-meshing (a change of ``step`` only) and exports, and fused
        models: every view of a fusion keeps its own, so that editing one view re-solves only it.
    max_json_bytes : int
        Largest JSON request body (regions with many points still fit).
    """

    max_upload_bytes: int = 64 * 2**20
    max_pixels: int = 4096 * 4096
    max_images: int = 16
    max_image_bytes: int = 1024 * 2**20
    max_results: int = 32
    max_result_bytes: int = 1024 * 2**20
    max_json_bytes: int = 4 * 2**20


def size_text(nbytes: int) -> str:
    return f"{nbytes / 2**20:.3g} MiB" if nbytes >= 2**20 else f"{nbytes / 2**10:.3g} KiB"


def file_too_large(limits: AppLimits) -> str:
    return f"the file is larger than {size_text(limits.max_upload_bytes)}; open a smaller image (crop or downscale it)"


# --- errors ------------------------------------------------------------------------------------


def add_error_handlers(app: FastAPI) -> None:
    async def http_error(request: Request, err: HTTPException) -> Response:
        detail = err.detail if isinstance(err.detail, str) else json.dumps(err.detail)
        if err.status_code == 404 and detail == "Not Found":
            detail = f"nothing at {request.url.path}; open / for the app"
        elif err.status_code == 405:
            detail = f"{request.method} is not allowed on {request.url.path}; see /api/openapi.json"
        return _error(err.status_code, detail, getattr(err, "headers", None))

    async def validation_error(request: Request, err: RequestValidationError) -> Response:
        return _error(422, _validation_message(err.errors()))

    async def input_error(request: Request, err: InputError) -> Response:
        from shadeform.io.images import ImageTooLargeError

        return _error(413 if isinstance(err, ImageTooLargeError) else 422, str(err))

    async def server_error(request: Request, err: Exception) -> Response:
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
    return JSONResponse({"detail": " ".join(str(detail).split())}, status_code=status, headers=headers)


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


class Guard:
    """ASGI middleware run before anything else sees a request.

    - ``Host`` (and ``Origin``, when a browser sends one) must name an allowed host: a page from
      another site, or a DNS name rebound to 127.0.0.1, cannot use the app.
    - Request bodies are read here up to their limit (the upload limit plus form overhead for
      ``/api/images`` and, for all photos together, ``/api/photosets``; the JSON limit elsewhere) and refused with 413 beyond it, before any parser
      runs or anything is spooled to disk.
    """

    _FORM_OVERHEAD = 64 * 1024

    def __init__(self, app, *, allowed_hosts: Iterable[str] | None, limits: AppLimits) -> None:
        self.app = app
        self.allowed = None if allowed_hosts is None else {h.lower().strip("[]") for h in allowed_hosts}
        self.limits = limits

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        headers = {key.decode("latin-1").lower(): value.decode("latin-1") for key, value in scope["headers"]}
        refusal = self._refusal(headers)
        if refusal is not None:
            return await _send_error(send, 403, refusal)
        if scope["method"] not in ("POST", "PUT", "PATCH"):
            return await self.app(scope, receive, send)

        limit = self.limits.max_json_bytes
        if scope["path"] in ("/api/images", "/api/photosets"):
            limit = self.limits.max_upload_bytes + self._FORM_OVERHEAD
        if scope["path"] == "/api/images":
            too_large = file_too_large(self.limits)
        elif scope["path"] == "/api/photosets":
            too_large = (
                f"the photos together are larger than {size_text(self.limits.max_upload_bytes)}; "
                "open fewer or smaller photos"
            )
        else:
            too_large = f"the request body is larger than {size_text(limit)}; send fewer or simpler regions"
        declared = headers.get("content-length", "")
        if declared.isdigit() and int(declared) > limit:
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
        replayed = False

        async def replay():
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: the disconnect, when the client leaves

        return await self.app(scope, replay, send)

    def _refusal(self, headers: dict[str, str]) -> str | None:
        if self.allowed is None:
            return None
        host = _host_name(headers.get("host", ""))
        if host not in self.allowed:
            return (
                f"this server only answers requests addressed to {', '.join(sorted(self.allowed))}; "
                "open it at the address it printed (or start it with --host and --allow-remote)"
            )
        origin = headers.get("origin")
        if origin and origin != "null" and _host_name(origin.split("://", 1)[-1]) not in self.allowed:
            return "requests from other sites' pages are refused; open the app at the address it printed"
        return None


def _host_name(authority: str) -> str:
    """The host of ``host[:port]`` or ``[v6]:port``, lower case, without brackets."""
    authority = authority.strip().lower().split("/", 1)[0]
    if authority.startswith("["):
        return authority[1:].split("]", 1)[0]
    return authority.rsplit(":", 1)[0] if authority.count(":") == 1 else authority


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
