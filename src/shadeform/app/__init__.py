"""The browser app: a FastAPI server (:mod:`shadeform.app.server`) over the library, and its
request/response schema (:mod:`shadeform.app.schema`). Start it with ``shadeform app``."""
