"""The app's sessions outlive a restart: what clients opened is kept in SQLite
(``shadeform.app.sessions``) and made again when a client names it after the restart."""

from __future__ import annotations

import io
import sqlite3

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from shadeform import synth
from shadeform.app.guard import AppLimits
from shadeform.app.server import create_app
from shadeform.app.sessions import SessionStore, data_folder
from shadeform.light import light_from_slant_tilt

LOCAL = "http://127.0.0.1:8000"


def png(image, bits=8) -> bytes:
    out = io.BytesIO()
    top = 255 if bits == 8 else 65535
    values = np.rint(np.clip(image, 0, 1) * top).astype(np.uint8 if bits == 8 else np.uint16)
    Image.fromarray(values).save(out, format="PNG")
    return out.getvalue()


def app_client(path, **options):
    return TestClient(create_app(sessions=path, **options), base_url=LOCAL)


class TestStore:
    def test_round_trip_across_a_reopening_in_wal_mode(self, tmp_path):
        store = SessionStore(tmp_path / "s.sqlite3", max_bytes=10_000)
        store.put("a", "upload", {"name": "a.png"}, [b"12345", b"xyz"])
        assert store.journal_mode == "wal"
        store.close()
        again = SessionStore(tmp_path / "s.sqlite3", max_bytes=10_000)
        assert again.get("a") == ("upload", {"name": "a.png"}, [b"12345", b"xyz"])
        assert again.get("missing") is None

    def test_the_least_recently_used_go_to_fit_the_bytes(self, tmp_path):
        store = SessionStore(tmp_path / "s.sqlite3", max_bytes=250)
        for key in "abc":
            store.put(key, "upload", {}, [bytes(100)])  # c pushes a out: 300 > 250
        assert store.get("a") is None and store.get("b") is not None
        store.put("d", "upload", {}, [bytes(100)])  # b was just used: c goes
        assert store.get("c") is None and store.get("b") is not None and store.get("d") is not None
        store.put("huge", "upload", {}, [bytes(1000)])  # the one just put stays, alone
        assert len(store) == 1 and store.get("huge") is not None

    def test_the_data_folder_follows_xdg(self, monkeypatch, tmp_path):
        monkeypatch.setattr("sys.platform", "linux")
        monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
        assert data_folder() == tmp_path / "shadeform"


def test_an_uploaded_photo_an_example_and_a_photo_set_outlive_a_restart(tmp_path):
    path = tmp_path / "app.sqlite3"
    scene = synth.scene("sphere", size=48)
    lights = [light_from_slant_tilt(s, t) for s, t in zip([20, 35, 50, 30], [0, 90, 180, 270])]
    photos = [
        (f"p{i}.png", png(synth.render(scene.normals, scene.mask, light=light), 16))
        for i, light in enumerate(lights)
    ]
    light_file = "\n".join(" ".join(f"{v:.9f}" for v in light) for light in lights).encode()
    with app_client(path) as client:
        image = client.post("/api/images", files={"file": ("disc.png", png(scene.image), "image/png")}).json()
        example = client.post("/api/examples/synth:bowl").json()
        photo_set = client.post(
            "/api/photosets",
            files=[("photos", (n, d, "image/png")) for n, d in photos] + [("lights", ("l.txt", light_file))],
        ).json()
        views = client.post("/api/viewsets/examples/views:lumpy").json()
        before = client.post("/api/reconstruct", json={"image_id": image["image_id"], "params": {"step": 2}})
        assert before.status_code == 200
    with app_client(path) as client:  # the server restarted: nothing in memory
        after = client.post("/api/reconstruct", json={"image_id": image["image_id"], "params": {"step": 2}})
        assert after.status_code == 200, after.text
        assert after.json()["mesh"] == before.json()["mesh"]  # the same photo, read again the same way
        assert client.get(f"/api/images/{example['image_id']}/photo.png").status_code == 200
        solved = client.post("/api/stereo", json={"photoset_id": photo_set["photoset_id"]})
        assert solved.status_code == 200, solved.text
        view = views["images"][2]["image_id"]
        assert (
            client.post("/api/reconstruct", json={"image_id": view, "params": {"step": 4}}).status_code == 200
        )
    with TestClient(create_app(), base_url=LOCAL) as client:  # no store: forgotten, as before
        gone = client.post("/api/reconstruct", json={"image_id": image["image_id"]})
        assert gone.status_code == 404 and "reload the page" in gone.json()["detail"]


