"""The app's project routes: the users' projects, kept by the server in its session store.

=========================================  ========================================================
``GET    /api/projects``                   ``ProjectList``: the projects, newest first
``PUT    /api/projects/{id}``              ``ProjectDocument`` -> ``ProjectInfo`` (saved)
``GET    /api/projects/{id}``              ``Project``: the listing and the document
``DELETE /api/projects/{id}``              204
=========================================  ========================================================

A project is the user's work on one photo, a photo set or views: what the client's project file
holds (:class:`~shadeform.app.schema.ProjectDocument`), with its images named by their ids in the
session store rather than carried inline. The client autosaves it under an id it chose, so that
it outlives a server restart, a browser whose storage was cleared and a change of browser. The
documents live in the same SQLite file as the sessions (:class:`shadeform.app.sessions.
SessionStore`); a server without one (``--no-sessions``) keeps no projects and says so.
"""

from __future__ import annotations

import json
import logging
import sqlite3
from typing import Any

from fastapi import FastAPI
from fastapi import Path as PathParam
from fastapi.responses import Response
from starlette.exceptions import HTTPException

from shadeform.app.guard import size_text
from shadeform.app.schema import PROJECT_ID_PATTERN, Project, ProjectDocument, ProjectInfo, ProjectList

__all__ = ["add_project_routes"]

logger = logging.getLogger(__name__)

NO_STORE = "this server keeps no projects; start it without --no-sessions"

_ID = PathParam(
    ...,
    description="The project's id, chosen by the client: 1 to 64 letters, digits, '-' or '_'.",
    pattern=PROJECT_ID_PATTERN,
)


def add_project_routes(app: FastAPI, state: Any) -> None:
    """Add the project endpoints to an app (before its catch-all route). They go on the app
    itself, not through a router: the catch-all tells a wrong method (405) by the app's own
    routes.

    Parameters
    ----------
    app : fastapi.FastAPI
        The app :func:`shadeform.app.server.create_app` builds.
    state : shadeform.app.state.State
        The app's state: its ``sessions`` (a :class:`~shadeform.app.sessions.SessionStore`, or
        None) keeps the projects, and its ``limits`` bound a document's size.
    """

    def store(status: int):
        if state.sessions is None:
            raise HTTPException(status, NO_STORE)
        return state.sessions

    @app.get("/api/projects", response_model=ProjectList)
    def list_projects() -> Response:
        projects = _stored(lambda: store(404).list_projects())
        return _json({"projects": projects})

    @app.put("/api/projects/{project_id}", response_model=ProjectInfo)
    def put_project(body: ProjectDocument, project_id: str = _ID) -> Response:
        sessions = store(409)
        # the document with every field, as GET gives it back (and as the schema says it is)
        text = body.model_dump_json()
        limit = state.limits.max_json_bytes
        if len(text.encode()) > limit:
            raise HTTPException(
                413,
                f"the project is larger than {size_text(limit)}; draw a simpler mask or fewer regions",
            )
        name, image, kind = _subject(body)
        name = body.name or name
        saved = _stored(lambda: sessions.save_project(project_id, name, text, image=image, kind=kind))
        return _json(saved)

    @app.get("/api/projects/{project_id}", response_model=Project)
    def get_project(project_id: str = _ID) -> Response:
        sessions = store(404)
        found = _stored(lambda: sessions.get_project(project_id))
        if found is None:
            raise HTTPException(404, _unknown(project_id))
        return _json({**found, "document": json.loads(found["document"])})

    @app.delete("/api/projects/{project_id}", status_code=204, response_class=Response)
    def delete_project(project_id: str = _ID) -> Response:
        sessions = store(404)
        if not _stored(lambda: sessions.delete_project(project_id)):
            raise HTTPException(404, _unknown(project_id))
        return Response(status_code=204)


def _unknown(project_id: str) -> str:
    return f"unknown project {project_id!r}: the server does not keep it (deleted, or one of the oldest)"


def _subject(document: ProjectDocument) -> tuple[str, str, str]:
    """A project's name unless it has one, what it is of in a few words, and its kind: ``photo``,
    ``photo_set`` or ``views``."""
    if document.photo_set is not None:
        info = document.photo_set.info
        return info.name, _some(info.names, "photos"), "photo_set"
    if document.views is not None:
        names = [view.image.name for view in document.views.views]
        return f"views of {names[0]}", _some(names, "views"), "views"
    return document.image.name, document.image.name, "photo"


def _some(names: list[str], what: str) -> str:
    """``"5 views: a, b, c and 2 more"``."""
    shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
    return f"{len(names)} {what}: {shown}"


def _stored(work):
    """``work()`` on the session store; a store that cannot be read or written (a full disk, a
    damaged file) is one line to the client, not a traceback."""
    try:
        return work()
    except sqlite3.Error as err:
        logger.warning("the project store failed: %s", err)
        raise HTTPException(503, f"the server could not use its project store ({err}); try again") from None


def _json(content: Any) -> Response:
    return Response(json.dumps(content), media_type="application/json")
