"""Fuzzing the app's HTTP server: no request may end in a 5xx, an exception, a hang, or a 4xx
without its one-line JSON message.

Run with ``python benchmarks/fuzz_server.py --cases 10000`` (a few minutes on two cores; run it
under ``nice``). The server is the app itself (:func:`shadeform.app.server.create_app`, with a
session store and small limits, so that nothing it is sent can make it solve or render anything
large), called in-process through FastAPI's ``TestClient``. Before the cases it is given two
24x24 images and a photo set, whose ids most cases use, so that their requests get past "unknown
id" into the library.

Each case is one request drawn by a seeded random generator: a route of the app's OpenAPI schema
(every operation), a path of no route, or the client's static files; any method (the route's own
most often, then the others, and a few no server knows); path parameters the server holds or
hostile ones (empty, ``..``, encoded NUL, the bytes of a lone surrogate, 5,000 characters, huge
numbers); query strings from the operation's parameters, odd, repeated or of undecodable bytes;
headers (content types right, wrong, malformed and absent; the app's own Origin, another's,
``null``; Host at the server's address, another port, another name; ``Sec-Fetch-Site``;
hundreds of headers); and a body: JSON drawn from the operation's schema with hostile values
mixed in (lone surrogates as escapes and as bytes, characters outside the BMP, NUL, strings up
to 200,000 characters, ``1e999``, ``NaN``, 5,000-digit integers, wrong types, unknown keys,
nesting 100,000 deep, arrays of 50,000 items), then sometimes damaged as bytes (cut, bytes
flipped, invalid UTF-8 put in, re-encoded as UTF-16); multipart forms (photos valid, damaged,
empty or whose header claims 10^10 pixels; light files; hostile file names; broken
boundaries); or random bytes, empty, or over the byte cap.

A request's outcome is its status class, or: ``5xx``; ``exception`` (the client raised: the app
let something escape); ``hang`` (no answer within ``--timeout`` seconds; the app is then made
again); ``no message`` (a 4xx whose body is not exactly ``{"detail": "<one line>"}``; HEAD
answers carry no body and are exempt). Prints a table by operation and the first case of every
distinct failure, and writes it (atomically) to ``benchmarks/results/fuzz_server.md``. The same
case number with the same ``--seed`` is the same request: ``--case N`` sends one case and prints
it and its answer. ``tests/test_app_fuzz.py`` runs a few hundred cases of seed 0.
"""

from __future__ import annotations

import os

if __name__ == "__main__":  # one thread each when run, before numpy loads; never when a test imports it
    for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_name, "1")

import argparse
import concurrent.futures
import io
import json
import logging
import platform
import random
import re
import sys
import tempfile
import time
import warnings
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

import numpy as np

from hostile_files import jpeg_with_damaged_exif, png_claiming

RESULTS = Path(__file__).resolve().parent / "results" / "fuzz_server.md"
HOST = "127.0.0.1:8000"
LOCAL = f"http://{HOST}"
SIDE = 24
#: Outcomes that are failures, in the table's order.
FAILURES = ("5xx", "exception", "hang", "no message")

#: Strings no schema generator sends: lone surrogates (both halves, reversed pairs), characters
#: outside the BMP, NUL and controls, right-to-left marks, and path tricks.
ODD_STRINGS = [
    "\ud800",
    "\udfff",
    "a\udc00b",
    "\ude00\ud83d",
    "\U0001f600",
    "\U0010ffff\U0001f4a9",
    "\x00",
    "a\x00b",
    "\x1b[31m\r\n\t",
    "\u202etxt.exe",
    "../../etc/passwd",
    "%00%ff",
    "",
    " ",
    "é",
    "\ufeff",
    "\uffff",
]


def limits():
    from shadeform.app.guard import AppLimits

    return AppLimits(max_upload_bytes=100_000, max_pixels=96 * 96, max_json_bytes=100_000)


# --------------------------------------------------------------------------------------- files


def png_bytes(array: np.ndarray) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.asarray(array)).save(buffer, format="PNG")
    return buffer.getvalue()


def photos() -> list[bytes]:
    from shadeform import synth

    image = synth.scene("sphere", size=SIDE).image
    return [
        png_bytes(np.rint(np.clip(image * gain, 0, 1) * 255).astype(np.uint8)) for gain in (0.6, 0.8, 1.0)
    ]


