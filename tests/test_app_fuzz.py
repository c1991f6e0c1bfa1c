"""Hostile requests against the app's HTTP API: no request a client can send may end in a 5xx.

Two halves. Schemathesis fuzzes every operation of the app's own OpenAPI schema in-process
(its ASGI transport), with data that fits the schema and data that does not, a bounded and
seeded number of cases per operation; half of the cases name images and photo sets the server
really holds (and valid solver names), so that they reach the library instead of stopping at
"unknown id". Each response must not be a 5xx, and must conform to the schema: a documented
status, content type and body (every 4xx is ``{"detail": "<one line>"}``). Then hand-written
hostile requests: malformed bodies, wrong content types, huge and non-finite numbers, unknown
ids, forms with missing or wrong parts, bodies over the byte cap, and images whose header claims
more pixels than the cap, which must be refused before any pixel is decoded.
"""

from __future__ import annotations

import asyncio
import base64
import collections
import importlib.util
import io
import json
import re
import struct
import sys
import zlib
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from hypothesis.errors import Unsatisfiable
from PIL import Image
from schemathesis import GenerationMode
from schemathesis.checks import (
    content_type_conformance,
    not_a_server_error,
    response_schema_conformance,
    status_code_conformance,
)

from shadeform import synth
from shadeform.app.guard import Guard
from shadeform.app.server import AppLimits, create_app
from shadeform.integration import available_integrators
from shadeform.photometric import MODELS as STEREO_MODELS
from shadeform.solvers import available_solvers

HOST = "127.0.0.1:8000"
LOCAL = f"http://{HOST}"
SIDE = 24  # the stored images' side: every solve the fuzz reaches takes milliseconds
#: Small limits, so that the fuzz cannot make the server render or solve anything large.
LIMITS = AppLimits(max_upload_bytes=100_000, max_pixels=96 * 96, max_json_bytes=100_000)
#: Cases per operation and generation mode (positive, negative): about 1,000 requests in all.
EXAMPLES = 30
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance]
FUZZ_SETTINGS = settings(
    max_examples=EXAMPLES,
    derandomize=True,  # seeded: the same cases on every run
    database=None,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    phases=[Phase.explicit, Phase.generate, Phase.shrink],
)

#: Requests sent by the fuzz, per operation and status (reported at the end of the module).
SENT: collections.Counter = collections.Counter()


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    # with a session store, as `shadeform app` runs: ids and names reach SQLite, which takes only
    # text UTF-8 can hold
    return create_app(limits=LIMITS, sessions=tmp_path_factory.mktemp("fuzz") / "sessions.sqlite3")


@pytest.fixture(scope="module")
def client(app):
    # 5xx as responses, not exceptions: the hand-written tests check the status themselves
    with TestClient(app, base_url=LOCAL, raise_server_exceptions=False) as test_client:
        yield test_client


def png_bytes(array) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(array)).save(buffer, format="PNG")
    return buffer.getvalue()


def sphere_photo(gain=1.0) -> bytes:
    image = synth.scene("sphere", size=SIDE).image
    return png_bytes(np.rint(np.clip(image * gain, 0, 1) * 255).astype(np.uint8))


def png_claiming(width: int, height: int) -> bytes:
    """A PNG of a few dozen bytes whose IHDR declares ``width`` x ``height`` RGB pixels."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(b"\0" * 16))
        + chunk(b"IEND", b"")
    )


PHOTOS = [("photos", (f"p{i}.png", sphere_photo(0.6 + 0.2 * i), "image/png")) for i in range(4)]
LIGHTS = ("lights", ("lights.txt", b"0 0 1\n0.5 0 0.866\n0 0.5 0.866\n-0.5 0 0.866\n", "text/plain"))


@pytest.fixture(scope="module")
def known(client):
    """Ids the server holds: two images (a sphere and a bowl) and a photo set, all SIDE x SIDE."""
    ids = {}
    for key, name in (("image", "sphere"), ("other", "bowl")):
        response = client.post(f"/api/examples/synth:{name}?size={SIDE}")
        assert response.status_code == 201, response.text
        ids[key] = response.json()["image_id"]
    response = client.post("/api/photosets", files=[*PHOTOS, LIGHTS])
    assert response.status_code == 201, response.text
    ids["photoset"] = response.json()["photoset_id"]
    return ids


def assert_one_line(response, *statuses: int) -> str:
    """A 4xx (one of ``statuses``) whose body is exactly ``{"detail": "<one line>"}``."""
    assert response.status_code in statuses, (response.status_code, response.text)
    assert response.headers["content-type"].startswith("application/json")
    body = response.json()
    assert set(body) == {"detail"} and isinstance(body["detail"], str), body
    detail = body["detail"]
    assert detail and "\n" not in detail and "Traceback" not in detail and 'File "' not in detail
    return detail


# ------------------------------------------------------------------ fuzz from the OpenAPI schema


def _labels() -> list[str]:
    """Every operation of the app's schema, as schemathesis names them ("POST /api/...")."""
    paths = create_app(limits=LIMITS).openapi()["paths"]
    return [f"{method.upper()} {path}" for path, item in paths.items() for method in item]


