"""The users' projects, kept by the server in its session store (issue 14, point 4): saved,
listed, read and deleted through ``/api/projects``; they outlive a restart of the server, are
bounded, refuse bad input with one line (never a 5xx), and a server without a store says it
keeps none."""

from __future__ import annotations

import json
import sqlite3

import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from hypothesis.errors import Unsatisfiable
from schemathesis import GenerationMode
from schemathesis.checks import (
    content_type_conformance,
    not_a_server_error,
    response_schema_conformance,
    status_code_conformance,
)

from helpers.projects import photo_document
from shadeform.app.guard import AppLimits
from shadeform.app.projects import NO_STORE
from shadeform.app.server import create_app
from shadeform.app.sessions import SessionStore

LOCAL = "http://127.0.0.1:8000"
JSON = {"content-type": "application/json"}


def client_for(path=None, **options) -> TestClient:
    return TestClient(create_app(sessions=path, **options), base_url=LOCAL, raise_server_exceptions=False)


def one_line(response, *statuses: int) -> str:
    assert response.status_code in statuses, (response.status_code, response.text)
    body = response.json()
    assert set(body) == {"detail"} and isinstance(body["detail"], str), body
    assert body["detail"] and "\n" not in body["detail"] and "Traceback" not in body["detail"]
    return body["detail"]


# --------------------------------------------------------------------------- the API


def test_save_list_read_update_and_delete(tmp_path):
    with client_for(tmp_path / "s.sqlite3") as client:
        assert client.get("/api/projects").json() == {"projects": []}
        saved = client.put("/api/projects/first", json=photo_document())
        assert saved.status_code == 200, saved.text
        info = saved.json()
        assert info["id"] == "first" and info["name"] == "bowl.png" and info["image"] == "bowl.png"
        assert info["kind"] == "photo" and info["created"] == info["updated"]

        got = client.get("/api/projects/first").json()
        assert got["document"] == photo_document()  # exactly what was sent
        assert {key: got[key] for key in info} == info

        # a second project, then the first saved again: it is the newest, created unchanged
        client.put("/api/projects/second", json={**photo_document("coin.png"), "name": "My coin"})
        again = client.put("/api/projects/first", json=photo_document(step=4)).json()
        assert again["created"] == info["created"] and again["updated"] > info["updated"]
        listed = client.get("/api/projects").json()["projects"]
        assert [(p["id"], p["name"], p["image"]) for p in listed] == [
            ("first", "bowl.png", "bowl.png"),
            ("second", "My coin", "coin.png"),
        ]
        assert client.get("/api/projects/first").json()["document"]["params"]["step"] == 4

        assert client.delete("/api/projects/second").status_code == 204
        assert "unknown project" in one_line(client.get("/api/projects/second"), 404)
        assert "unknown project" in one_line(client.delete("/api/projects/second"), 404)
        assert [p["id"] for p in client.get("/api/projects").json()["projects"]] == ["first"]


def test_a_document_is_stored_with_every_field(tmp_path):
    # a project file's fields only (as saved from the Project menu, image inline): the rest is
    # filled in, so that what comes back is what the schema says
    document = {
        "format": "shadeform-project",
        "version": 1,
        "image": {"name": "a.png", "type": "image/png", "data": "iVBORw0KGgo=", "example": "coin"},
        "params": {"step": 3},
        "view": {"wireframe": True},
    }
    with client_for(tmp_path / "s.sqlite3") as client:
        assert client.put("/api/projects/p1", json=document).status_code == 200
        back = client.get("/api/projects/p1").json()["document"]
    assert back["image"]["data"] == "iVBORw0KGgo=" and back["image"]["source"] is None
    assert back["params"]["step"] == 3 and back["params"]["channel"] == "luma"
    assert back["view"] == {
        "wireframe": True,
        "normalColours": False,
        "texture": False,
        "maskOverlay": True,
        "lightArrow": True,
    }
    assert back["photo_set"] is None and back["views"] is None and back["name"] is None


