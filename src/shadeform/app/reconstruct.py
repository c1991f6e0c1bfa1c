"""The app's routes that solve one photo: the model for the view (a quick look on a large photo),
the full solve of a large photo in the background, and the model's file.

==========================================  ===================================================
``POST /api/reconstruct``                   ``ReconstructRequest`` -> ``ReconstructResult``
``POST /api/solves``                        ``ReconstructRequest`` -> ``SolveJob``: the full solve
                                            in the background (large photos: progress, cancel)
``GET  /api/solves/{id}[/result]``          its progress; its ``ReconstructResult`` once done
``DELETE /api/solves/{id}``                 cancel it
``POST /api/export?format=.wrl``            ``ReconstructRequest`` -> the mesh file
                                            (``&closed=true``: closed, the back a guess)
==========================================  ===================================================

The solves themselves are :mod:`shadeform.app.solving`'s; one runs at a time (the app's
``solve_lock``).
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI, Query, Request
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException

from shadeform.app.encoding import FILE_RESPONSES, download, format_suffix, json_response, safe_stem
from shadeform.app.schema import ReconstructRequest, ReconstructResult, SolveJob
from shadeform.app.solving import export_bytes, find_job, job_info, reconstruct_result, start_job

__all__ = ["add_reconstruct_routes"]


def add_reconstruct_routes(app: FastAPI, state: Any) -> None:
    """Add the reconstruct, background solve and export endpoints to an app (before its
    catch-all route).

    Parameters
    ----------
    app : fastapi.FastAPI
        The app :func:`shadeform.app.server.create_app` builds.
    state : shadeform.app.state.State
        The app's store: its images, reconstructions, background jobs and solve lock.
    """

    @app.post("/api/reconstruct", response_model=ReconstructResult)
    async def post_reconstruct(body: ReconstructRequest, request: Request) -> Response:
        return await state.solve_json(request, reconstruct_result, state, state.image(body.image_id), body)

    @app.post("/api/solves", response_model=SolveJob, status_code=202)
    def post_solve(body: ReconstructRequest) -> Response:
        return json_response(job_info(start_job(state, state.image(body.image_id), body)), status_code=202)

    @app.get("/api/solves/{job_id}", response_model=SolveJob)
    def get_solve(job_id: str) -> Response:
        return json_response(job_info(find_job(state, job_id)))

    @app.get("/api/solves/{job_id}/result", response_model=ReconstructResult)
    def get_solve_result(job_id: str) -> Response:
        job = find_job(state, job_id)
        if job.state == "done":
            return Response(job.result, media_type="application/json")
        if job.state == "failed":
            raise HTTPException(422, job.detail)
        if job.state == "cancelled":
            raise HTTPException(409, f"the solve was {job.detail}; start a new one")
        raise HTTPException(409, "the solve is still running; ask for its progress until it is done")

    @app.delete("/api/solves/{job_id}", response_model=SolveJob)
    def delete_solve(job_id: str) -> Response:
        find_job(state, job_id)
        return json_response(job_info(state.jobs.cancel(job_id)))

    @app.post("/api/export", response_class=Response, responses=FILE_RESPONSES)
    async def post_export(
        body: ReconstructRequest,
        format: str = Query(..., description="A suffix from Options.formats, e.g. .wrl."),
        closed: bool = Query(
            False,
            description="A closed, watertight model: the photo's model as the front, the back the "
            "front mirrored (a guess: the photo does not show it).",
        ),
    ) -> Response:
        from shadeform.io.exporters import available_formats

        suffix = format_suffix(format, available_formats())
        entry = state.image(body.image_id)
        async with state.solve_lock:
            data = await run_in_threadpool(export_bytes, state, entry, body.params, suffix, closed=closed)
        return download(data, safe_stem(entry.name) + "_closed" if closed else entry.name, suffix)