@pytest.fixture(scope="module")
def api_schema(app):
    # loaded through schemathesis's own client, whose server is at port 80
    return schemathesis.openapi.from_asgi("/api/openapi.json", app, headers={"host": "127.0.0.1"})


@pytest.fixture(scope="module", autouse=True)
def report():
    yield
    if SENT:
        operations = len({label for label, _ in SENT})
        statuses = collections.Counter()
        for (_, status), count in SENT.items():
            statuses[status] += count
        print(f"\nfuzz: {operations} operations, {sum(SENT.values())} requests, by status {dict(statuses)}")


def _aim(case, data, known) -> None:
    """Point a generated case at what the server holds (ids, a shipped example, valid solver
    names), so that the rest of its data reaches the library."""
    path = case.path_parameters or {}
    if "image_id" in path:
        path["image_id"] = known["image"]
    if "photoset_id" in path:
        path["photoset_id"] = known["photoset"]
    if case.operation.path == "/api/examples/{name}":
        path["name"] = data.draw(st.sampled_from(["synth:sphere", "synth:bowl", "coin"]))
    body = case.body
    if not isinstance(body, dict):
        return
    if "image_id" in body:
        body["image_id"] = known["image"]
    if "photoset_id" in body:
        body["photoset_id"] = known["photoset"]
    views = body.get("views")
    if isinstance(views, list):
        for i, view in enumerate(views):
            if isinstance(view, dict):
                view["image_id"] = known["image"] if i % 2 == 0 else known["other"]
                _aim_params(view.get("params"), data, stereo=False)
    _aim_params(body.get("params"), data, stereo="photoset_id" in body)


def _aim_params(params, data, *, stereo: bool) -> None:
    if not isinstance(params, dict):
        return
    if stereo:
        methods, integrators = list(STEREO_MODELS), list(available_integrators())
    else:
        methods, integrators = ["auto", *available_solvers()], [None, *available_integrators()]
    chosen = "model" if stereo else "solver"
    if chosen in params:
        params[chosen] = data.draw(st.sampled_from(methods))
    if "integrator" in params:
        params["integrator"] = data.draw(st.sampled_from(integrators))


@pytest.mark.parametrize("mode", [GenerationMode.POSITIVE, GenerationMode.NEGATIVE], ids=str)
@pytest.mark.parametrize("label", _labels())
def test_fuzz(api_schema, known, label, mode):
    operation = api_schema.find_operation_by_label(label)
    assert operation is not None, label

    @FUZZ_SETTINGS
    @given(case=operation.as_strategy(generation_mode=mode), aim=st.booleans(), data=st.data())
    def run(case, aim, data):
        if aim:
            _aim(case, data, known)
        response = case.call(base_url=LOCAL)
        SENT[label, response.status_code] += 1
        case.validate_response(response, checks=CHECKS)

    try:
        run()
    except Unsatisfiable:
        # nothing in the operation can be made invalid (no parameters, or only free strings)
        assert mode == GenerationMode.NEGATIVE, label


def test_every_operation_fuzzed():
    paths = create_app(limits=LIMITS).openapi()["paths"]
    assert len(_labels()) == sum(len(item) for item in paths.values()) >= 18


# ------------------------------------------------------------------ every string field, any code point