def views_and_photo_set(photo):
    """A views project's ``views`` and a photo set project's ``photo_set``, beside ``photo``."""
    info = photo["image"]["info"]
    source = photo["image"]["source"]
    views = {
        "views": [
            {"image": {**info, "name": f"v{i}.png"}, "source": source, "angle": 90.0 * i, "params": {}}
            for i in range(5)
        ],
        "refine_poses": True,
        "settle": False,
        "resolution": 2,
        "showParts": True,
        "editing": 1,
    }
    photo_set = {
        "info": {
            "photoset_id": "abc",
            "name": "cat",
            "count": 12,
            "width": 64,
            "height": 64,
            "colour": True,
            "names": [f"{i}.png" for i in range(12)],
            "lights_file": True,
            "intensities_file": False,
            "mask": False,
            "suggested": {},
        },
        "params": {"lights": "file"},
    }
    return views, photo_set


def test_photo_set_and_views_projects_are_listed_by_what_they_hold(tmp_path):
    photo = photo_document()
    views, photo_set = views_and_photo_set(photo)
    base = {key: photo[key] for key in ("format", "version", "view")}
    with client_for(tmp_path / "s.sqlite3") as client:
        assert client.put("/api/projects/views", json={**base, "views": views}).status_code == 200
        assert client.put("/api/projects/set", json={**base, "photo_set": photo_set}).status_code == 200
        listed = {p["id"]: p for p in client.get("/api/projects").json()["projects"]}
        assert client.get("/api/projects/views").json()["document"]["views"]["editing"] == 1
    assert (listed["views"]["kind"], listed["views"]["name"]) == ("views", "views of v0.png")
    assert listed["views"]["image"] == "5 views: v0.png, v1.png, v2.png and 2 more"
    assert (listed["set"]["kind"], listed["set"]["name"]) == ("photo_set", "cat")
    assert listed["set"]["image"] == "12 photos: 0.png, 1.png, 2.png and 9 more"


def test_a_views_project_keeps_a_view_that_is_a_photo_set(tmp_path):
    """A view that is a photo set (its set and stereo settings, ``ProjectViewEntry.photo_set``)
    comes back as saved; the views saved before it (no ``photo_set``) read as photos."""
    photo = photo_document()
    views, photo_set = views_and_photo_set(photo)
    info = photo_set["info"]
    image = {"image_id": info["photoset_id"], "name": "cat", "width": 64, "height": 64, "channels": 3}
    views["views"][2] = {
        "image": image,
        "source": {"kind": "photoset", "name": "cat"},
        "angle": 180.0,
        "params": {},
        "photo_set": {**photo_set, "params": {"lights": "file", "model": "robust"}},
    }
    base = {key: photo[key] for key in ("format", "version", "view")}
    with client_for(tmp_path / "s.sqlite3") as client:
        assert client.put("/api/projects/views", json={**base, "views": views}).status_code == 200
        back = client.get("/api/projects/views").json()["document"]["views"]["views"]
    assert [view["photo_set"] is None for view in back] == [True, True, False, True, True]
    kept = back[2]["photo_set"]
    assert kept["info"]["photoset_id"] == "abc" and kept["info"]["count"] == 12
    assert kept["params"]["model"] == "robust" and back[2]["source"]["kind"] == "photoset"


def test_projects_saved_with_the_old_names_are_taken_in_the_new(tmp_path):
    """A project saved before the renames (a photo set's ``method``, the views' ``refine``) is
    taken, and kept in today's names (``model``, ``refine_poses``)."""
    photo = photo_document()
    views, photo_set = views_and_photo_set(photo)
    del views["refine_poses"]
    views["refine"] = False
    photo_set["params"] = {"lights": "file", "method": "robust"}
    base = {key: photo[key] for key in ("format", "version", "view")}
    with client_for(tmp_path / "s.sqlite3") as client:
        assert client.put("/api/projects/views", json={**base, "views": views}).status_code == 200
        assert client.put("/api/projects/set", json={**base, "photo_set": photo_set}).status_code == 200
        back = client.get("/api/projects/views").json()["document"]["views"]
        assert back["refine_poses"] is False and "refine" not in back
        back = client.get("/api/projects/set").json()["document"]["photo_set"]["params"]
        assert back["model"] == "robust" and "method" not in back


