"""The web client's TypeScript types (``web/src/api.gen.ts``), generated from the schema's models."""

from __future__ import annotations

import json

from pydantic.json_schema import models_json_schema


def typescript() -> str:
    """The TypeScript declarations of the schema: the text of ``web/src/api.gen.ts``.

    Built from pydantic's JSON schema (serialization mode, so every field the server sends is
    required): objects become interfaces, string enums union types of literals, fixed-length
    arrays tuples.

    Returns
    -------
    str
        The whole file, ending with a newline.
    """
    from pydantic import BaseModel

    from shadeform.app import schema as package  # imported when asked: the package imports this module

    # every model the package exports, in the order of its __all__
    exported = [getattr(package, name) for name in package.__all__]
    models = [item for item in exported if isinstance(item, type) and issubclass(item, BaseModel)]
    _, schema = models_json_schema([(model, "serialization") for model in models])
    definitions = schema["$defs"]
    # aliases (Channel, ...) first, then the models in the package's order
    order = [name for name in definitions if "properties" not in definitions[name]]
    order += [model.__name__ for model in models]
    lines = [
        "// Generated from shadeform.app.schema by `python -m shadeform.app.schema`; do not edit.",
        "// A test (tests/test_app_api.py) fails when this file and the schema disagree.",
        "",
    ]
    for name in order:
        definition = definitions[name]
        if "properties" not in definition:
            lines += [f"export type {name} = {_ts_type(definition)};", ""]
            continue
        doc = definition.get("description")
        if doc:
            lines.append(f"/** {' '.join(doc.split())} */")
        lines.append(f"export interface {name} {{")
        required = set(definition.get("required", ()))
        for field, spec in definition["properties"].items():
            if spec.get("description"):
                lines.append(f"  /** {spec['description']} */")
            optional = "" if field in required else "?"
            lines.append(f"  {field}{optional}: {_ts_type(spec)};")
        lines += ["}", ""]
    return "\n".join(lines).rstrip("\n") + "\n"


def _ts_type(spec: dict) -> str:
    """A TypeScript type expression for one JSON-schema node."""
    if "$ref" in spec:
        return spec["$ref"].rsplit("/", 1)[-1]
    if "enum" in spec:
        return " | ".join(json.dumps(value) for value in spec["enum"])
    if "const" in spec:
        return json.dumps(spec["const"])
    if "anyOf" in spec:
        return " | ".join(dict.fromkeys(_ts_type(option) for option in spec["anyOf"]))  # int | float: number
    kind = spec.get("type")
    if kind == "array":
        if "prefixItems" in spec:
            return "[" + ", ".join(_ts_type(item) for item in spec["prefixItems"]) + "]"
        item = _ts_type(spec.get("items", {}))
        return f"({item})[]" if " | " in item else f"{item}[]"
    if kind == "object":
        values = spec.get("additionalProperties", True)
        return f"Record<string, {'unknown' if values is True else _ts_type(values)}>"
    return {
        "string": "string",
        "number": "number",
        "integer": "number",
        "boolean": "boolean",
        "null": "null",
    }.get(kind, "unknown")
