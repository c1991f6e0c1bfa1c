"""Relightable images (RTI) for cultural-heritage users: a photo set (one still camera, one light
per photo) fitted per pixel as a polynomial texture map or hemispherical harmonics
(:mod:`.models`), written as the ``.ptm`` and ``.rti`` files RTIViewer opens (:mod:`.files`) or
as the folder of JPEG planes Relight's web viewer and OpenLIME read (:mod:`.web`)."""

from __future__ import annotations

from shadeform.rti.files import SUFFIXES, encode, file_size, write_rti
from shadeform.rti.models import (
    FORMATS,
    RelightModel,
    display_values,
    fit,
    hsh_basis,
    ptm_basis,
    relight,
    rms_error,
)
from shadeform.rti.web import check_web_folder, web_files, web_set, write_web

__all__ = [
    "FORMATS",
    "SUFFIXES",
    "RelightModel",
    "display_values",
    "check_web_folder",
    "encode",
    "file_size",
    "fit",
    "hsh_basis",
    "ptm_basis",
    "relight",
    "rms_error",
    "web_files",
    "web_set",
    "write_rti",
    "write_web",
]