LIGHTS = b"0 0 1\n0.5 0 0.866\n0 0.5 0.866\n"


# --------------------------------------------------------------------------------------- the app


@dataclass
class Server:
    """The app under test, its client and the ids it holds."""

    client: object
    known: dict
    folder: tempfile.TemporaryDirectory
    pool: concurrent.futures.ThreadPoolExecutor = field(
        default_factory=lambda: concurrent.futures.ThreadPoolExecutor(1)
    )

    def close(self, *, hung: bool = False) -> None:
        if not hung:
            self.client.__exit__(None, None, None)
        self.pool.shutdown(wait=not hung, cancel_futures=True)
        self.folder.cleanup()


def start_server() -> Server:
    from fastapi.testclient import TestClient

    from shadeform.app.server import create_app

    folder = tempfile.TemporaryDirectory(prefix="fuzz_server-")
    app = create_app(limits=limits(), sessions=Path(folder.name) / "sessions.sqlite3")
    client = TestClient(app, base_url=LOCAL, raise_server_exceptions=False)
    client.__enter__()
    known = {}
    for key, name in (("image", "sphere"), ("other", "bowl")):
        response = client.post(f"/api/examples/synth:{name}?size={SIDE}")
        known[key] = response.json()["image_id"]
    files = [("photos", (f"p{i}.png", data, "image/png")) for i, data in enumerate(photos())]
    response = client.post("/api/photosets", files=[*files, ("lights", ("l.txt", LIGHTS, "text/plain"))])
    known["photoset"] = response.json()["photoset_id"]
    response = client.post("/api/solves", json={"image_id": known["image"], "request_id": 1})
    known["job"] = response.json()["job_id"]
    return Server(client, known, folder)


def operations() -> list[dict]:
    """Every operation of the app's schema: method, path, parameters, body schema and content type."""
    from shadeform.app.server import create_app

    spec = create_app(limits=limits()).openapi()
    found = []
    for path, item in spec["paths"].items():
        for method, operation in item.items():
            content = operation.get("requestBody", {}).get("content", {})
            kind, body = next(iter(content.items()), (None, {}))
            found.append(
                dict(
                    label=f"{method.upper()} {path}",
                    method=method.upper(),
                    path=path,
                    parameters=operation.get("parameters", []),
                    kind=kind,
                    schema=body.get("schema"),
                )
            )
    return found, spec


# --------------------------------------------------------------------------------------- values