#: What no schema generator sends (hypothesis leaves surrogates out of its text): lone UTF-16
#: surrogates, characters outside the BMP, NUL and a string over every length limit.
ODD_STRINGS = {
    "high surrogate": "\ud800",
    "low surrogate": "a\udfffb",
    "reversed pair": "\ude00\ud83d",
    "outside the BMP": "\U0001f600 \U0010ffff",
    "NUL": "a\x00b",
    "long": "\U0001f600" * 40_000,
}


def _resolve(spec: dict, schema: dict) -> dict:
    while "$ref" in schema:
        schema = spec["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
    return schema


def string_fields(spec: dict, schema: dict, path: tuple = (), depth: int = 0):
    """The paths (keys and list indices) of every string a JSON body of ``schema`` may hold, each
    once: those under alternatives, lists (their first item) and nested objects included."""
    schema = _resolve(spec, schema)
    if depth > 8:
        return
    for key in ("anyOf", "oneOf", "allOf"):
        for sub in schema.get(key, []):
            yield from string_fields(spec, sub, path, depth + 1)
    if schema.get("type") == "string":
        yield path
    for name, sub in schema.get("properties", {}).items():
        yield from string_fields(spec, sub, (*path, name), depth + 1)
    for i, sub in enumerate(schema.get("prefixItems", [])):
        yield from string_fields(spec, sub, (*path, i), depth + 1)
    if isinstance(schema.get("items"), dict):
        yield from string_fields(spec, schema["items"], (*path, 0), depth + 1)


def with_value(node, path: tuple, value):
    """``node`` (a JSON value) with ``value`` at ``path``, the objects and lists on the way made."""
    if not path:
        return value
    part, rest = path[0], path[1:]
    if isinstance(part, int):
        items = list(node) if isinstance(node, list) else []
        items += [{}] * (part + 1 - len(items))
        items[part] = with_value(items[part], rest, value)
        return items
    fields = dict(node) if isinstance(node, dict) else {}
    fields[part] = with_value(fields.get(part), rest, value)
    return fields


def _odd_cases():
    """(operation, where, string name) for every string field and parameter of the schema."""
    spec = create_app(limits=LIMITS).openapi()
    for path, item in spec["paths"].items():
        for method, operation in item.items():
            label = f"{method.upper()} {path}"
            body = operation.get("requestBody", {}).get("content", {}).get("application/json")
            fields = set(string_fields(spec, body["schema"])) if body else set()
            places = [("body", field) for field in sorted(fields, key=str)]
            places += [(param["in"], param["name"]) for param in operation.get("parameters", [])]
            for place in places:
                for name in ODD_STRINGS:
                    yield pytest.param(label, place, name, id=f"{label} {place} {name}")


def _base_body(label: str, known) -> dict:
    """A body that reaches the library (ids the server holds) before the odd string is put in."""
    if label.startswith("PUT /api/projects"):
        return {"format": "shadeform-project", "version": 1, "image": {"name": "a.png"}, "params": {}}
    if "/fuse" in label:
        views = [{"image_id": known["image"], "angle": 0}, {"image_id": known["other"], "angle": 90}]
        return {"views": views, "resolution": 2}
    if "/stereo" in label:
        return {"photoset_id": known["photoset"]}
    if "/mask/" in label:
        return {}
    return {"image_id": known["image"], "params": {"step": 4}}


@pytest.mark.parametrize(("label", "place", "name"), list(_odd_cases()))
def test_odd_strings_everywhere(client, known, label, place, name):
    """Every string field of every JSON body, and every path and query parameter, given each odd
    string: sent as JSON escapes (a lone surrogate can only be sent so) and as UTF-8 (its
    surrogatepass bytes for a lone one, which are not UTF-8). Never a 5xx; a 4xx is one line; a
    lone surrogate is refused, wherever it is."""
    method, route = label.split(" ", 1)
    value = ODD_STRINGS[name]
    lone = any(0xD800 <= ord(ch) <= 0xDFFF for ch in value)
    # in a URL the long one is cut to what a URL may hold (httpx sends at most 64 KiB)
    raw = quote(value[:2000].encode("utf-8", "surrogatepass"), safe="")
    params = {"image_id": known["image"], "photoset_id": known["photoset"], "index": "0"}
    params.update(name="synth:sphere", job_id="nope", project_id="p1")
    where, field = place
    url = route
    for key in re.findall(r"{(\w+)}", route):
        url = url.replace(f"{{{key}}}", raw if (where, field) == ("path", key) else params[key])
    query = [f"{field}={raw}"] if where == "query" else []
    if "/export" in route and field != "format":
        query.append("format=.obj")
    url += "?" + "&".join(query) if query else ""
    if where != "body":
        response = client.request(method, url, json=_base_body(label, known) if "json" in method else None)
        assert_one_line(response, *range(400, 500)) if response.status_code >= 400 else None
        assert response.status_code < 500, response.text
        return
    body = with_value(_base_body(label, known), field, value)
    for encoded in (
        json.dumps(body).encode(),
        json.dumps(body, ensure_ascii=False).encode("utf-8", "surrogatepass"),
    ):
        response = client.request(method, url, content=encoded, headers={"content-type": "application/json"})
        assert response.status_code < 500, (field, response.text)
        if lone or response.status_code >= 400:
            assert_one_line(response, *range(400, 500))


# ------------------------------------------------------------------ hand-written hostile requests


def post_raw(client, url: str, body: bytes | str, content_type: str | None = "application/json", **headers):
    if content_type is not None:
        headers["content-type"] = content_type
    return client.post(url, content=body, headers=headers)


BAD_BODIES = [
    pytest.param(b"{", "application/json", 422, "not valid JSON", id="malformed"),
    pytest.param(b"", "application/json", 422, "missing", id="empty"),
    pytest.param(b"[]", "application/json", 422, "object", id="a list"),
    pytest.param(b"null", "application/json", 422, "object", id="null"),
    pytest.param(b"NaN", "application/json", 422, "object", id="NaN"),
    pytest.param(b'{"image_id": "\xff\xfe"}', "application/json", 400, "UTF-8", id="not UTF-8"),
    pytest.param(b"[" * 100_000 + b"]" * 100_000, "application/json", (400, 413), "", id="deep"),
    pytest.param(
        b'{"a":' * 10_000 + b"1" + b"}" * 10_000, "application/json", 400, "nested", id="deep object"
    ),
    pytest.param(b"image_id=x", "application/x-www-form-urlencoded", 422, "object", id="form"),
    pytest.param(b'{"image_id": "x"}', "text/plain", 422, "object", id="text/plain"),
    pytest.param(b"--x\r\n", "multipart/form-data; boundary=x", 422, "object", id="multipart"),
    pytest.param(b'{"image_id": "x"}', None, 422, "object", id="no content type"),
]


@pytest.mark.parametrize(("body", "content_type", "status", "fragment"), BAD_BODIES)
@pytest.mark.parametrize("url", ["/api/reconstruct", "/api/stereo", "/api/fuse", "/api/export?format=.obj"])
def test_bad_bodies(client, url, body, content_type, status, fragment):
    statuses = status if isinstance(status, tuple) else (status,)
    detail = assert_one_line(post_raw(client, url, body, content_type), *statuses)
    assert fragment.lower() in detail.lower()


def reconstruct(client, known, params=None, **fields):
    body = {"image_id": known["image"], "params": params or {}, **fields}
    # allow_nan: NaN and Infinity as Python's json writes them, which FastAPI's parser accepts
    return post_raw(client, "/api/reconstruct", json.dumps(body, allow_nan=True))


NAN, INF = float("nan"), float("inf")


@pytest.mark.parametrize(
    ("params", "fragment"),
    [
        ({"filter": {"kind": "gaussian", "size": 1e9}}, "larger than the image"),
        ({"filter": {"kind": "median", "size": 1e9}}, "larger than the image"),
        ({"filter": {"kind": "mean", "size": 1e300}}, "larger than the image"),
        ({"filter": {"kind": "minimum", "size": 1e18}}, "larger than the image"),
        ({"filter": {"kind": "gaussian", "size": NAN}}, "filter.size"),
        ({"filter": {"kind": "gaussian", "size": INF}}, "finite"),
        ({"filter": {"kind": "median", "size": -1}}, "filter.size"),
        ({"light": {"mode": "slant_tilt", "slant": NAN}}, "finite"),
        ({"light": {"mode": "slant_tilt", "slant": INF}}, "finite"),
        ({"light": {"mode": "slant_tilt", "slant": 1e308}}, "slant"),
        ({"light": {"mode": "slant_tilt", "tilt": -INF}}, "finite"),
        ({"step": 10**30}, "step"),
        ({"step": -1}, "step"),
        ({"step": 0}, "step"),
        ({"refine": 10**9}, "refine"),
        ({"references": [[10**30, 5]]}, "references"),
        ({"references": [[-(2**63), 5]]}, "references"),
        ({"references": [[-1, -1]]}, "not on the object"),
        ({"concave": {"regions": [{"polygon": [[NAN, 1], [2, 3], [4, 5]], "axis": "x"}]}}, "non-finite"),
        ({"concave": {"regions": [{"polygon": [[1, 1], [2, 3]], "axis": "x"}]}}, "at least 3 points"),
        ({"concave": {"regions": [{"polygon": [[1e300, 1], [2, -1e300], [4, 5]], "axis": "q"}]}}, "axis"),
        ({"solver": "nope"}, "unknown solver"),
        ({"integrator": ""}, "unknown integrator"),
        ({"channel": "alpha"}, "channel"),
        ({"mask": "@@@"}, "base64"),
        ({"mask": ""}, "empty"),
        ({"mask": "é"}, "base64"),
        ({"extra": 1}, "unknown field"),
    ],
    ids=repr,
)
def test_bad_parameters(client, known, params, fragment):
    detail = assert_one_line(reconstruct(client, known, params), 422)
    assert fragment.lower() in detail.lower()


def test_huge_numbers_elsewhere(client, known):
    response = reconstruct(client, known, request_id=10**40)
    assert response.status_code == 200 and response.json()["request_id"] == 10**40
    assert_one_line(reconstruct(client, known, request_id=1.5), 422)
    assert_one_line(client.post(f"/api/examples/synth:sphere?size={10**30}"), 413)
    assert_one_line(client.post("/api/examples/synth:sphere?size=-5"), 422)
    assert_one_line(client.post("/api/examples/synth:sphere?size=1e3"), 422)
    image = known["image"]
    for spec in ("gaussian:1e9", "median:1000000", "minimum:1e18", "mean:inf", "median:nan", "gaussian:-1"):
        assert_one_line(client.get(f"/api/images/{image}/channel.png?filter={spec}"), 422)
    seeds = f"/api/images/{image}/mask/seeds"
    for click in ([10**30, 1], [2**63, 1], [1, -(2**70)]):
        assert "inside" in assert_one_line(client.post(seeds, json={"inside": [click]}), 422)
    auto = f"/api/images/{image}/mask/auto"
    for value in (NAN, INF, -INF):
        body = json.dumps({"threshold": value}, allow_nan=True)
        assert "finite" in assert_one_line(post_raw(client, auto, body), 422)
    ps = known["photoset"]
    for index in ("-1", str(10**30)):
        assert_one_line(client.get(f"/api/photosets/{ps}/photos/{index}.png"), 404)
    for sphere in ([NAN, 1, 1], [-5, -5, -3], [1e300, 1e300, 1e300]):
        body = json.dumps(
            {"photoset_id": ps, "params": {"lights": "sphere", "sphere": sphere}}, allow_nan=True
        )
        assert_one_line(post_raw(client, "/api/stereo", body), 422)
    views = [{"image_id": known["image"], "angle": 0}, {"image_id": known["other"], "angle": NAN}]
    assert "finite" in assert_one_line(post_raw(client, "/api/fuse", json.dumps({"views": views})), 422)
    views[1]["angle"] = 1e300  # a finite angle is an angle, however many turns
    assert client.post("/api/fuse", json={"views": views, "resolution": 2}).status_code == 200


def test_unknown_ids(client, known):
    unknown = "feedfacefeedface"
    assert "unknown image id" in assert_one_line(reconstruct(client, {"image": unknown}), 404)
    assert "unknown image id" in assert_one_line(client.get(f"/api/images/{unknown}/photo.png"), 404)
    assert "unknown image id" in assert_one_line(client.get(f"/api/images/{'x' * 5000}/channel.png"), 404)
    assert "unknown image id" in assert_one_line(client.post("/api/images/%00/mask/auto", json={}), 404)
    assert "unknown photo set" in assert_one_line(
        client.post("/api/stereo", json={"photoset_id": unknown}), 404
    )
    # one kind's id is not the other's
    assert_one_line(client.post("/api/stereo", json={"photoset_id": known["image"]}), 404)
    assert_one_line(reconstruct(client, {"image": known["photoset"]}), 404)
    views = [{"image_id": known["image"], "angle": 0}, {"image_id": unknown, "angle": 90}]
    assert "view 2" in assert_one_line(client.post("/api/fuse", json={"views": views}), 404)
    for name in ("/api/examples/nope", "/api/photosets/examples/nope", "/api/viewsets/examples/nope"):
        assert "unknown" in assert_one_line(client.post(name), 404)


def multipart(*parts: tuple[str, str | None, bytes], boundary: str = "xyz") -> tuple[bytes, str]:
    """A multipart body written by hand: (field name, file name or None for a text field, data)."""
    body = b""
    for name, filename, data in parts:
        disposition = f'form-data; name="{name}"' + (f'; filename="{filename}"' if filename else "")
        body += f"--{boundary}\r\nContent-Disposition: {disposition}\r\n\r\n".encode() + data + b"\r\n"
    return body + f"--{boundary}--\r\n".encode(), f"multipart/form-data; boundary={boundary}"


def test_bad_uploads(client):
    def upload(body, content_type):
        return post_raw(client, "/api/images", body, content_type)

    assert "no file" in assert_one_line(upload(*multipart()), 422)
    assert "no file" in assert_one_line(upload(*multipart(("other", "a.png", sphere_photo()))), 422)
    assert "not a file" in assert_one_line(upload(*multipart(("file", None, sphere_photo()))), 422)
    assert "empty" in assert_one_line(upload(*multipart(("file", "a.png", b""))), 400)
    assert_one_line(upload(*multipart(("file", "a.png", b"not an image at all"))), 415)
    assert_one_line(upload(*multipart(("file", "a.png", sphere_photo()[:60]))), 415)
    assert "boundary" in assert_one_line(upload(b"abc", "multipart/form-data"), 400)
    assert_one_line(
        upload(b"--xyz\r\nContent-Disposition: form-data; name=", "multipart/form-data; boundary=xyz"),
        400,
        422,
    )
    assert "no file" in assert_one_line(upload(b'{"file": "x"}', "application/json"), 422)
    assert "not a file" in assert_one_line(upload(b"file=abc", "application/x-www-form-urlencoded"), 422)
    fields = [(f"f{i}", None, b"a") for i in range(1500)]
    assert_one_line(upload(*multipart(*fields)), 400)


def test_bad_photo_sets(client):
    def post_set(*parts):
        return post_raw(client, "/api/photosets", *multipart(*parts))

    photos = [("photos", name, data) for _, (name, data, _) in PHOTOS]
    assert "3 to" in assert_one_line(post_set(*photos[:2]), 422)
    assert "not a file" in assert_one_line(post_set(("photos", None, b"abc")), 422)
    assert "photos" in assert_one_line(post_set(("lights", "l.txt", b"0 0 1\n")), 422)
    assert "empty" in assert_one_line(post_set(*photos[:3], ("photos", "e.png", b"")), 400)
    small = ("photos", "small.png", png_bytes(np.zeros((20, 21), np.uint8)))
    assert "give photos from one still camera" in assert_one_line(post_set(*photos[:3], small), 422)
    assert "not text" in assert_one_line(post_set(*photos, ("lights", "l.txt", b"\xff\xfe\x00")), 422)
    for lights in (b"nan nan nan\n" * 4, b"0 0 0\n" * 4, b"1 2\n", b"1e400 0 1\n" * 4):
        response = post_set(*photos, ("lights", "l.txt", lights))
        if response.status_code == 201:  # read as given: a solve with them must say what is wrong
            photoset_id = response.json()["photoset_id"]
            response = client.post("/api/stereo", json={"photoset_id": photoset_id})
        assert_one_line(response, 422)
    for mask, status in ((b"xxxx", 422), (b"", 422), (png_bytes(np.zeros((SIDE, SIDE), np.uint8)), 422)):
        assert "mask" in assert_one_line(post_set(*photos, ("mask", "m.png", mask)), status)


# ------------------------------------------------------------------ byte and pixel caps


def test_body_over_the_cap_by_content_length(client, known):
    # refused from the header: the guard answers before it reads a byte of the body
    too_many = LIMITS.max_json_bytes + 1
    detail = assert_one_line(reconstruct_sized(client, known, too_many), 413)
    assert "larger than" in detail
    # twice the upload limit: over it, whatever the guard allows the form's framing on top
    upload_cap = 2 * LIMITS.max_upload_bytes
    body, content_type = multipart(("file", "big.png", b"\0" * upload_cap))
    assert "larger than" in assert_one_line(post_raw(client, "/api/images", body, content_type), 413)
    body, content_type = multipart(*[("photos", f"{i}.png", b"\0" * (upload_cap // 3)) for i in range(4)])
    assert "photos together" in assert_one_line(post_raw(client, "/api/photosets", body, content_type), 413)


def reconstruct_sized(client, known, size: int):
    padding = " " * (size - len(json.dumps({"image_id": known["image"]})))
    return post_raw(client, "/api/reconstruct", json.dumps({"image_id": known["image"]}) + padding)


def test_body_over_the_cap_streamed_is_not_read_to_its_end():
    """A body without Content-Length is read only until it passes the cap."""
    received = []
    chunk = b"x" * 10_000

    async def receive():
        received.append(len(chunk))
        return {"type": "http.request", "body": chunk, "more_body": True}  # never ends

    sent = []

    async def send(message):
        sent.append(message)

    async def never_called(scope, receive, send):
        raise AssertionError("the app was reached")

    guard = Guard(never_called, allowed_hosts=["127.0.0.1"], limits=LIMITS)
    scope = {
        "type": "http",
        "method": "POST",
        "path": "/api/reconstruct",
        "scheme": "http",
        "headers": [(b"host", HOST.encode()), (b"content-type", b"application/json")],
    }
    asyncio.run(guard(scope, receive, send))
    assert sent[0]["status"] == 413
    assert sum(received) <= LIMITS.max_json_bytes + len(chunk)


def test_content_length_over_the_cap_reads_nothing():
    async def receive():
        raise AssertionError("the body was read")

    sent = []

    async def send(message):
        sent.append(message)

    async def never_called(scope, receive, send):
        raise AssertionError("the app was reached")

    guard = Guard(never_called, allowed_hosts=["127.0.0.1"], limits=LIMITS)
    for path, declared in (("/api/images", 10**12), ("/api/fuse", LIMITS.max_json_bytes + 1)):
        sent.clear()
        scope = {
            "type": "http",
            "method": "POST",
            "path": path,
            "scheme": "http",
            "headers": [(b"host", HOST.encode()), (b"content-length", str(declared).encode())],
        }
        asyncio.run(guard(scope, receive, send))
        assert sent[0]["status"] == 413, path
        assert json.loads(sent[1]["body"])["detail"]


@pytest.mark.parametrize("declared", [b"\xb2", b"-1", b"1e9", b" 7 ", b"", b"99999999999999999999999999"])
def test_odd_content_length(app, known, declared):
    """A Content-Length that is not a plain number (a real server's parser would refuse most of
    these first): the body is read and capped as if none was given; never a 5xx."""
    body = json.dumps({"image_id": "nope"}).encode()
    scope = {
        "type": "http",
        "http_version": "1.1",
        "method": "POST",
        "path": "/api/reconstruct",
        "raw_path": b"/api/reconstruct",
        "query_string": b"",
        "root_path": "",
        "scheme": "http",
        "server": ("127.0.0.1", 8000),
        "client": ("127.0.0.1", 50000),
        "headers": [
            (b"host", HOST.encode()),
            (b"content-type", b"application/json"),
            (b"content-length", declared),
        ],
    }
    messages = [{"type": "http.request", "body": body, "more_body": False}]

    async def receive():
        return messages.pop(0) if messages else {"type": "http.disconnect"}

    sent = []

    async def send(message):
        sent.append(message)

    asyncio.run(app(scope, receive, send))
    assert sent[0]["status"] in (404, 413), sent


@pytest.fixture
def no_decoding(monkeypatch):
    """Fail if an image over the server's pixel cap is decoded (Pillow's decoders; libpng's for
    16-bit PNG and tifffile's decode nothing here)."""
    import imagecodecs
    import tifffile
    from PIL import ImageFile

    load = ImageFile.ImageFile.load

    def checked_load(self):
        width, height = self.size
        assert width * height <= LIMITS.max_pixels, f"a {width}x{height} image was decoded"
        return load(self)

    def refuse(*args, **kwargs):
        raise AssertionError("pixels were decoded")

    monkeypatch.setattr(ImageFile.ImageFile, "load", checked_load)
    monkeypatch.setattr(imagecodecs, "png_decode", refuse)
    monkeypatch.setattr(tifffile.TiffPage, "asarray", refuse)


@pytest.mark.parametrize("size", [(100_000, 100_000), (97, 96), (5000, 5000)])
def test_images_over_the_pixel_cap_are_never_decoded(client, known, no_decoding, size):
    """A tiny file whose header claims more pixels than the server's cap (96 x 96 here): 413
    from every route that reads an image, before any pixel is decoded."""
    bomb = png_claiming(*size)
    response = client.post("/api/images", files={"file": ("bomb.png", bomb, "image/png")})
    assert "too large" in assert_one_line(response, 413)
    text = base64.b64encode(bomb).decode()
    assert "too large" in assert_one_line(reconstruct(client, known, {"mask": text}), 413)
    response = client.post(f"/api/images/{known['image']}/mask/file", json={"data": text})
    assert "too large" in assert_one_line(response, 413)
    photos = [("photos", (name, data, "image/png")) for _, (name, data, _) in PHOTOS]
    response = client.post("/api/photosets", files=[("photos", ("bomb.png", bomb, "image/png")), *photos[1:]])
    assert "too large" in assert_one_line(response, 413)
    response = client.post("/api/photosets", files=[*photos, ("mask", ("bomb.png", bomb, "image/png"))])
    assert "too large" in assert_one_line(response, 413)


def test_library_warnings_stay_off_the_console(capfd, caplog):
    """Pillow warns of an upload's corrupt EXIF on every read: the server logs it once, at DEBUG
    level, and prints nothing (the lifespan started in this test: pytest's own capture of
    warnings is undone after each test)."""
    buffer = io.BytesIO()
    # an orientation tag whose entry count runs past the data: "Corrupt EXIF data"
    exif = b"Exif\x00\x00MM\x00*\x00\x00\x00\x08\x00\x05\x01\x12\x00\x03\x00\x00\x00\x01\x00\x06"
    Image.fromarray(np.full((16, 16, 3), 128, np.uint8)).save(buffer, format="JPEG", exif=exif)
    app = create_app(limits=LIMITS)
    with caplog.at_level("DEBUG", logger="shadeform.app.quiet"), TestClient(app, base_url=LOCAL) as client:
        for _ in range(3):
            response = client.post(
                "/api/images", files={"file": ("exif.jpg", buffer.getvalue(), "image/jpeg")}
            )
            assert response.status_code == 201, response.text
    assert "EXIF" not in capfd.readouterr().err
    logged = [record.getMessage() for record in caplog.records if record.name == "shadeform.app.quiet"]
    assert len(logged) == 1 and "Corrupt EXIF data" in logged[0], logged


def test_request_fuzz_seeded(monkeypatch):
    """A few hundred cases of ``benchmarks/fuzz_server.py`` (seed 0; the benchmark sends 10,000):
    every route, method, header and body kind; no 5xx, exception, hang or 4xx without its line."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "fuzz_server.py"
    monkeypatch.syspath_prepend(str(path.parent))  # its sibling hostile_files
    spec = importlib.util.spec_from_file_location("fuzz_server", path)
    fuzz = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "fuzz_server", fuzz)  # its dataclasses look their module up
    spec.loader.exec_module(fuzz)
    counts, failures, _ = fuzz.run(300, seed=0, timeout=60.0)
    assert sum(sum(row.values()) for row in counts.values()) == 300
    assert len(counts) >= 25  # most operations drawn
    assert not failures, [
        (f.case, f.outcome, f.status, f.said, f.request.shown()[:300]) for f in failures[:5]
    ]