def test_projects_outlive_a_restart_with_the_same_sessions_file(tmp_path):
    path = tmp_path / "app.sqlite3"
    with client_for(path) as client:
        image = client.post("/api/examples/synth:bowl?size=32").json()
        document = photo_document()
        document["image"]["info"] = image
        document["image"]["source"] = {"kind": "example", "name": "synth:bowl", "type": None, "index": None}
        assert client.put("/api/projects/kept", json=document).status_code == 200
    with client_for(path) as client:  # a new server: nothing in memory
        listed = client.get("/api/projects").json()["projects"]
        assert [p["id"] for p in listed] == ["kept"]
        back = client.get("/api/projects/kept").json()["document"]
        assert back == document
        # and its image too, from the session store, under the same id (as a reload reopens it)
        assert client.get(f"/api/images/{image['image_id']}/photo.png").status_code == 200
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_the_app_keeps_the_200_most_recently_updated(tmp_path):
    with client_for(tmp_path / "s.sqlite3") as client:
        for i in range(201):
            assert client.put(f"/api/projects/p{i}", json=photo_document(f"{i}.png")).status_code == 200
        listed = [p["id"] for p in client.get("/api/projects").json()["projects"]]
    assert len(listed) == 200 and listed[0] == "p200" and "p0" not in listed


class TestStoreBounds:
    def test_by_count_the_least_recently_updated_go(self, tmp_path):
        store = SessionStore(tmp_path / "s.sqlite3", max_bytes=1000, max_projects=3)
        for key in "abcd":
            store.save_project(key, key, {"k": key})
        assert [p["id"] for p in store.list_projects()] == ["d", "c", "b"]
        store.save_project("b", "b again", {"k": "b"})  # updated: now the newest
        store.save_project("e", "e", {})
        assert [p["id"] for p in store.list_projects()] == ["e", "b", "d"]
        assert store.get_project("b")["name"] == "b again"
        assert json.loads(store.get_project("b")["document"]) == {"k": "b"}

    def test_by_bytes_and_the_one_just_saved_stays(self, tmp_path):
        store = SessionStore(tmp_path / "s.sqlite3", max_bytes=1000, max_project_bytes=250)
        for key in "abc":
            store.save_project(key, key, "x" * 100)  # c pushes a out: 300 > 250
        assert [p["id"] for p in store.list_projects()] == ["c", "b"]
        store.save_project("huge", "huge", "x" * 1000)
        assert [p["id"] for p in store.list_projects()] == ["huge"]

    def test_sessions_and_projects_share_the_file_and_neither_evicts_the_other(self, tmp_path):
        store = SessionStore(tmp_path / "s.sqlite3", max_bytes=150, max_projects=1)
        store.put("img", "upload", {"name": "a.png"}, [bytes(100)])
        store.save_project("p", "p", {})
        store.save_project("q", "q", {})
        store.put("img2", "upload", {"name": "b.png"}, [bytes(100)])
        assert store.get("img") is None and store.get("img2") is not None
        assert [p["id"] for p in store.list_projects()] == ["q"]
        assert store.delete_project("q") and not store.delete_project("q")
        assert store.get_project("q") is None


# --------------------------------------------------------------------------- bad input


BAD_DOCUMENTS = [
    (lambda d: d.update(format="something-else"), "format"),
    (lambda d: d.update(version=2), "version"),
    (lambda d: d.update(params=None), "needs its params"),
    (lambda d: d.update(image=None), "none of them"),
    (lambda d: d.update(views={"views": []}), "views.views: give at least 1"),
    (lambda d: d.update(extra=1), "unknown field"),
    (lambda d: d["params"].update(step=0), "params.step"),
    (lambda d: d["params"]["concave"]["regions"][0].update(axis="q"), "axis"),
    (lambda d: d["image"].update(name=7), "image.name"),
    (lambda d: d["image"]["source"].update(kind="ftp"), "image.source.kind"),
    (lambda d: d["view"].update(wireframe="maybe"), "view.wireframe"),
    (lambda d: d.update(name="n" * 201), "name"),
]


@pytest.mark.parametrize(
    ("change", "fragment"), BAD_DOCUMENTS, ids=[fragment for _, fragment in BAD_DOCUMENTS]
)
def test_bad_documents_get_one_line(tmp_path, change, fragment):
    document = photo_document()
    change(document)
    with client_for(tmp_path / "s.sqlite3") as client:
        detail = one_line(client.put("/api/projects/p", json=document), 422)
        assert client.get("/api/projects").json() == {"projects": []}
    assert fragment in detail