class Draw:
    """One case's random values (a ``random.Random`` seeded by the seed and the case number)."""

    def __init__(self, seed: int, case: int, spec: dict, known: dict, files: dict) -> None:
        self.rng = random.Random(f"{seed}:{case}")
        self.spec = spec
        self.known = known
        self.files = files

    def chance(self, p: float) -> bool:
        return self.rng.random() < p

    def odd_string(self) -> str:
        rng = self.rng
        roll = rng.random()
        if roll < 0.6:
            return rng.choice(ODD_STRINGS)
        if roll < 0.7:
            return rng.choice(ODD_STRINGS) * rng.choice([100, 5000, 200_000])
        if roll < 0.85:
            return "".join(chr(rng.randrange(0x110000)) for _ in range(rng.randrange(1, 20)))
        return rng.choice(["x", "sphere", "synth:sphere", "coin", ".obj", ".stl", "gaussian:2", "luma"])

    def number(self):
        return self.rng.choice(
            [
                0,
                -1,
                1,
                2,
                7,
                -(2**63),
                2**64,
                10**30,
                1.5,
                -0.0,
                1e308,
                -1e308,
                5e-324,
                RAW("1e999"),
                RAW("-1e999"),
                RAW("NaN"),
                RAW("Infinity"),
                RAW("-Infinity"),
                RAW("1" * self.rng.choice([20, 400, 4301, 5000])),
                RAW("1." + "0" * 5000 + "1"),
                RAW("-0"),
                RAW("1E+2"),
            ]
        )

    def hostile(self, depth: int = 0):
        rng = self.rng
        roll = rng.random()
        if roll < 0.35:
            return self.odd_string()
        if roll < 0.6:
            return self.number()
        if roll < 0.7:
            return rng.choice([None, True, False, {}, [], [None], {"": None}])
        if roll < 0.78:  # deep
            depth = rng.choice([50, 1000, 100_000])
            return (
                RAW("[" * depth + "]" * depth)
                if self.chance(0.5)
                else RAW('{"a":' * depth + "1" + "}" * depth)
            )
        if roll < 0.85:  # wide
            return [self.number() for _ in range(rng.choice([100, 5000, 50_000]))]
        if roll < 0.9 and depth < 3:
            return {self.odd_string(): self.hostile(depth + 1) for _ in range(rng.randrange(1, 4))}
        return [self.hostile(depth + 1) for _ in range(rng.randrange(0, 4))] if depth < 3 else None

    def resolve(self, schema: dict) -> dict:
        while "$ref" in schema:
            schema = self.spec["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
        return schema

    def value(self, schema: dict | None, name: str = "", depth: int = 0):
        """A value for ``schema``: usually of its type (the server's ids for id fields), now and
        then a hostile one in its place."""
        rng = self.rng
        if name in ("image_id", "photoset_id") and self.chance(0.7):
            return self.known["image" if name == "image_id" else "photoset"]
        if schema is None or depth > 6 or self.chance(0.12):
            return self.hostile()
        schema = self.resolve(schema)
        for key in ("anyOf", "oneOf"):
            if key in schema:
                return self.value(rng.choice(schema[key]), name, depth + 1)
        if "allOf" in schema:
            return self.value(schema["allOf"][0], name, depth + 1)
        if "const" in schema:
            return schema["const"]
        if "enum" in schema:
            return rng.choice(schema["enum"]) if self.chance(0.85) else self.odd_string()
        kind = schema.get("type")
        if kind == "object" or "properties" in schema:
            required = set(schema.get("required", ()))
            out = {}
            for key, sub in schema.get("properties", {}).items():
                if (key in required and self.chance(0.95)) or self.chance(0.5):
                    out[key] = self.value(sub, key, depth + 1)
            if self.chance(0.05):
                out[self.odd_string()] = self.hostile()
            return out
        if kind == "array":
            if "prefixItems" in schema:
                items = [self.value(sub, name, depth + 1) for sub in schema["prefixItems"]]
                return items if self.chance(0.9) else items[: rng.randrange(len(items) + 1)] + [self.number()]
            count = rng.choice([0, 1, 2, 3, 4, rng.randrange(0, 40)])
            return [self.value(schema.get("items"), name, depth + 1) for _ in range(count)]
        if kind == "string":
            if "format" in schema or name in ("mask", "data"):
                import base64

                return base64.b64encode(self.file()).decode() if self.chance(0.6) else self.odd_string()
            return self.odd_string() if self.chance(0.5) else rng.choice(["x", "sphere", "a.png", "gaussian"])
        if kind == "integer":
            minimum = schema.get("minimum", 0)
            return (
                rng.choice([minimum, minimum + 1, rng.randrange(0, 64)])
                if self.chance(0.7)
                else self.number()
            )
        if kind == "number":
            return (
                rng.choice([0.0, 1.0, 30.0, 90.0, rng.uniform(-180, 180)])
                if self.chance(0.7)
                else self.number()
            )
        if kind == "boolean":
            return self.chance(0.5)
        if kind == "null":
            return None
        return self.hostile()

    def file(self) -> bytes:
        rng = self.rng
        kind = rng.choice(["photo", "photo", "damaged", "empty", "bomb", "exif", "lights", "garbage", "text"])
        if kind == "photo":
            return rng.choice(self.files["photos"])
        if kind == "damaged":
            return mutate(self, rng.choice(self.files["photos"]))
        if kind == "empty":
            return b""
        if kind == "bomb":
            return png_claiming(rng.choice([100_000, 97, 2**31 - 1]), rng.choice([100_000, 96, 1]))
        if kind == "exif":
            return self.files["exif"]
        if kind == "lights":
            return rng.choice([LIGHTS, b"nan nan nan\n" * 3, b"1e400 0 1\n" * 3, b"0 0 0\n" * 3, b"1 2\n"])
        if kind == "garbage":
            return rng.randbytes(rng.choice([1, 10, 1000, 50_000]))
        return self.odd_string().encode("utf-8", "surrogatepass")


@dataclass(frozen=True)
class RAW:
    """JSON text written as it is (a number JSON's writer would not write)."""

    text: str


def dump(value, *, ascii: bool = True) -> bytes:
    """``value`` as JSON, :class:`RAW` parts as they are, non-ASCII as escapes (a lone surrogate
    can only be sent so) or as UTF-8 (``surrogatepass``: a lone one's bytes)."""
    raws: list[str] = []

    def default(obj):
        if isinstance(obj, RAW):
            raws.append(obj.text)
            return f"\x00RAW{len(raws) - 1}\x00"
        raise TypeError(type(obj))

    text = json.dumps(value, default=default, ensure_ascii=ascii)
    text = re.sub(r'"\\u0000RAW(\d+)\\u0000"', lambda m: raws[int(m[1])], text)
    return text.encode("utf-8", "surrogatepass")


def mutate(draw: Draw, data: bytes) -> bytes:
    """``data`` damaged as bytes: cut, bytes flipped or put in, doubled, or re-encoded."""
    rng = draw.rng
    if not data:
        return rng.randbytes(rng.randrange(1, 64))
    kind = rng.choice(["cut", "flip", "insert", "double", "utf16"])
    at = rng.randrange(len(data))
    if kind == "cut":
        return data[:at]
    if kind == "flip":
        out = bytearray(data)
        for _ in range(rng.randrange(1, 16)):
            out[rng.randrange(len(out))] ^= 1 << rng.randrange(8)
        return bytes(out)
    if kind == "insert":
        bad = rng.choice([b"\xff", b"\xed\xa0\x80", b"\xc0\x80", b"\x00", b"\xf4\x90\x80\x80", b'"', b"\\u"])
        return data[:at] + bad + data[at:]
    if kind == "double":
        return data + data
    try:
        return data.decode("utf-8", "surrogatepass").encode(
            rng.choice(["utf-16", "utf-16-le", "utf-32"]), "surrogatepass"
        )
    except UnicodeError:
        return data[::-1]


# --------------------------------------------------------------------------------------- requests


METHODS = ["GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"]
CONTENT_TYPES = [
    "application/json",
    "application/json; charset=utf-8",
    "application/json; charset=latin-1",
    "application/vnd.api+json",
    "text/plain",
    "application/x-www-form-urlencoded",
    "multipart/form-data",
    "multipart/form-data; boundary=",
    "image/png",
    "application/octet-stream",
    "*/*",
    ";;;",
    "application/json; boundary=\x7f",
    "x" * 5000,
]
OTHER_PATHS = [
    "/",
    "/index.html",
    "/api",
    "/api/",
    "/api/nope",
    "/api/images",
    "/api/images/",
    "/api/images//photo.png",
    "/assets/../../../../etc/passwd",
    "/%2e%2e/%2e%2e/etc/passwd",
    "/api/openapi.json",
    "/favicon.ico",
    "/" + "a" * 5000,
    "/api/%ED%A0%80",
    "/api/%00",
    "/api/solves/%FF%FE",
]


@dataclass
class Request:
    label: str
    method: str
    url: str
    headers: dict
    content: bytes | None
    kind: str  # what the body is, for the report

    def shown(self) -> str:
        body = (
            ""
            if self.content is None
            else f", body {self.kind} ({len(self.content):,} bytes): {self.content[:120]!r}"
        )
        headers = {k: (v if len(v) <= 80 else v[:77] + "...") for k, v in self.headers.items()}
        url = self.url if len(self.url) <= 160 else self.url[:157] + "..."
        return f"{self.method} {url} headers {headers}{body}"


def path_value(draw: Draw, name: str) -> str:
    known = draw.known
    good = {
        "image_id": known["image"],
        "photoset_id": known["photoset"],
        "job_id": known["job"],
        "project_id": "p1",
        "index": "0",
        "name": draw.rng.choice(["synth:sphere", "coin", "views:lumpy", "diligent:cat"]),
    }
    if name in good and draw.chance(0.6):
        return quote(good[name], safe=":")
    rng = draw.rng
    return rng.choice(
        [
            quote(draw.odd_string()[:3000].encode("utf-8", "surrogatepass"), safe=""),
            "%ED%A0%80",
            "%00",
            "..",
            "%2e%2e",
            "%2F",
            "-1",
            str(10**30),
            "1e3",
            "x" * 5000,
            "%FF%FE",
        ]
    )


def query_string(draw: Draw, parameters: list[dict]) -> str:
    rng = draw.rng
    pairs = []
    for param in parameters:
        if param["in"] != "query":
            continue
        if draw.chance(0.2):
            continue
        schema = draw.resolve(param.get("schema", {}))
        name = param["name"]
        if name == "format" and draw.chance(0.7):
            value = rng.choice([".obj", ".stl", ".glb", ".ply", ".wrl", ".zip", ".png", "obj"])
        elif name == "size" and draw.chance(0.7):
            value = str(rng.choice([16, SIDE, 32]))
        else:
            value = draw.value(schema, name)
            value = (
                value.text
                if isinstance(value, RAW)
                else dump(value).decode("utf-8", "surrogatepass")
                if not isinstance(value, str)
                else value
            )
        text = str(value)[:3000]  # a URL holds at most 64 KiB (httpx's limit)
        pairs.append(f"{quote(name)}={quote(text.encode('utf-8', 'surrogatepass'), safe='')}")
        if draw.chance(0.05):
            pairs.append(pairs[-1])
    if draw.chance(0.1):
        pairs.append(
            rng.choice(["%FF=%FE", "a=%ED%A0%80", "=", "&&&", "x" * 3000 + "=1", "%00=%00", "a[]=1&a[]=2"])
        )
    return "&".join(pairs)


def multipart(draw: Draw, label: str) -> tuple[bytes, str]:
    rng = draw.rng
    boundary = rng.choice(["xyz", "b" * 70, "----fuzz", "é"])
    names = ["file"] if "/api/images" in label else ["photos"] * rng.randrange(0, 6) + ["lights", "mask"]
    if draw.chance(0.2):
        names.append(draw.odd_string()[:100])
    if draw.chance(0.03):
        names = ["f"] * rng.choice([500, 3000])
    body = b""
    for name in names:
        if draw.chance(0.15) and name != "photos":
            continue
        filename = rng.choice(
            ["a.png", "p.jpg", "l.txt", None, draw.odd_string()[:300], "../../x.png", "x" * 2000]
        )
        disposition = f'form-data; name="{name}"'
        if filename is not None:
            disposition += f'; filename="{filename}"'
        data = draw.files["lights"] if name == "lights" and draw.chance(0.6) else draw.file()
        body += (
            f"--{boundary}\r\nContent-Disposition: {disposition}\r\n\r\n".encode("utf-8", "surrogatepass")
            + data
            + b"\r\n"
        )
    body += f"--{boundary}--\r\n".encode()
    content_type = f"multipart/form-data; boundary={boundary}"
    if draw.chance(0.1):
        body = mutate(draw, body)
    if draw.chance(0.05):
        content_type = rng.choice(
            ["multipart/form-data", "multipart/form-data; boundary=other", "multipart/mixed; boundary=xyz"]
        )
    return body, content_type


def make_request(draw: Draw, ops: list[dict]) -> Request:
    rng = draw.rng
    roll = rng.random()
    if roll < 0.9:
        op = rng.choice(ops)
        label = op["label"]
        path = re.sub(r"{(\w+)}", lambda m: path_value(draw, m[1]), op["path"])
        query = query_string(draw, op["parameters"])
        method = op["method"] if draw.chance(0.85) else rng.choice(METHODS + ["FOO", "TRACE", "PROPFIND"])
    else:
        op = None
        path = rng.choice(OTHER_PATHS)
        label = "(other paths)"
        query = rng.choice(["", "a=1", "%FF"])
        method = rng.choice(METHODS)
    url = path + (f"?{query}" if query else "")
    headers: dict[str, str] = {}
    content: bytes | None = None
    kind = "none"
    body_roll = rng.random()
    if op is not None and op["kind"] == "application/json" and body_roll < 0.8:
        content, kind = dump(draw.value(op["schema"]), ascii=draw.chance(0.5)), "json"
        headers["content-type"] = "application/json"
        if draw.chance(0.15):
            content, kind = mutate(draw, content), "json, damaged"
    elif op is not None and op["kind"] == "multipart/form-data" and body_roll < 0.8:
        content, headers["content-type"] = multipart(draw, label)
        kind = "multipart"
    elif body_roll < 0.9:
        choice = rng.random()
        if choice < 0.3:
            content, kind = dump(draw.hostile(), ascii=draw.chance(0.5)), "json, hostile"
        elif choice < 0.5:
            content, kind = rng.randbytes(rng.choice([1, 100, 5000])), "random bytes"
        elif choice < 0.6:
            content, kind = b"", "empty"
        elif choice < 0.7:
            content, kind = b" " * (limits().max_json_bytes + rng.choice([1, 200_000])), "over the cap"
        elif choice < 0.85:
            content, kind = multipart(draw, label)[0], "multipart"
        else:
            content, kind = dump(draw.value(draw.rng.choice(ops)["schema"])), "another route's JSON"
    if draw.chance(0.3):
        headers["content-type"] = rng.choice(CONTENT_TYPES)
    elif draw.chance(0.05):
        headers.pop("content-type", None)
    if draw.chance(0.1):
        headers["origin"] = rng.choice(
            [LOCAL, "http://attacker.example", "null", "http://127.0.0.1:8001", "\x7f"]
        )
    if draw.chance(0.05):
        headers["host"] = rng.choice(
            ["127.0.0.1:8001", "attacker.example", "localhost", "", "[::1]:8000", "a b", "é"]
        )
    if draw.chance(0.05):
        headers["sec-fetch-site"] = rng.choice(["cross-site", "same-site", "same-origin", "none"])
        headers["sec-fetch-mode"] = rng.choice(["cors", "navigate", "no-cors"])
    if draw.chance(0.03):
        headers.update({f"x-fuzz-{i}": "y" * 100 for i in range(rng.choice([10, 300]))})
    if draw.chance(0.05):
        headers[rng.choice(["accept", "accept-encoding", "range", "if-none-match", "cookie"])] = rng.choice(
            ["*/*", "gzip;q=é", "bytes=0-1,-5", "bytes=999999999999-", '"x"', "a=" + "b" * 4000]
        )
    return Request(label, method, url, headers, content, kind)


# --------------------------------------------------------------------------------------- running


def one_line_json(response) -> bool:
    if not response.headers.get("content-type", "").startswith("application/json"):
        return False
    try:
        body = json.loads(response.content)
    except ValueError:
        return False
    return (
        isinstance(body, dict)
        and set(body) == {"detail"}
        and isinstance(body["detail"], str)
        and bool(body["detail"])
        and "\n" not in body["detail"]
        and "Traceback" not in body["detail"]
    )


def send(server: Server, request: Request, timeout: float):
    """(outcome, status or None, what the answer said)."""

    # header values as bytes (a client may send any), UTF-8 where they are text
    headers = {key: value.encode("utf-8", "surrogatepass") for key, value in request.headers.items()}

    def call():
        return server.client.request(request.method, request.url, headers=headers, content=request.content)

    future = server.pool.submit(call)
    try:
        response = future.result(timeout=timeout)
    except concurrent.futures.TimeoutError:
        return "hang", None, f"no answer in {timeout:g} s"
    except Exception as err:  # the app let it escape
        return "exception", None, f"{type(err).__name__}: {str(err)[:200]}"
    status = response.status_code
    text = response.text[:200]
    if status >= 500:
        return "5xx", status, text
    if 400 <= status < 500 and request.method != "HEAD" and not one_line_json(response):
        return "no message", status, text
    return f"{status // 100}xx", status, text


@dataclass
class Failure:
    case: int
    outcome: str
    status: int | None
    said: str
    request: Request


def run(cases: int, seed: int = 0, *, timeout: float = 60.0, first: int = 0, progress: bool = False):
    """Send ``cases`` cases (numbers ``first`` on) of ``seed``; returns (counts by label and
    outcome, failures, seconds)."""
    log = logging.getLogger("shadeform")
    level = log.level
    log.setLevel(logging.CRITICAL)  # refusals the app logs on purpose
    try:
        return _run(cases, seed, timeout=timeout, first=first, progress=progress)
    finally:
        log.setLevel(level)


def _run(cases: int, seed: int, *, timeout: float, first: int, progress: bool):
    ops, spec = operations()
    server = start_server()
    files = {"photos": photos(), "exif": jpeg_with_damaged_exif(SIDE), "lights": LIGHTS}
    counts: dict[str, Counter] = defaultdict(Counter)
    failures: list[Failure] = []
    times: list[tuple[float, int, str]] = []
    start = time.perf_counter()
    for number in range(first, first + cases):
        draw = Draw(seed, number, spec, server.known, files)
        request = make_request(draw, ops)
        lap = time.perf_counter()
        outcome, status, said = send(server, request, timeout)
        times.append((time.perf_counter() - lap, number, request.label))
        counts[request.label][outcome] += 1
        if outcome in FAILURES:
            failures.append(Failure(number, outcome, status, said, request))
        if outcome == "hang":  # its thread may hold the solve lock: a fresh app for the rest
            server.close(hung=True)
            server = start_server()
        if progress and (number - first + 1) % 500 == 0:
            print(
                f"{number - first + 1:,} cases, {len(failures)} failures, {time.perf_counter() - start:.0f} s",
                file=sys.stderr,
            )
    server.close()
    if progress:
        for took, number, label in sorted(times)[-15:]:
            print(f"slowest: case {number} {label} {took:.2f} s", file=sys.stderr)
    return counts, failures, time.perf_counter() - start


def signature(failure: Failure) -> tuple:
    said = re.sub(r"'[^']*'|\d+", "#", failure.said)[:100]
    return failure.request.label, failure.outcome, failure.status, said


def report(counts, failures, seconds: float, args) -> str:
    columns = ["2xx", "3xx", "4xx", *FAILURES]
    total = Counter()
    for outcome_counts in counts.values():
        total.update(outcome_counts)
    lines = [
        "# Fuzzing the app's HTTP server",
        "",
        f"`python benchmarks/fuzz_server.py --cases {args.cases} --seed {args.seed} --timeout {args.timeout:g}`: {sum(total.values()):,} requests "
        f"in {seconds:.0f} s ({platform.machine()}, Python {platform.python_version()}), in-process through "
        f"FastAPI's TestClient, {args.timeout:g} s per request before it counts as a hang.",
        "",
        "**Failures: " + ", ".join(f"{total[name]} {name}" for name in FAILURES) + ".**",
        "",
        "| operation | requests | " + " | ".join(columns) + " |",
        "|---|---:|" + "---:|" * len(columns),
    ]
    for label in sorted(counts):
        row = counts[label]
        lines.append(
            f"| `{label}` | {sum(row.values()):,} | " + " | ".join(f"{row[c]:,}" for c in columns) + " |"
        )
    lines.append(
        f"| **all** | {sum(total.values()):,} | " + " | ".join(f"{total[c]:,}" for c in columns) + " |"
    )
    if failures:
        lines += ["", "## The first case of each distinct failure", ""]
        seen = set()
        for failure in failures:
            key = signature(failure)
            if key in seen:
                continue
            seen.add(key)
            lines.append(
                f"- case {failure.case} ({failure.outcome}, {failure.status}): `{failure.said[:160]}`; "
                f"{failure.request.shown()[:400]!r}"
            )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--timeout", type=float, default=60.0, help="Seconds per request before it is a hang."
    )
    parser.add_argument("--case", type=int, help="Send this one case, print it and its answer.")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    if args.case is not None:
        warnings.simplefilter("ignore")
        ops, spec = operations()
        server = start_server()
        files = {"photos": photos(), "exif": jpeg_with_damaged_exif(SIDE), "lights": LIGHTS}
        request = make_request(Draw(args.seed, args.case, spec, server.known, files), ops)
        print(request.shown())
        print(send(server, request, args.timeout))
        server.close()
        return 0
    counts, failures, seconds = run(args.cases, args.seed, timeout=args.timeout, progress=True)
    text = report(counts, failures, seconds, args)
    print(text)
    from shadeform.io.atomic import atomic_write

    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, mode="w") as handle:
        handle.write(text)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