def test_a_kept_upload_obeys_todays_limits(tmp_path):
    path = tmp_path / "app.sqlite3"
    with app_client(path) as client:
        image_id = client.post(
            "/api/images", files={"file": ("big.png", png(np.ones((64, 64)) * 0.5))}
        ).json()["image_id"]
    with app_client(path, limits=AppLimits(max_pixels=32 * 32)) as client:
        assert client.post("/api/reconstruct", json={"image_id": image_id}).status_code == 404


@pytest.mark.parametrize("command", [["app", "--help"]])
def test_the_app_command_says_where_sessions_live(command, cli):
    result = cli(*command)
    assert result.exit_code == 0 and "--sessions" in result.output


def damage(path, offset: int, size: int = 3000) -> bytes:
    """Overwrite ``size`` bytes of the file at ``offset`` (from its end if negative) with noise;
    the file's bytes after."""
    data = bytearray(path.read_bytes())
    start = offset % len(data)
    data[start : start + size] = np.random.default_rng(1).integers(0, 256, size, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))
    return bytes(data)


def test_a_file_damaged_past_its_header_is_set_aside_once_and_what_can_be_read_kept(tmp_path, caplog):
    path = tmp_path / "app.sqlite3"
    store = SessionStore(path, max_bytes=10**9)
    files = {f"k{i}": bytes([i]) * 3000 for i in range(20)}
    for key, data in files.items():
        store.put(key, "upload", {"name": f"{key}.png"}, [data])
    store.save_project("p", "mine", {"a": 1})
    store.close()
    damaged = damage(path, -5000)  # the last pages: the header and the schema are whole
    with caplog.at_level("WARNING"):
        store = SessionStore(path, max_bytes=10**9)
    lines = [record.getMessage() for record in caplog.records]
    assert len(lines) == 1 and lines[0] == store.notice, lines
    aside = [p for p in tmp_path.iterdir() if p.name.startswith("app.sqlite3.damaged-") and p.suffix != ""]
    (kept_aside,) = [p for p in aside if not p.name.endswith(("-wal", "-shm"))]
    assert kept_aside.read_bytes() == damaged  # renamed, not deleted, not changed
    assert "damaged" in lines[0] and kept_aside.name in lines[0] and "\n" not in lines[0]
    kept = len(store)
    assert 0 < kept < 20 and f"({kept} photos, 1 project)" in lines[0]
    for key, data in files.items():  # what was kept has all its bytes (SQLite keeps no checksum
        found = store.get(key)  # of them: a damaged upload is refused when it is decoded again)
        assert found is None or (found[:2], len(found[2][0])) == (
            ("upload", {"name": f"{key}.png"}),
            len(data),
        )
    assert store.get_project("p")["name"] == "mine"
    with store._lock:
        assert store._db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    store.close()
    # an app over the fresh file keeps every new session, and says nothing more
    caplog.clear()
    with caplog.at_level("WARNING"), app_client(path) as client:
        ids = [
            client.post("/api/images", files={"file": (f"{i}.png", png(np.full((16, 16), 0.1 * i)))}).json()[
                "image_id"
            ]
            for i in range(1, 4)
        ]
    assert not caplog.records
    with app_client(path) as client:
        for image_id in ids:
            assert client.get(f"/api/images/{image_id}/photo.png").status_code == 200


def test_a_file_that_is_not_sqlite_is_never_set_aside(tmp_path):
    path = tmp_path / "photo.png"
    path.write_bytes(png(np.zeros((8, 8))))
    with pytest.raises(sqlite3.DatabaseError):
        SessionStore(path, max_bytes=1000)
    assert [p.name for p in tmp_path.iterdir()] == ["photo.png"]