def test_bad_ids_bodies_and_sizes_get_one_line(tmp_path):
    limits = AppLimits(max_json_bytes=20_000)
    with client_for(tmp_path / "s.sqlite3", limits=limits) as client:
        for bad in ("a b", "x" * 65, "é", "a.b", "..", "%00"):
            one_line(client.put(f"/api/projects/{bad}", json=photo_document()), 404, 422)
            one_line(client.get(f"/api/projects/{bad}"), 404, 422)
        for body, content_type in (
            (b"{", "application/json"),
            (b"[]", "application/json"),
            (b"x", "text/plain"),
        ):
            one_line(client.put("/api/projects/p", content=body, headers={"content-type": content_type}), 422)
        # over the app's JSON limit: refused before it is read (the guard) or once validated
        big = photo_document()
        big["image"]["data"] = "A" * 30_000
        assert "larger than" in one_line(client.put("/api/projects/p", json=big), 413)
        # fits as sent, but not once every field is filled in (as it would be stored)
        minimal = {"format": "shadeform-project", "version": 1, "image": {"name": "a.png"}, "params": {}}
        padding = limits.max_json_bytes - len(json.dumps(minimal)) - len(', "data": ""') - 10
        minimal["image"]["data"] = "A" * padding
        assert len(json.dumps(minimal)) < limits.max_json_bytes
        detail = one_line(client.put("/api/projects/p", content=json.dumps(minimal), headers=JSON), 413)
        assert detail.startswith("the project is larger than")
        assert "unknown project" in one_line(client.get("/api/projects/nothing"), 404)
        assert "not allowed" in one_line(client.post("/api/projects/p", json=photo_document()), 405)


def test_a_broken_store_is_one_line_not_a_traceback(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(SessionStore, "save_project", broken)
    monkeypatch.setattr(SessionStore, "list_projects", broken)
    with client_for(tmp_path / "s.sqlite3") as client:
        assert "disk is full" in one_line(client.put("/api/projects/p", json=photo_document()), 503)
        assert "project store" in one_line(client.get("/api/projects"), 503)


def test_a_server_without_a_store_keeps_no_projects():
    with client_for(None) as client:
        assert one_line(client.get("/api/projects"), 404) == NO_STORE
        assert one_line(client.put("/api/projects/p", json=photo_document()), 409) == NO_STORE
        assert one_line(client.get("/api/projects/p"), 404) == NO_STORE
        assert one_line(client.delete("/api/projects/p"), 404) == NO_STORE
    assert "--no-sessions" in NO_STORE


# --------------------------------------------------------------------------- fuzzed, with a store

CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance]


@pytest.fixture(scope="module")
def fuzzed_app(tmp_path_factory):
    return create_app(
        sessions=tmp_path_factory.mktemp("fuzz") / "s.sqlite3",
        limits=AppLimits(max_upload_bytes=100_000, max_pixels=96 * 96, max_json_bytes=100_000),
    )


def _project_labels() -> list[str]:
    paths = create_app().openapi()["paths"]
    return [f"{m.upper()} {p}" for p, item in paths.items() if p.startswith("/api/projects") for m in item]


def test_every_project_operation_is_in_the_schema():
    assert sorted(_project_labels()) == [
        "DELETE /api/projects/{project_id}",
        "GET /api/projects",
        "GET /api/projects/{project_id}",
        "PUT /api/projects/{project_id}",
    ]


@pytest.mark.parametrize("mode", [GenerationMode.POSITIVE, GenerationMode.NEGATIVE], ids=str)
@pytest.mark.parametrize("label", _project_labels())
def test_fuzz_with_a_store(fuzzed_app, label, mode):
    """The project operations against a server that keeps projects (tests/test_app_fuzz.py fuzzes
    them on one without): every answer documented, none a 5xx; half the cases use ids that exist."""
    # loaded through schemathesis's own client, whose server is at port 80
    schema = schemathesis.openapi.from_asgi("/api/openapi.json", fuzzed_app, headers={"host": "127.0.0.1"})
    operation = schema.find_operation_by_label(label)
    with TestClient(fuzzed_app, base_url=LOCAL) as client:
        for key in ("kept", "other"):
            assert client.put(f"/api/projects/{key}", json=photo_document(key)).status_code == 200

    @settings(
        max_examples=25,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
        phases=[Phase.explicit, Phase.generate],
    )
    @given(case=operation.as_strategy(generation_mode=mode), aim=st.sampled_from(["kept", "other", None]))
    def run(case, aim):
        if aim and case.path_parameters and "project_id" in case.path_parameters:
            case.path_parameters["project_id"] = aim
        case.call_and_validate(base_url=LOCAL, checks=CHECKS)

    try:
        run()
    except Unsatisfiable:
        assert mode == GenerationMode.NEGATIVE, label
